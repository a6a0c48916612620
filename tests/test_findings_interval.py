"""Findings across splits (flat, drop) judged on an unpaired bootstrap interval over each entry's episodes."""

from __future__ import annotations

from ovon.experiments.definitions import Check
from ovon.experiments.findings import judge_check
from ovon.experiments.report import split_gaps
from ovon.reports.splits import split_spread


def _records(rates: dict[str, float], episodes: int, seeds: int = 2) -> dict[str, list[dict]]:
    """ref -> records whose success is 1 on the first `rate` share of episodes (same on every seed)."""
    return {
        ref: [
            {"split": "s", "scene": "h", "episode_id": str(i), "seed": k, "success": i < rate * episodes}
            for i in range(episodes)
            for k in range(seeds)
        ]
        for ref, rate in rates.items()
    }


def _spread(by_ref: dict[str, list[dict]]):
    return lambda refs: split_spread([{**r, "split": ref} for ref in refs for r in by_ref[ref]])


def test_flat_across_splits_needs_an_interval_below_the_tolerance_to_hold() -> None:
    look = lambda r, m: (0.0, 0.0)  # noqa: E731  the std rule's numbers do not matter here
    flat = Check(kind="flat", refs=("A @ seen", "A @ unseen"), tolerance=5.0)
    wide = judge_check(flat, look, spread=_spread(_records({"A @ seen": 0.5, "A @ unseen": 0.3}, 500)))
    assert wide["interval"]["verdict"] == "does not hold"  # 20 points, interval about +14..+26
    assert wide["interval"]["numbers"].startswith("largest gap A @ seen - A @ unseen +20.0 [+1")
    close = judge_check(flat, look, spread=_spread(_records({"A @ seen": 0.5, "A @ unseen": 0.48}, 500)))
    assert close["interval"]["verdict"] == "not shown (the interval includes 5)"  # 500 episodes cannot show flat
    many = judge_check(flat, look, spread=_spread(_records({"A @ seen": 0.5, "A @ unseen": 0.5}, 20_000, 1)))
    assert many["interval"]["verdict"] == "holds"
    assert "interval" not in judge_check(flat, look, spread=lambda refs: None)  # an entry without episodes
    assert "interval" not in judge_check(Check(kind="greater", pairs=(("a", "b"),)), look, spread=lambda r: 1 / 0)


def test_a_drop_is_signed_from_the_first_entry_to_the_second() -> None:
    look = lambda r, m: (0.0, 0.0)  # noqa: E731
    drop = Check(kind="drop", pairs=(("A @ seen", "A @ unseen"),), tolerance=5.0)
    fell = judge_check(drop, look, spread=_spread(_records({"A @ seen": 0.5, "A @ unseen": 0.3}, 500)))
    assert fell["interval"]["verdict"] == "holds" and "A @ seen - A @ unseen +20.0 [+1" in fell["interval"]["numbers"]
    rose = judge_check(drop, look, spread=_spread(_records({"A @ seen": 0.4, "A @ unseen": 0.5}, 500)))
    assert rose["interval"]["verdict"] == "does not hold" and "-10.0 [-1" in rose["interval"]["numbers"]


def test_split_gaps_groups_table_entries_by_their_ref() -> None:
    """Two entries of one evaluation on two splits: each ref gets its split's records (none: None)."""
    recs = [
        {"split": split, "scene": "h", "episode_id": str(i), "seed": 0, "success": i < n}
        for split, n in (("val_seen", 6), ("val_unseen", 2))
        for i in range(10)
    ]
    evals = {"vlfm": {"records": recs}, "other": {"records": []}}
    got = split_gaps(
        evals, {"V @ seen": {"eval": "vlfm", "split": "val_seen"}, "V @ un": {"eval": "vlfm", "split": "val_unseen"}}
    )
    assert got is not None and got["splits"]["V @ seen"]["sr"] == 0.6 and got["splits"]["V @ un"]["sr"] == 0.2
    assert (
        split_gaps(
            evals, {"V @ seen": {"eval": "vlfm", "split": "val_seen"}, "O": {"eval": "other", "split": "val_seen"}}
        )
        is None
    )


def test_the_report_prints_an_interval_verdict_under_its_rule() -> None:
    from ovon.experiments.report import findings_markdown

    check = {"rule": "r", "numbers": "n", "verdict": "holds", "within_noise": False}
    check["interval"] = {
        "verdict": "not shown (the interval includes 5)",
        "numbers": "largest gap A - B +3.0 [-2.8, +8.8]",
    }
    finding = {
        "id": "d",
        "claim": "c",
        "note": "",
        "ours": {"verdict": "holds", "within_noise": False, "checks": [check]},
    }
    lines = findings_markdown([{**finding, "paper": {"verdict": "holds"}}])
    assert "  - episodes: **not shown (the interval includes 5)**: largest gap A - B +3.0 [-2.8, +8.8]" in lines
