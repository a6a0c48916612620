"""benchmarks/vlfm_stops.py on hand-made run folders: distances to the success region and to the goal per
failure label, SR / SPL against the first run, the JSON it writes, and its one-line errors."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _script():
    spec = importlib.util.spec_from_file_location("vlfm_stops", ROOT / "benchmarks" / "vlfm_stops.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _record(i: int, success: bool, failure: str | None, d: float, to_object: float | None, in_view: bool) -> dict:
    r = {
        "split": "val_seen",
        "scene": "s.glb",
        "episode_id": str(i),
        "seed": 0,
        "success": success,
        "spl": 0.5 if success else 0.0,
        "soft_spl": 0.5,
        "distance_to_goal": d,
        "steps": 10,
        "collisions": 0,
        "failure": failure,
        "goal_in_view": in_view,
        "category": "chair",
        "geodesic_distance": 3.0,
    }
    if to_object is not None:
        r["distance_to_object"] = to_object
    return r


def _run(folder: Path, records: list[dict]) -> Path:
    folder.mkdir()
    (folder / "run.json").write_text(
        json.dumps(
            {
                "agent": "vlfm",
                "task": {"success_distance": 0.25},
                "sim": {"camera": {"width": 72, "height": 128, "hfov_deg": 42}},
            }
        )
    )
    (folder / "episodes.jsonl").write_text("".join(json.dumps(r, sort_keys=True) + "\n" for r in records))
    return folder


def test_stop_distances_per_label_and_comparison(tmp_path, capsys):
    mod = _script()
    before = _run(
        tmp_path / "before",
        [
            _record(0, True, None, 0.1, 0.7, True),
            _record(1, False, "stop_too_far", 0.55, 0.85, False),  # 0.30 m outside the region
            _record(2, False, "stop_too_far", 0.95, 0.88, True),  # 0.70 m outside
            _record(3, False, "timeout_missed_goal", 5.25, None, False),  # an old record: no distance_to_object
        ],
    )
    after = _run(
        tmp_path / "after",
        [
            _record(0, True, None, 0.1, 0.7, True),
            _record(1, True, None, 0.2, 0.6, True),
            _record(2, False, "stop_too_far", 0.95, 0.88, True),
            _record(3, False, "timeout_missed_goal", 5.25, 3.0, False),
        ],
    )
    out = tmp_path / "stops.json"
    assert mod.main([f"before={before}", f"after={after}", "--out", str(out)]) == 0
    res = json.loads(out.read_text())["runs"]
    b, a = res
    assert (b["sr"], a["sr"]) == (25.0, 50.0) and a["vs_before"]["sr"] == 25.0
    far = b["failures"]["stop_too_far"]
    assert far["episodes"] == 2
    assert far["to_region_m"]["median"] == pytest.approx(0.5) and far["to_region_m"]["max"] == pytest.approx(0.7)
    assert far["to_object_m"]["mean"] == pytest.approx(0.865) and far["goal_in_view"] == 0.5
    assert far["to_region_histogram"] == {"<=0.25": 0, "0.25-0.5": 1, "0.5-1.0": 1, "1.0-2.0": 0, ">2.0": 0}
    assert b["failures"]["timeout_missed_goal"]["to_object_m"] is None
    assert b["failed_stops"] == 2 and b["failed_stops_within_0.5m_of_region"] == 1
    printed = capsys.readouterr().out
    assert "| stop_too_far | 2 | 0.50 / 0.50 / 0.66 |" in printed and "SR +25.0" in printed


def test_errors_are_one_line(tmp_path):
    mod = _script()
    with pytest.raises(SystemExit, match="no run.json"):
        mod.main([str(tmp_path), "--out", str(tmp_path / "x.json")])
    empty = _run(tmp_path / "empty", [])
    with pytest.raises(SystemExit, match="holds no records"):
        mod.main([str(empty), "--out", str(tmp_path / "x.json")])
    run = _run(tmp_path / "random", [_record(0, False, "stop_too_far", 0.5, 0.6, False)])
    meta = json.loads((run / "run.json").read_text())
    (run / "run.json").write_text(json.dumps({**meta, "agent": "random", "agent_kwargs": {}}))
    with pytest.raises(SystemExit, match="needs a modular agent"):
        mod.main([f"r={run}", "--replay", "--out", str(tmp_path / "x.json")])


def test_replay_finds_the_agents_goal_point_on_the_goal(tiny_dataset, tiny_scenes, tmp_path):
    """VLFM told to stop 3 m from its goal point fails with stop_too_far; replayed, its actions match the
    record, its goal point lies on the goal object, every lifted point on a goal-category box, rho < 3 m."""
    from ovon.cli.main import main as ovon

    run = tmp_path / "vlfm_far"
    assert (
        ovon(
            [
                "evaluate",
                "--agent",
                "vlfm",
                "--agent-arg",
                "navigator.stop_distance_m=3.0",
                "--data",
                str(tiny_dataset),
                "--scenes",
                str(tiny_scenes),
                "--splits",
                "val_seen",
                "--episodes",
                "2",
                "--workers",
                "1",
                "--no-progress",
                "--set",
                "task.max_steps=80",
                "--out",
                str(run),
            ]
        )
        == 0
    )
    out = tmp_path / "stops.json"
    assert _script().main([f"far={run}", "--replay", "--out", str(out)]) == 0
    rep = json.loads(out.read_text())["runs"][0]["replay"]
    assert rep["episodes"] >= 1 and rep["replays_matching_the_record"] == rep["episodes"]
    near = [r for r in rep["per_episode"] if r["cause"] == "near_miss"]
    assert near, rep["per_episode"]
    for r in near:
        assert r["goal_point_to_goal_m"] <= 0.1 and r["rho"] < 3.0 and r["lifted_off_category"] == 0.0
