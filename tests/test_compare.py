"""`ovon compare`: paired differences, bootstrap intervals and the sign test, on known outcomes and on real runs."""

from __future__ import annotations

import json

import numpy as np
import pytest

from ovon.cli.main import main as ovon
from ovon.reports.paired import compare_pairs, pair_records


def _records(successes: list[int], seeds: int = 1, split: str = "val_seen") -> list[dict]:
    return [
        {"split": split, "seed": s, "scene": "hm3d/val/x.glb", "episode_id": str(i), "success": bool(v), "spl": 0.5 * v}
        for s in range(seeds)
        for i, v in enumerate(successes)
    ]


def test_a_clear_gain_has_an_interval_above_zero_and_a_small_sign_test_p():
    a, b = _records([0] * 40), _records([1] * 30 + [0] * 10)
    res = {r.split: r for r in compare_pairs(pair_records(a, b, "A", "B"), resamples=2000)}
    sr, spl = res["val_seen"].stats
    assert sr.diff == pytest.approx(0.75) and sr.ci_low > 0.5 and sr.verdict == "B better"
    assert spl.diff == pytest.approx(0.375)
    assert (res["val_seen"].sign.b_wins, res["val_seen"].sign.a_wins) == (30, 0)
    assert res["val_seen"].sign.p_value < 1e-8
    assert res["(all splits)"].episodes == 40


def test_the_same_runs_show_no_difference_and_seeds_move_with_their_episode():
    a = _records([1, 0, 1, 0, 1] * 4, seeds=3)
    (r, _all) = compare_pairs(pair_records(a, a, "A", "A"), resamples=500)
    assert (r.stats[0].diff, r.stats[0].ci_low, r.stats[0].ci_high) == (0, 0, 0)
    assert r.sign.p_value == 1.0 and r.episodes == 20 and r.seeds == 3


def test_balanced_disagreement_is_no_difference():
    a, b = _records([1, 0] * 20), _records([0, 1] * 20)
    sr = compare_pairs(pair_records(a, b, "A", "B"), resamples=2000)[0].stats[0]
    assert sr.diff == 0 and sr.ci_low < 0 < sr.ci_high and sr.verdict == "no difference shown"


def test_runs_of_different_episodes_are_refused_in_one_line():
    with pytest.raises(ValueError, match=r"A and B ran different episodes \(1 only in A, 0 only in B") as e:
        pair_records(_records([1, 1]), _records([1]), "A", "B")
    assert "\n" not in str(e.value)


def test_cli_compares_real_runs_and_refuses_mismatched_ones(tiny_dataset, tiny_scenes, tmp_path, capsys):
    common = ["--data", str(tiny_dataset), "--scenes", str(tiny_scenes), "--splits", "val_seen", "--seeds", "0"]
    common += ["--workers", "1", "--no-progress"]
    for agent, n in (("random", "6"), ("shortest-path", "6"), ("shortest-path", "3")):
        out = tmp_path / f"{agent}{n}"
        assert ovon(["evaluate", "--agent", agent, *common, "--episodes", n, "--out", str(out)]) == 0
    capsys.readouterr()
    rc = ovon(["compare", str(tmp_path / "random6"), str(tmp_path / "shortest-path6"), "--out", str(tmp_path / "c")])
    assert rc == 0
    result = json.loads((tmp_path / "c" / "compare.json").read_text())
    (comp,) = result["comparisons"]
    assert [s["split"] for s in comp["splits"]] == ["val_seen", "(all splits)"]
    sr = comp["splits"][0]["stats"][0]
    assert sr["b"] == 1.0 and sr["diff"] > 0.5 and sr["ci_low"] > 0
    assert "| shortest-path | val_seen | 6 x 1 |" in (tmp_path / "c" / "compare.md").read_text()
    capsys.readouterr()
    assert ovon(["compare", str(tmp_path / "random6"), str(tmp_path / "shortest-path3")]) == 2
    err = capsys.readouterr().err.strip()
    assert "ran different episodes (3 only in random" in err and "\n" not in err
    assert ovon(["compare", str(tmp_path / "random6")]) == 2


def test_each_split_states_the_difference_its_episodes_detect():
    a, b = _records([1, 0] * 20), _records([0, 1] * 20)
    (r, _all) = compare_pairs(pair_records(a, b, "A", "B"), resamples=500)
    d = [-1.0, 1.0] * 20  # B - A per episode: sd 1.013, so MDE = 2.80 * 1.013 / sqrt(40)
    assert r.mde == pytest.approx(2.8016 * np.std(d, ddof=1) / np.sqrt(40), rel=1e-3)
    # identical runs: no spread to measure, so the planning value at their SR (60%) stands in
    same = _records([1, 0, 1, 0, 1] * 4)
    (r, _all) = compare_pairs(pair_records(same, same, "A", "A"), resamples=500)
    assert r.mde == pytest.approx(2.8016 * np.sqrt(2 * 0.6 * 0.4) / np.sqrt(20), rel=1e-3)


def test_the_table_names_the_mde_in_a_verdict_that_shows_no_difference(tiny_dataset, tiny_scenes, tmp_path):
    from ovon.reports.paired import compare_runs, paired_table

    common = ["--data", str(tiny_dataset), "--scenes", str(tiny_scenes), "--splits", "val_seen", "--seeds", "0"]
    common += ["--workers", "1", "--no-progress", "--episodes", "4"]
    for name in ("a", "b"):
        assert ovon(["evaluate", "--agent", "shortest-path", *common, "--out", str(tmp_path / name)]) == 0
    result = compare_runs([tmp_path / "a", tmp_path / "b"], resamples=200)
    split = result["comparisons"][0]["splits"][0]
    assert split["verdict"] == f"no difference shown (MDE {100 * split['mde']:.1f} pts)"
    assert split["mde"] == pytest.approx(2.8016 / 2, rel=1e-3)  # both SR 100%: the worst case over 4 episodes
    table = paired_table(result)
    assert "| MDE SR | verdict (SR) |" in table and f"| {100 * split['mde']:.1f} | {split['verdict']} |" in table
