"""The three roles of the world-vl network behind ovon's protocols: image encoder (`world-vl`), detector
(`world-owl`) and value scorer (`world-vl`). None of them reads the privileged channel."""

from __future__ import annotations

import numpy as np
import torch
from scipy import ndimage

from ovon.models.detectors.base import Detection, box_of
from ovon.models.encoders.base import ObsBatch, TextEncoder, get_obs
from ovon.models.encoders.depth_grid import depth_grid_features
from ovon.models.world import load_world_vl


def _unit_text(text_encoder: TextEncoder, texts: list[str]) -> torch.Tensor:
    t = torch.as_tensor(np.asarray(text_encoder.encode(texts), dtype=np.float32))
    return t / t.norm(dim=-1, keepdim=True).clamp_min(1e-12)


def _default_text() -> TextEncoder:
    from ovon.models.encoders.text import MiniLMText

    return MiniLMText()


class WorldVLEncoder:
    """Frames -> [global | grid x grid regions] objectness-weighted embeddings in the MiniLM space, then the
    depth grid and the bump flag: the layout of `oracle-vl`, from RGB instead of the semantic frame."""

    trainable = False
    privileged = False

    def __init__(
        self,
        checkpoint: str = "",
        batch: int = 4,
        grid: int = 2,
        include_global: bool = True,
        depth_grid: tuple[int, int] = (0, 0),
        max_depth: float = 5.0,
        collision: bool = False,
    ) -> None:
        self.model = load_world_vl(checkpoint)
        self.name = f"world-vl ({self.model.source})"
        self.batch = int(batch)
        self.text_dim = int(self.model.net.cfg.text_dim)
        self.grid = int(grid)
        self.include_global = bool(include_global)
        self.depth_grid = (int(depth_grid[0]), int(depth_grid[1]))
        self.max_depth = float(max_depth)
        self.collision = bool(collision)
        parts = grid * grid + (1 if include_global else 0)
        self.dim = parts * self.text_dim + 2 * self.depth_grid[0] * self.depth_grid[1] + (1 if collision else 0)
        # encoders with the same key give the same output for a frame: a vector env worker batches their frames
        self.batch_key = (id(self.model), self.batch, self.grid, self.include_global, self.depth_grid, collision)

    def _semantic(self, rgb: np.ndarray) -> torch.Tensor:
        """(B, parts * D) in chunks of exactly `batch` frames (the last one padded with black frames): a frame's
        embedding is then bitwise the same whichever frames share its chunk, so results do not depend on how
        envs are spread over workers."""
        out = []
        for i in range(0, len(rgb), self.batch):
            chunk = rgb[i : i + self.batch]
            n = len(chunk)
            if n < self.batch:
                chunk = np.concatenate([chunk, np.zeros((self.batch - n, *chunk.shape[1:]), chunk.dtype)])
            top, obj, _ = self.model.features(chunk)
            with torch.inference_mode():
                whole, regions = self.model.net.pooled(top, obj, self.grid)
            parts = [whole[:, None]] if self.include_global else []
            out.append(torch.cat([*parts, regions], dim=1).flatten(1)[:n])
        return torch.cat(out)

    def encode_frame(self, obs: dict) -> np.ndarray:
        """One frame (an agent acting, one env without a vector worker): a forward pass of batch 1 instead of
        a padded chunk, about half the cost (4 instead of 9 ms per step on one thread), shared with a
        world-owl detector or world-vl scorer reading the same frame (`WorldVL.frame_features`). It equals
        `encode` up to float rounding (batch-size-dependent kernels), not bit for bit; each path is
        deterministic on its own."""
        top, obj, _ = self.model.frame_features(np.asarray(obs["rgb"]))
        with torch.inference_mode():
            whole, regions = self.model.net.pooled(top, obj, self.grid)
        parts = [whole[:, None]] if self.include_global else []
        return self._with_geometry(
            torch.cat([*parts, regions], dim=1).flatten(1), {k: np.asarray(v)[None] for k, v in obs.items()}
        )[0].numpy()

    def encode(self, batch: ObsBatch) -> torch.Tensor:
        rgb = np.asarray(get_obs(batch, "rgb"))
        if rgb.ndim == 3:
            rgb = rgb[None]
        return self._with_geometry(self._semantic(rgb), batch)

    def _with_geometry(self, semantic: torch.Tensor, batch: ObsBatch) -> torch.Tensor:
        """The semantic part followed by the depth grid and the bump flag."""
        out = [semantic]
        if self.depth_grid[0] > 0:
            depth = np.asarray(get_obs(batch, "depth"))
            depth = depth[None] if depth.ndim == 2 else depth
            feats = np.stack([depth_grid_features(d, self.depth_grid, self.max_depth) for d in depth])
            out.append(torch.from_numpy(feats))
        if self.collision:
            bump = np.asarray(get_obs(batch, "collided"), dtype=np.float32).reshape(len(semantic), 1)
            out.append(torch.from_numpy(bump))
        return torch.cat(out, dim=1).float()


class WorldOWLDetector:
    """Open-vocabulary detection: cells whose probability for the goal text reaches the calibrated threshold,
    grouped into connected components; each is a detection with its mask, box and best cell probability.
    A frame whose pooled score stays under the threshold has no detection."""

    privileged = False

    def __init__(self, cfg=None, text_encoder: TextEncoder | None = None) -> None:
        from ovon.models.config import DetectorConfig

        self.cfg = cfg or DetectorConfig(kind="world-owl")
        self.model = load_world_vl(self.cfg.checkpoint)
        self.threshold = self.model.threshold if self.cfg.world_threshold < 0 else float(self.cfg.world_threshold)
        self.name = f"world-owl ({self.model.source})"
        self.text = text_encoder if text_encoder is not None else _default_text()
        self._goal: tuple[str, torch.Tensor] | None = None

    def reset(self, seed: int) -> None:
        del seed  # deterministic

    def detect(self, observation: dict, goal_text: str) -> list[Detection]:
        if self._goal is None or self._goal[0] != goal_text:
            self._goal = (goal_text, _unit_text(self.text, [goal_text]))
        rgb = np.asarray(observation["rgb"])
        top, _, _ = self.model.frame_features(rgb)
        probs = self.model.probs(top, self._goal[1])[0, 0]  # (h, w)
        if float(self.model.frame_score(probs[None])) < self.threshold:
            return []
        p = probs.numpy()
        labels, n = ndimage.label(p >= self.threshold)
        H, W = rgb.shape[:2]
        out = []
        for k in range(1, n + 1):
            cells = labels == k
            rows = (np.arange(H) * cells.shape[0]) // H
            cols = (np.arange(W) * cells.shape[1]) // W
            mask = cells[rows][:, cols]
            out.append(Detection(box_of(mask), float(p[cells].max()), goal_text, mask))
        return sorted(out, key=lambda d: -d.score)


class WorldVLScorer:
    """VLFM's value: the probability (SigLIP sigmoid of the frame embedding against the prompt) that the
    goal is in view."""

    privileged = False

    def __init__(self, cfg=None, text_encoder: TextEncoder | None = None) -> None:
        from ovon.models.config import ScorerConfig

        self.cfg = cfg or ScorerConfig(kind="world-vl")
        self.model = load_world_vl(self.cfg.checkpoint)
        self.name = f"world-vl value ({self.model.source})"
        self.text = text_encoder if text_encoder is not None else _default_text()
        self._goal: tuple[str, torch.Tensor] | None = None

    def reset(self, seed: int) -> None:
        del seed

    def score(self, observation: dict, goal_text: str) -> float:
        if self._goal is None or self._goal[0] != goal_text:
            self._goal = (goal_text, _unit_text(self.text, [self.cfg.prompt.format(goal=goal_text)]))
        _, _, glob = self.model.frame_features(np.asarray(observation["rgb"]))
        return float(self.model.global_probs(glob, self._goal[1])[0, 0])
