"""Encoder protocols shared by the policies, the modular baseline and the feature caches.

Why protocols: the paper's encoders (SigLIP) cannot be downloaded here, so perception is a pluggable
choice; everything downstream only relies on `dim`, `trainable` and `encode`.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any, Protocol, runtime_checkable

import numpy as np
import torch

# An observation batch: a mapping with any of "rgb" (B,H,W,3) uint8, "depth" (B,H,W) float metres,
# "semantic" (B,H,W) int32 instance ids; or a bare array, taken as the encoder's main input.
ObsBatch = Mapping[str, Any] | np.ndarray | torch.Tensor


class ModelNotAvailableError(RuntimeError):
    """A pretrained model is not in the local cache/folder (no machine here can download weights)."""


@runtime_checkable
class ImageEncoder(Protocol):
    """Per-frame image embedding."""

    name: str
    dim: int
    trainable: bool

    def encode(self, batch: ObsBatch) -> torch.Tensor:
        """Embed a batch of frames -> float32 (B, dim)."""
        ...


@runtime_checkable
class TextEncoder(Protocol):
    """Goal-text embedding with a per-string cache (goals repeat every episode)."""

    name: str
    dim: int

    def encode(self, texts: Sequence[str]) -> torch.Tensor:
        """Embed strings -> float32 (N, dim)."""
        ...


def get_obs(batch: ObsBatch, key: str) -> Any:
    """Pick `key` from a mapping batch; a bare array is returned as is (the main input)."""
    if isinstance(batch, Mapping):
        if key not in batch:
            raise KeyError(f"observation batch lacks {key!r}; it has {sorted(batch)}")
        return batch[key]
    return batch


class CachedTextEncoder:
    """Base for text encoders: embeds only strings not seen before, keeps the rest in memory."""

    name: str = "text"
    dim: int = 0

    def __init__(self) -> None:
        self._cache: dict[str, torch.Tensor] = {}

    def _embed(self, texts: list[str]) -> torch.Tensor:  # pragma: no cover - abstract
        raise NotImplementedError

    def encode(self, texts: Sequence[str]) -> torch.Tensor:
        if isinstance(texts, str):
            raise TypeError("encode() takes a list of strings, not a single string")
        missing = list(dict.fromkeys(t for t in texts if t not in self._cache))
        if missing:
            emb = self._embed(missing).detach().to(torch.float32).cpu()
            for t, e in zip(missing, emb):
                self._cache[t] = e
        if not texts:
            return torch.zeros(0, self.dim)
        return torch.stack([self._cache[t] for t in texts])

    def clear_cache(self) -> None:
        self._cache.clear()


class FunctionTextEncoder(CachedTextEncoder):
    """Wrap any `list[str] -> array (N, dim)` function (tests, custom models)."""

    def __init__(self, fn: Callable[[list[str]], Any], dim: int, name: str = "function-text") -> None:
        super().__init__()
        self._fn = fn
        self.dim = dim
        self.name = name

    def _embed(self, texts: list[str]) -> torch.Tensor:
        return torch.as_tensor(np.asarray(self._fn(texts), dtype=np.float32))
