"""Depth-grid image encoder: coarse depth (mean and minimum per cell) + the bump flag, no learned weights.

Why: PointNav needs free space and obstacles, not objects. These are the depth features the oracle-vl
encoder appends (`oracle_depth_grid`, `oracle_collision`), without its semantic part, so the policy reads
only a real depth camera and bump sensor. A ~100-number input trains in minutes on a CPU, where a CNN on
frames costs a forward and backward pass per step. The features are means and minima over image cells, so
they barely change with the resolution as long as the field of view and the aspect ratio stay the same.
"""

from __future__ import annotations

import numpy as np
import torch

from ovon.models.encoders.base import ObsBatch, get_obs


def depth_grid_features(depth: np.ndarray, grid: tuple[int, int], max_depth: float) -> np.ndarray:
    """(H, W) metres -> (2 * rows * cols,) mean and min per cell, scaled to [0, 1] by `max_depth`."""
    gr, gc = grid
    h, w = depth.shape
    if h < gr or w < gc:
        raise ValueError(f"a {h}x{w} depth frame cannot be split into a {gr}x{gc} grid")
    d = np.clip(np.asarray(depth, dtype=np.float32) / max_depth, 0.0, 1.0)
    d = d[: h - h % gr, : w - w % gc].reshape(gr, h // gr, gc, w // gc)
    return np.concatenate([d.mean(axis=(1, 3)).ravel(), d.min(axis=(1, 3)).ravel()]).astype(np.float32)


class DepthGridEncoder:
    """(B, H, W) depth [+ (B,) collided] -> (B, 2 * rows * cols [+ 1]) float32."""

    name = "depth-grid"
    trainable = False

    def __init__(self, grid: tuple[int, int], max_depth: float = 5.0, collision: bool = True) -> None:
        if grid[0] < 1 or grid[1] < 1:
            raise ValueError(
                f"depth-grid encoder needs a grid of at least 1x1 cells, got {grid}; set "
                "encoder.oracle_depth_grid=[rows,cols]"
            )
        self.grid = (int(grid[0]), int(grid[1]))
        self.max_depth = float(max_depth)
        self.collision = bool(collision)
        self.dim = 2 * self.grid[0] * self.grid[1] + (1 if self.collision else 0)

    def encode(self, batch: ObsBatch) -> torch.Tensor:
        depth = get_obs(batch, "depth")
        depth = np.asarray(depth.cpu().numpy() if isinstance(depth, torch.Tensor) else depth)
        if depth.ndim == 2:
            depth = depth[None]
        out = np.stack([depth_grid_features(d, self.grid, self.max_depth) for d in depth])
        if self.collision:
            bump = get_obs(batch, "collided")
            bump = np.asarray(bump.cpu().numpy() if isinstance(bump, torch.Tensor) else bump, np.float32)
            out = np.concatenate([out, bump.reshape(len(out), 1)], axis=1)
        return torch.from_numpy(out.astype(np.float32, copy=False))
