"""Frame-level detection scores and their calibration (shared by pretraining and `ovon perception evaluate`).

A (frame, goal name) pair is positive when an instance counted for that name covers at least `visible_share`
of the frame: strictly the name's own instances, or (synonym-tolerant) any instance of a name with the same
look (`ovon.scenes.procedural.looks`). Candidates are the names of the objects of the frame's house.
"""

from __future__ import annotations

import numpy as np
import torch

from ovon.models.world.net import POOLINGS, pool_cells
from ovon.perception.frames import HouseFrames


def frame_scores(net, frames: HouseFrames, text: torch.Tensor, batch: int = 64) -> dict[str, np.ndarray]:
    """Per pooling mode, (N, C) scores of every frame against every category of its house."""
    t = text[torch.as_tensor(frames.house_cats, dtype=torch.long)]
    out: dict[str, list[np.ndarray]] = {m: [] for m in POOLINGS}
    for i in range(0, len(frames.rgb), batch):
        top, _, _ = net.features(torch.from_numpy(frames.rgb[i : i + batch]))
        probs = torch.sigmoid(net.logit_scale.exp() * net.cell_cosines(top, t) + net.logit_bias)
        for m in POOLINGS:
            out[m].append(pool_cells(probs, m).numpy())
    return {m: np.concatenate(v) for m, v in out.items()}


def frame_labels(frames: HouseFrames, visible_share: float, groups: np.ndarray | None = None) -> np.ndarray:
    """(N, C) bool: the house category is visible at `visible_share` in the frame. `groups` (K,) maps each
    category index to its synonym group (synonym-tolerant labels); None: strict."""
    cats = frames.house_cats
    pos = np.zeros((len(frames.rgb), len(cats)), dtype=bool)
    col = {int(c): j for j, c in enumerate(cats)}
    for f, c, share in frames.inst[:, :3]:
        if share < visible_share:
            continue
        if groups is None:
            j = col.get(int(c))
            if j is not None:
                pos[int(f), j] = True
        else:
            pos[int(f)] |= groups[cats] == groups[int(c)]
    return pos


def pr_curve(scores: np.ndarray, labels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Precision and recall at every distinct threshold, highest first (tied scores are one threshold)."""
    if len(scores) == 0:
        return np.zeros(0), np.zeros(0)
    order = np.argsort(-scores, kind="stable")
    s, y = scores[order], labels[order]
    tp = np.cumsum(y)
    last = np.r_[s[1:] != s[:-1], True]
    k = np.arange(1, len(y) + 1)
    return (tp / k)[last], (tp / max(1, y.sum()))[last]


def average_precision(scores: np.ndarray, labels: np.ndarray) -> float:
    """AP with tied scores taken as one threshold (sklearn's definition): an oracle's scores are mostly tied,
    and ranking ties by pair order would make its AP depend on that order."""
    if labels.sum() == 0:
        return float("nan")
    precision, recall = pr_curve(scores, labels)
    return float(np.sum(np.diff(np.r_[0.0, recall]) * precision))


def pr_at(scores: np.ndarray, labels: np.ndarray, threshold: float) -> tuple[float, float]:
    pred = scores >= threshold
    tp = float((pred & labels).sum())
    precision = tp / pred.sum() if pred.any() else float("nan")
    recall = tp / labels.sum() if labels.any() else float("nan")
    return precision, recall


def best_threshold(scores: np.ndarray, labels: np.ndarray, min_precision: float) -> float:
    """The threshold with the best recall at precision >= min_precision (the most precise one if none)."""
    order = np.argsort(-scores, kind="stable")
    s, y = scores[order], labels[order]
    tp = np.cumsum(y)
    precision = tp / np.arange(1, len(y) + 1)
    recall = tp / max(1, y.sum())
    last = np.r_[s[1:] != s[:-1], True]  # a threshold can only sit between distinct scores
    ok = last & (precision >= min_precision)
    if ok.any():
        k = np.flatnonzero(ok)[np.argmax(recall[ok])]
    else:
        k = int(np.argmax(np.where(last, precision, -1)))
    return float(s[k])


def calibrate(houses: list[HouseFrames], scores: list[dict[str, np.ndarray]], visible_share: float,
              min_precision: float) -> dict:  # fmt: skip
    """Choose the pooling (best AP) and the threshold (best recall at min_precision) on these houses."""
    labels = np.concatenate([frame_labels(h, visible_share).ravel() for h in houses])
    best = None
    for mode in POOLINGS:
        s = np.concatenate([sc[mode].ravel() for sc in scores])
        ap = average_precision(s, labels)
        if best is None or ap > best["ap"]:
            thr = best_threshold(s, labels, min_precision)
            p, r = pr_at(s, labels, thr)
            best = {"pooling": mode, "threshold": thr, "ap": ap, "precision": p, "recall": r}
    best.update({"visible_share": visible_share, "min_precision": min_precision, "positives": int(labels.sum()),
                 "pairs": int(labels.size), "frames": int(sum(len(h.rgb) for h in houses))})  # fmt: skip
    return best
