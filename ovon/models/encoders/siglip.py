"""SigLIP image encoder (the paper's frozen encoder), loaded only from local files.

Loaded through `ovon.models.hf.load_pretrained` (local files only, once per process). Uses the PIL image processor of
transformers 5 (`SiglipImageProcessorPil`), never `AutoImageProcessor` (which wants torchvision).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch

from ovon.models.config import DEFAULT_SIGLIP
from ovon.models.encoders.base import ObsBatch, get_obs
from ovon.models.hf import load_pretrained


def _missing_message(name_or_path: str, err: Exception) -> str:
    return (
        f"SigLIP model {name_or_path!r} is not available locally ({type(err).__name__}: "
        f"{str(err).splitlines()[0] if str(err) else ''}). Weights are never downloaded at run time. "
        f"On a machine with internet run `huggingface-cli download {name_or_path}` (or "
        f"`hf download {name_or_path}`), then copy ~/.cache/huggingface to this machine (or set "
        f"HF_HOME to the copy), or pass a folder written by `save_pretrained` as the model name. "
        f"Without weights use the default encoders (image=oracle-vl, text=minilm-text: oracle perception)."
    )


def load_siglip(name_or_path: str = DEFAULT_SIGLIP, device: str = "cpu") -> tuple[Any, Any, Any]:
    """(model, image_processor, tokenizer) from the local cache/folder; shared by image and text.

    Raises `ModelNotAvailableError` at once when the files are missing.
    """

    def classes() -> tuple[Any, Any, Any]:
        from transformers import SiglipImageProcessorPil, SiglipModel, SiglipTokenizer

        return SiglipModel, SiglipImageProcessorPil, SiglipTokenizer

    return load_pretrained("siglip", name_or_path, device, classes, lambda e: _missing_message(str(name_or_path), e))


def _l2(x: torch.Tensor) -> torch.Tensor:
    return x / x.norm(dim=-1, keepdim=True).clamp_min(1e-12)


class SiglipImageEncoder:
    """Frozen SigLIP image tower: RGB uint8 (B,H,W,3) -> `pooler_output` (B, projection dim)."""

    name = "siglip"
    trainable = False

    def __init__(self, model_name: str = DEFAULT_SIGLIP, device: str = "cpu", normalize: bool = True) -> None:
        self.model, self.processor, self.tokenizer = load_siglip(model_name, device)
        self.model_name = model_name
        self.device = device
        self.normalize = normalize
        cfg = self.model.config
        self.dim = int(getattr(cfg.vision_config, "projection_size", None) or cfg.vision_config.hidden_size)

    @torch.inference_mode()
    def encode(self, batch: ObsBatch) -> torch.Tensor:
        rgb = get_obs(batch, "rgb")
        if isinstance(rgb, torch.Tensor):
            rgb = rgb.cpu().numpy()
        rgb = np.asarray(rgb)
        if rgb.ndim == 3:
            rgb = rgb[None]
        if rgb.dtype != np.uint8:
            raise TypeError(f"SigLIP expects uint8 RGB frames, got {rgb.dtype}")
        pixels = self.processor(images=list(rgb), return_tensors="pt")["pixel_values"].to(self.device)
        out = self.model.get_image_features(pixel_values=pixels).pooler_output
        out = out.to(torch.float32)
        return (_l2(out) if self.normalize else out).cpu()

    def score(self, image_emb: torch.Tensor, text_emb: torch.Tensor) -> torch.Tensor:
        """Cosine image-text similarity (B, N), e.g. for the VLFM value map."""
        return _l2(image_emb.float()) @ _l2(text_emb.float()).T
