"""Oracle vision-language image encoder: ORACLE PERCEPTION computed from the semantic frame.

Why: no pretrained image model can be installed here, yet the policy needs an image embedding in the
same space as the goal text so that open-vocabulary generalisation can be studied. This encoder
writes, for every visible instance, the text embedding of its category weighted by its pixel-area
fraction. Every report that uses it must say "oracle perception".

Layout of the output (dim = (global + grid*grid) * text_dim [+ depth grid] [+ collision flag]):
  [ global part (text_dim) | cell (0,0) | ... | cell (g-1,g-1) | depth mean, min per cell | collided ]
Each part is sum_i (pixels of instance i in the region / pixels of the region) * e_i, where e_i is
the unit text embedding of the instance's category (background id 0 and unknown ids contribute
nothing). The vectors are not normalised, so their length tells how much of the region is covered by
known objects. The global part is the text-aligned part: cosine(global, goal text) is the
image-goal score (`score`). Without a global part, `score` uses the mean of the cells (equal to the
global part when the cells have equal pixel counts).

Noise model, per frame and instance (seeded `numpy` generator, deterministic for a given seed and
call sequence): with probability `dropout` the instance is missed; otherwise its embedding is
replaced by normalise(e_i + n), n ~ N(0, noise_std^2 / text_dim * I), so `noise_std` is the expected
noise norm relative to the unit embedding (0.5 -> cosine with the clean embedding ~0.89).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import torch

from ovon.models.encoders.base import ObsBatch, TextEncoder, get_obs


class OracleVLEncoder:
    """Oracle perception image encoder: area-weighted category text embeddings on a spatial grid."""

    name = "oracle-vl (oracle perception)"
    trainable = False

    def __init__(
        self,
        text_encoder: TextEncoder,
        grid: int = 2,
        include_global: bool = True,
        noise_std: float = 0.0,
        dropout: float = 0.0,
        seed: int = 0,
        depth_grid: tuple[int, int] = (0, 0),
        max_depth: float = 5.0,
        collision: bool = False,
    ) -> None:
        if grid < 1:
            raise ValueError(f"oracle grid must be >= 1, got {grid}")
        if not 0.0 <= dropout <= 1.0:
            raise ValueError(f"oracle dropout must be in [0, 1], got {dropout}")
        self.text_encoder = text_encoder
        self.text_dim = int(text_encoder.dim)
        self.grid = grid
        self.include_global = include_global
        self.noise_std = float(noise_std)
        self.dropout = float(dropout)
        self.seed = seed
        self.rng = np.random.default_rng(seed)
        self.parts = grid * grid + (1 if include_global else 0)
        # Coarse depth (a real sensor, not privileged): per cell of a rows x cols grid, the mean and the
        # minimum depth / max_depth. Without it the policy sees objects but no walls or free space.
        self.depth_grid = (int(depth_grid[0]), int(depth_grid[1]))
        self.max_depth = float(max_depth)
        self.depth_dim = 2 * self.depth_grid[0] * self.depth_grid[1]
        self.collision = bool(collision)  # append the observation's "collided" flag (last dim)
        self.dim = self.parts * self.text_dim + self.depth_dim + (1 if self.collision else 0)
        self._shared: tuple[np.ndarray, np.ndarray] | None = None
        self._per_env: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        self._cells: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]] = {}

    def reseed(self, seed: int) -> None:
        """Restart the noise stream (e.g. per evaluation episode, for reproducible runs)."""
        self.seed = seed
        self.rng = np.random.default_rng(seed)

    def set_scene(self, instance_to_category: Mapping[int, str], env: int | None = None) -> None:
        """Register the scene's instance id -> category name (at episode reset).

        `env=None` sets the mapping used by every batch row; `env=i` sets the one for row i only
        (a trainer that batches several environments in one process).
        """
        ids = np.fromiter((int(k) for k in instance_to_category), dtype=np.int64)
        names = [str(instance_to_category[k]) for k in instance_to_category]
        size = int(ids.max()) + 1 if ids.size else 1
        lut = np.full(size, -1, dtype=np.int64)
        uniq = list(dict.fromkeys(names))
        index = {n: i for i, n in enumerate(uniq)}
        if ids.size:
            lut[ids] = [index[n] for n in names]
        lut[0] = -1  # id 0 is "no instance"
        emb = self.text_encoder.encode(uniq).numpy().astype(np.float32) if uniq else np.zeros((0, 1))
        if uniq:
            emb = emb / np.maximum(np.linalg.norm(emb, axis=1, keepdims=True), 1e-12)
        entry = (lut, emb)
        if env is None:
            self._shared = entry
            self._per_env.clear()
        else:
            self._per_env[env] = entry

    def _cell_index(self, h: int, w: int) -> tuple[np.ndarray, np.ndarray]:
        key = (h, w)
        if key not in self._cells:
            g = self.grid
            rows = np.minimum(np.arange(h) * g // h, g - 1)
            cols = np.minimum(np.arange(w) * g // w, g - 1)
            cell = (rows[:, None] * g + cols[None, :]).astype(np.int64).ravel()
            pixels = np.bincount(cell, minlength=g * g).astype(np.float64)
            self._cells[key] = (cell, pixels)
        return self._cells[key]

    def _mapping(self, row: int) -> tuple[np.ndarray, np.ndarray]:
        entry = self._per_env.get(row, self._shared)
        if entry is None:
            raise RuntimeError(
                "OracleVLEncoder.set_scene(instance_to_category) must be called before encode() "
                f"(no mapping for batch row {row})"
            )
        return entry

    def encode_frame(self, semantic: np.ndarray, row: int = 0) -> np.ndarray:
        """One semantic frame (H, W) int -> float32 (dim,)."""
        lut, emb = self._mapping(row)
        h, w = semantic.shape
        cell, pixels = self._cell_index(h, w)
        size, g2 = lut.size, self.grid * self.grid
        sem = semantic.astype(np.int64).ravel()
        sem[(sem < 0) | (sem >= size)] = 0
        # pixels per (cell, instance id) in one bincount: ids are small integers, a sort is not needed
        per_cell = np.bincount(cell * size + sem, minlength=g2 * size).reshape(g2, size)
        ids = np.flatnonzero((per_cell.sum(0) > 0) & (lut >= 0))  # visible known instances, sorted
        if not ids.size:
            return np.zeros(self.parts * self.text_dim, dtype=np.float32)
        n = ids.size
        counts = per_cell[:, ids]
        frac = counts / pixels[:, None]
        vecs = emb[lut[ids]].astype(np.float64)
        if self.dropout > 0.0:
            keep = self.rng.random(n) >= self.dropout
            vecs = vecs * keep[:, None]
        if self.noise_std > 0.0:
            noise = self.rng.standard_normal(vecs.shape) * (self.noise_std / np.sqrt(self.text_dim))
            noisy = vecs + noise
            noisy /= np.maximum(np.linalg.norm(noisy, axis=1, keepdims=True), 1e-12)
            vecs = np.where(np.any(vecs != 0, axis=1, keepdims=True), noisy, 0.0)
        cells = frac @ vecs  # (cells, text_dim)
        parts = [cells]
        if self.include_global:
            glob = (counts.sum(0) / (h * w)) @ vecs
            parts.insert(0, glob[None])
        return np.concatenate(parts, 0).astype(np.float32).ravel()

    def encode_depth(self, depth: np.ndarray) -> np.ndarray:
        """(H, W) metres -> (2 * rows * cols,) mean and min per cell, scaled to [0, 1]."""
        from ovon.models.encoders.depth_grid import depth_grid_features

        return depth_grid_features(depth, self.depth_grid, self.max_depth)

    def encode_one(self, semantic: np.ndarray, depth: np.ndarray | None, collided: int = 0) -> np.ndarray:
        """One frame -> (dim,) float32, equal to `encode` of a batch of one without its batching (the env's
        encoding wrapper calls it every step)."""
        parts = [self.encode_frame(np.asarray(semantic), 0)]
        if self.depth_dim:
            parts.append(self.encode_depth(np.asarray(depth)))
        if self.collision:
            parts.append(np.array([collided], np.float32))
        return np.concatenate(parts) if len(parts) > 1 else parts[0]

    def encode(self, batch: ObsBatch) -> torch.Tensor:
        sem = get_obs(batch, "semantic")
        if isinstance(sem, torch.Tensor):
            sem = sem.cpu().numpy()
        sem = np.asarray(sem)
        if sem.ndim == 2:
            sem = sem[None]
        out = np.stack([self.encode_frame(s, i) for i, s in enumerate(sem)])
        if self.depth_dim:
            depth = get_obs(batch, "depth")
            if isinstance(depth, torch.Tensor):
                depth = depth.cpu().numpy()
            depth = np.asarray(depth)
            if depth.ndim == 2:
                depth = depth[None]
            out = np.concatenate([out, np.stack([self.encode_depth(d) for d in depth])], axis=1)
        if self.collision:
            bump = get_obs(batch, "collided")
            bump = np.asarray(bump.cpu().numpy() if isinstance(bump, torch.Tensor) else bump, np.float32)
            out = np.concatenate([out, bump.reshape(len(out), 1)], axis=1)
        return torch.from_numpy(out.astype(np.float32, copy=False))

    def text_aligned(self, image_emb: torch.Tensor) -> torch.Tensor:
        """The part of the embedding that lives in the goal-text space: (B, dim) -> (B, text_dim)."""
        image_emb = image_emb[..., : self.parts * self.text_dim]
        parts = image_emb.reshape(*image_emb.shape[:-1], self.parts, self.text_dim)
        return parts[..., 0, :] if self.include_global else parts.mean(-2)

    def score(self, image_emb: torch.Tensor, text_emb: torch.Tensor) -> torch.Tensor:
        """Cosine between the text-aligned image part and goal texts: (B, N)."""
        a = self.text_aligned(image_emb.float())
        a = a / a.norm(dim=-1, keepdim=True).clamp_min(1e-12)
        b = text_emb.float() / text_emb.float().norm(dim=-1, keepdim=True).clamp_min(1e-12)
        return a @ b.T
