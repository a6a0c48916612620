"""A text encoder backed by a precomputed {text: embedding} table.

Why: the goal vocabulary is fixed per run, so the trainer embeds it once (one language model load) and
ships the table to every env worker and into `policy.pt`; a worker then never loads a language model
unless it meets a text the table lacks.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch

from ovon.models.config import EncoderConfig
from ovon.models.encoders.base import CachedTextEncoder


class TableTextEncoder(CachedTextEncoder):
    """Texts from the table; misses go to the real encoder named by `cfg` (built lazily)."""

    def __init__(self, table: dict[str, Any], cfg: EncoderConfig | None = None) -> None:
        super().__init__()
        self.cfg = cfg
        self._model = None
        for k, v in table.items():
            self._cache[k] = torch.as_tensor(np.asarray(v, dtype=np.float32))
        first = next(iter(self._cache.values()), None)
        self.dim = int(first.shape[-1]) if first is not None else 0
        self.name = f"table({cfg.text if cfg else 'fixed'})"

    def _embed(self, texts: list[str]) -> torch.Tensor:
        if self.cfg is None:
            raise KeyError(f"text(s) {texts[:5]} are not in the embedding table and no text encoder is configured")
        if self._model is None:
            from ovon.models.encoders import make_text_encoder

            self._model = make_text_encoder(self.cfg)
            self.dim = int(self._model.dim)
        return self._model.encode(texts)

    def table(self) -> dict[str, torch.Tensor]:
        return dict(self._cache)
