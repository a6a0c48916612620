"""One agent's splits against each other: SR per split and every gap, with seeded bootstrap intervals."""

from __future__ import annotations

import numpy as np
import pytest

from ovon.reports.splits import split_spread, split_success, spread_lines


def _records(split: str, successes: list[int], seeds: int = 2) -> list[dict]:
    return [
        {"split": split, "scene": "s", "episode_id": str(i), "seed": k, "success": bool(v)}
        for k in range(seeds)
        for i, v in enumerate(successes)
    ]


def test_a_large_gap_is_shown_and_an_equal_pair_is_not():
    rng = np.random.default_rng(0)
    recs = (
        _records("val_seen", list(rng.random(400) < 0.5))
        + _records("val_unseen", list(rng.random(400) < 0.2))
        + _records("val_seen_synonyms", list(rng.random(400) < 0.5))
    )
    res = split_spread(recs, resamples=2000)
    sr = {s: v["sr"] for s, v in res["splits"].items()}
    assert sr == pytest.approx({s: float(split_success(recs)[s].mean()) for s in sr})
    sp = res["spread"]
    assert sp["b"] == "val_unseen" and sp["diff"] == pytest.approx(max(sr.values()) - sr["val_unseen"])
    assert sp["ci"][0] > 0.15 and sp["ci"][0] < sp["diff"] < sp["ci"][1]
    same = next(p for p in res["pairs"] if {p["a"], p["b"]} == {"val_seen", "val_seen_synonyms"})
    assert same["ci"][0] < 0 < same["ci"][1]  # both near 50%: not shown
    # half-width ~ 1.96 * sqrt(2 * 0.25 / 400) = 6.9 points for the equal pair
    assert (same["ci"][1] - same["ci"][0]) / 2 == pytest.approx(0.069, abs=0.015)
    lines = spread_lines(res)
    assert lines[0].startswith("SR per split, 95% bootstrap interval over episodes: ")
    assert "(unpaired: the splits hold different episodes)" in lines[1]
    assert any("not shown (the interval includes 0)" in ln for ln in lines[2:])
    assert split_spread(recs, resamples=2000) == res  # seeded


def test_seeds_of_an_episode_move_together_and_one_split_gives_none():
    # every episode solved on seed 0 only: per-episode success 0.5, no episode-level spread at all
    recs = [
        {"split": sp, "scene": "s", "episode_id": str(i), "seed": k, "success": k == 0}
        for sp in ("val_seen", "val_unseen")
        for i in range(50)
        for k in range(2)
    ]
    res = split_spread(recs, resamples=500)
    assert res["splits"]["val_seen"]["ci"] == pytest.approx((0.5, 0.5))
    assert res["spread"]["diff"] == 0.0 and res["spread"]["ci"] == pytest.approx((0.0, 0.0))
    assert split_spread(_records("val_seen", [1, 0, 1])) is None
