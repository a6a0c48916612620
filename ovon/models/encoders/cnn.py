"""Small trainable CNN on RGB (optionally + depth): an image encoder learned end to end.

Why: a perception baseline that uses only the agent's camera (no oracle, no downloaded weights).
Strided convolutions + GroupNorm + global average pooling make it size-agnostic (64x64 .. 160x120+).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import torch
from torch import nn

from ovon.models.encoders.base import ObsBatch, get_obs


def _as_tensor(x: np.ndarray | torch.Tensor, device: torch.device) -> torch.Tensor:
    return x.to(device) if isinstance(x, torch.Tensor) else torch.from_numpy(np.ascontiguousarray(x)).to(device)


class CNNEncoder(nn.Module):
    """uint8 RGB (B,H,W,3) [+ depth (B,H,W) metres] -> float32 (B, dim); trainable."""

    name = "cnn"
    trainable = True

    def __init__(
        self,
        dim: int = 256,
        channels: Sequence[int] = (32, 64, 128, 128),
        use_depth: bool = False,
        max_depth: float = 5.0,
    ) -> None:
        super().__init__()
        self.dim = dim
        self.use_depth = use_depth
        self.max_depth = max_depth
        layers: list[nn.Module] = []
        c_in = 4 if use_depth else 3
        for i, c in enumerate(channels):
            k, s = (5, 2) if i == 0 else (3, 2)
            layers += [nn.Conv2d(c_in, c, k, stride=s, padding=k // 2), nn.GroupNorm(min(8, c), c), nn.ReLU()]
            c_in = c
        self.convs = nn.Sequential(*layers)
        self.fc = nn.Sequential(nn.Linear(c_in, dim), nn.ReLU())

    def forward(self, rgb: torch.Tensor, depth: torch.Tensor | None = None) -> torch.Tensor:
        x = rgb.permute(0, 3, 1, 2).float() / 255.0
        if self.use_depth:
            if depth is None:
                raise ValueError("this CNN encoder was built with use_depth=True; pass depth")
            d = (depth.float() / self.max_depth).clamp(0.0, 1.0)
            x = torch.cat([x, d.reshape(d.shape[0], 1, *d.shape[-2:])], 1)
        x = self.convs(x).mean(dim=(2, 3))
        return self.fc(x)

    def encode(self, batch: ObsBatch) -> torch.Tensor:
        """Observation batch -> (B, dim) (keeps the autograd graph: this encoder is trained)."""
        dev = next(self.parameters()).device
        rgb = _as_tensor(get_obs(batch, "rgb"), dev)
        if rgb.ndim == 3:
            rgb = rgb[None]
        depth = None
        if self.use_depth:
            depth = _as_tensor(get_obs(batch, "depth"), dev)
            if depth.ndim == 2:
                depth = depth[None]
        return self.forward(rgb, depth)
