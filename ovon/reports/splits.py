"""How far apart one agent's splits are: SR per split and the difference between every two splits, each with
a seeded 95% bootstrap interval.

Why: the paper reads generalisation off the gap between val_seen, val_seen_synonyms and val_unseen. The
splits hold different episodes, so the gap is unpaired: each split's episodes are resampled on their own (an
episode's seeds move together, they share its difficulty). A gap whose interval includes 0 is not shown by
these episodes, however large it looks.
"""

from __future__ import annotations

import itertools
import math
from collections import defaultdict

import numpy as np


def split_success(records: list[dict]) -> dict[str, np.ndarray]:
    """split -> per-episode success, averaged over the episode's seeds (splits in sorted order)."""
    acc: dict[str, dict[tuple, list[float]]] = defaultdict(lambda: defaultdict(list))
    for r in records:
        acc[r["split"]][(r["scene"], str(r["episode_id"]))].append(float(r["success"]))
    return {s: np.array([math.fsum(v) / len(v) for _, v in sorted(eps.items())]) for s, eps in sorted(acc.items())}


def split_spread(records: list[dict], resamples: int = 10_000, seed: int = 0, level: float = 0.95) -> dict | None:
    """SR per split and SR(a) - SR(b) for every two splits, as fractions with (low, high) intervals; `spread`
    is the pair with the largest gap. None with fewer than two splits."""
    per = split_success(records)
    if len(per) < 2:
        return None
    rng = np.random.default_rng(seed)
    boot = {s: v[rng.integers(0, len(v), size=(resamples, len(v)))].mean(axis=1) for s, v in per.items()}
    q = ((1 - level) / 2, (1 + level) / 2)
    splits = {
        s: {"sr": float(v.mean()), "ci": tuple(float(x) for x in np.quantile(boot[s], q)), "episodes": len(v)}
        for s, v in per.items()
    }
    pairs = []
    for a, b in itertools.combinations(per, 2):
        if splits[a]["sr"] < splits[b]["sr"]:
            a, b = b, a
        d = boot[a] - boot[b]
        pairs.append(
            {
                "a": a,
                "b": b,
                "diff": splits[a]["sr"] - splits[b]["sr"],
                "ci": tuple(float(x) for x in np.quantile(d, q)),
            }
        )
    spread = max(pairs, key=lambda p: (p["diff"], p["a"], p["b"]))
    return {"splits": splits, "pairs": pairs, "spread": spread, "level": level, "resamples": resamples}


def spread_lines(result: dict) -> list[str]:
    """The report's lines: SR per split with its interval, then each gap (highest first) with its verdict."""
    pct = lambda x: 100 * x  # noqa: E731
    lev = round(100 * result["level"])
    sp = result["spread"]
    lines = [
        "SR per split, "
        + f"{lev}% bootstrap interval over episodes: "
        + "; ".join(
            f"{s} {pct(v['sr']):.1f} [{pct(v['ci'][0]):.1f}, {pct(v['ci'][1]):.1f}] ({v['episodes']} episodes)"
            for s, v in result["splits"].items()
        ),
        f"Spread across splits: {sp['a']} - {sp['b']} {pct(sp['diff']):+.1f} points "
        f"[{pct(sp['ci'][0]):+.1f}, {pct(sp['ci'][1]):+.1f}] (unpaired: the splits hold different episodes).",
    ]
    for p in sorted(result["pairs"], key=lambda p: -p["diff"]):
        shown = "shown" if p["ci"][0] > 0 else "not shown (the interval includes 0)"
        lines.append(
            f"- {p['a']} - {p['b']}: {pct(p['diff']):+.1f} [{pct(p['ci'][0]):+.1f}, {pct(p['ci'][1]):+.1f}], {shown}"
        )
    return lines
