"""Tensor plumbing shared by the algorithms: image batches (embeddings or raw frames for a trainable
CNN), the imitation loss and episode summaries."""

from __future__ import annotations

import numpy as np
import torch

from ovon.models.policy import NARROW_FLOATS

# An image batch: precomputed embeddings (..., D) float, or raw frames {"rgb": (..., H, W, 3) uint8,
# "depth": (..., H, W) float} for a trainable CNN that lives inside the policy.
Images = torch.Tensor | dict[str, torch.Tensor]


def features(policy, images: Images) -> torch.Tensor:
    """Image embeddings for a batch with any leading dims: a tensor passes through (float16 buffer
    embeddings too: `make_obs` widens them as it concatenates); raw frames go through the policy's
    trainable CNN (with gradients when called under grad)."""
    if isinstance(images, torch.Tensor):
        return images if images.dtype in NARROW_FLOATS else images.float()
    rgb = images["rgb"]
    lead = rgb.shape[:-3]
    flat = {k: v.reshape(-1, *v.shape[len(lead) :]) for k, v in images.items()}
    return policy.encode_images(flat).reshape(*lead, -1)


def stack_images(items: list[Images], dim: int = 0) -> Images:
    if isinstance(items[0], torch.Tensor):
        return torch.stack(items, dim)
    return {k: torch.stack([x[k] for x in items], dim) for k in items[0]}


def cat_images(items: list[Images]) -> Images:
    """Concatenate along the first (env) dimension."""
    if isinstance(items[0], torch.Tensor):
        return torch.cat(items)
    return {k: torch.cat([x[k] for x in items]) for k in items[0]}


def map_images(images: Images, fn) -> Images:
    return fn(images) if isinstance(images, torch.Tensor) else {k: fn(v) for k, v in images.items()}


def imitation_loss(logits: torch.Tensor, target: torch.Tensor, stop_weight: float = 1.0) -> torch.Tensor:
    """Cross-entropy on expert labels (entries < 0 are ignored); STOP (action 0) weighted by `stop_weight`.

    A weighted mean (divided by the summed weights), so `stop_weight=1` is the plain cross-entropy."""
    weight = None
    if stop_weight != 1.0:
        weight = torch.ones(logits.shape[-1], dtype=logits.dtype, device=logits.device)
        weight[0] = stop_weight
    return torch.nn.functional.cross_entropy(
        logits.reshape(-1, logits.shape[-1]), target.reshape(-1), weight=weight, ignore_index=-1
    )


def episode_summary(metrics: list[dict]) -> dict[str, float | None]:
    """Mean success / SPL / SoftSPL / length over finished episodes (None when none finished)."""
    if not metrics:
        return {"episode/count": 0.0}
    out: dict[str, float | None] = {"episode/count": float(len(metrics))}
    for k in ("success", "spl", "soft_spl", "steps", "distance_to_goal"):
        vals = [float(m[k]) for m in metrics if k in m and m[k] is not None]
        out[f"episode/{k}"] = float(np.mean(vals)) if vals else None
    return out
