"""What the learners share besides the chunk (`ovon.models.chunk`): the imitation loss and episode summaries."""

from __future__ import annotations

import numpy as np
import torch


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
