"""Evaluation harness: oracle/random sanity, resumable runs, released-format episodes, reports, videos."""

import gzip
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import pytest

from ovon.cli.main import main as ovon
from ovon.dataset.episodes import load_specs
from ovon.evaluate.config import EvalConfig, parse_noise
from ovon.evaluate.harness import evaluate
from ovon.evaluate.results import read_records, record_key

FIXTURES = Path(__file__).parent / "fixtures"


def cfg_for(tiny_dataset, tiny_scenes, agent, **kw) -> EvalConfig:
    return EvalConfig(agent=agent, data=str(tiny_dataset), scenes=str(tiny_scenes), **kw)


def test_shortest_path_oracle_is_near_perfect(tiny_dataset, tiny_scenes, tmp_path):
    summary = evaluate(cfg_for(tiny_dataset, tiny_scenes, "shortest-path"), tmp_path / "sp", progress=False)
    n = 0
    for split, s in summary["splits"].items():
        n += s["episodes"]
        assert s["sr"]["mean"] >= 0.98, split
        assert s["spl"]["mean"] >= 0.9, split
    assert n == sum(len(load_specs(str(tiny_dataset), str(tiny_scenes), sp, None)) for sp in summary["splits"])


def test_random_agent_is_near_zero(tiny_dataset, tiny_scenes, tmp_path):
    summary = evaluate(cfg_for(tiny_dataset, tiny_scenes, "random", seeds=(0, 1)), tmp_path / "rnd", progress=False)
    for s in summary["splits"].values():
        assert s["sr"]["mean"] <= 0.15
        assert set(s["seeds"]) == {0, 1}
    recs = read_records(tmp_path / "rnd")
    assert all(r["failure"] for r in recs if not r["success"])


def test_interrupted_run_resumes_to_the_same_summary(tiny_dataset, tiny_scenes, tmp_path):
    full = evaluate(cfg_for(tiny_dataset, tiny_scenes, "random", seeds=(0, 1)), tmp_path / "full", progress=False)
    run = tmp_path / "killed"
    cmd = [
        sys.executable,
        "-m",
        "ovon.cli.main",
        "evaluate",
        "--agent",
        "random",
        "--data",
        str(tiny_dataset),
        "--scenes",
        str(tiny_scenes),
        "--seeds",
        "0,1",
        "--workers",
        "1",
        "--no-progress",
        "--out",
        str(run),
    ]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    deadline = time.time() + 120
    while time.time() < deadline:
        f = run / "episodes.jsonl"
        if f.exists() and f.read_bytes().count(b"\n") >= 5:
            break
        time.sleep(0.05)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    partial = read_records(run)
    assert 5 <= len(partial) < sum(s["episodes"] for s in full["splits"].values())
    with open(run / "episodes.jsonl", "a") as f:  # a torn line, as a kill mid-write leaves
        f.write('{"split": "val_seen", "seed": 0, "sce')
    resumed = evaluate(cfg_for(tiny_dataset, tiny_scenes, "random", seeds=(0, 1)), run, progress=False)
    assert resumed["splits"] == full["splits"]
    keys = [record_key(r) for r in read_records(run)]
    assert len(keys) == len(set(keys))


def test_noise_spec_parsing_and_metrics_use_true_pose(tiny_dataset, tiny_scenes, tmp_path):
    n = parse_noise("actuation:movebase*0.5,odometry")
    assert n.actuation == "movebase" and n.actuation_multiplier == 0.5 and n.odometry
    with pytest.raises(ValueError, match="unknown noise"):
        parse_noise("wind")
    cfg = cfg_for(tiny_dataset, tiny_scenes, "shortest-path", splits=("val_seen",), episodes=4)
    cfg = replace(cfg, sim=replace(cfg.sim, noise=parse_noise("actuation,odometry")))
    evaluate(cfg, tmp_path / "noisy", progress=False)
    clean = evaluate(replace(cfg, sim=replace(cfg.sim, noise=parse_noise(""))), tmp_path / "clean", progress=False)
    noisy = read_records(tmp_path / "noisy")
    assert [r["path_length"] for r in noisy] != [r["path_length"] for r in read_records(tmp_path / "clean")]
    assert clean["splits"]["val_seen"]["sr"]["mean"] >= 0.98


def test_user_agent_by_module_path(tiny_dataset, tiny_scenes, tmp_path):
    summary = evaluate(
        cfg_for(tiny_dataset, tiny_scenes, "tests.example_agent:TurnInPlaceAgent", splits=("val_unseen",), episodes=3),
        tmp_path / "user",
        progress=False,
    )
    assert summary["splits"]["val_unseen"]["episodes"] == 3
    with pytest.raises(ValueError, match="unknown agent"):
        evaluate(cfg_for(tiny_dataset, tiny_scenes, "nope", episodes=1), tmp_path / "bad", progress=False)


def write_release_fixture(root: Path) -> tuple[Path, Path]:
    """A released-format val_seen split for the hand-written HM3DSem fixture scene (textured semantics)."""
    scenes = root / "scene_datasets"
    shutil.copytree(FIXTURES / "hm3dsem" / "00001-FixtureScn01", scenes / "hm3d" / "val" / "00001-FixtureScn01")
    data = root / "objectnav_hm3d_ovon"
    content = data / "val_seen" / "content"
    content.mkdir(parents=True)
    with gzip.open(data / "val_seen" / "val_seen.json.gz", "wt") as f:
        json.dump({"episodes": [], "category_to_task_category_id": {"couch": 0}}, f)
    episode = {
        "episode_id": "0",
        "scene_id": "hm3d/val/00001-FixtureScn01/FixtureScn01.basis.glb",
        "scene_dataset_config": "./data/scene_datasets/hm3d/hm3d_annotated_basis.scene_dataset_config.json",
        "additional_obj_config_paths": [],
        "start_position": [2.3, 0.0, 2.3],
        "start_rotation": [0.0, 0.0, 0.0, 1.0],
        "info": {"geodesic_distance": 2.55, "euclidean_distance": 2.55},
        "goals": [],
        "start_room": None,
        "shortest_paths": None,
        "object_category": "couch",
        "children_object_categories": [],
    }
    goals = {
        "FixtureScn01.basis.glb_couch": [
            {
                "object_category": "couch",
                "object_id": "couch_1",
                "object_name": "couch_1",
                "position": [0.0, 0.4, 0.0],
                "radius": None,
                "room_id": None,
                "room_name": None,
                "view_points": [
                    {"agent_state": {"position": [0.0, 0.0, 1.2], "rotation": [0.0, 0.0, 0.0, 1.0]}, "iou": 0.4}
                ],
            }
        ]
    }
    with gzip.open(content / "FixtureScn01.json.gz", "wt") as f:
        json.dump({"episodes": [episode], "goals_by_category": goals}, f)
    (content / "._FixtureScn01.json.gz").write_bytes(b"\x00\x05\x16\x07 AppleDouble junk")
    return data, scenes


def test_released_format_episode_runs_end_to_end(tmp_path):
    data, scenes = write_release_fixture(tmp_path)
    with pytest.warns(UserWarning, match="._FixtureScn01"):
        summary = evaluate(
            EvalConfig(agent="shortest-path", data=str(data), scenes=str(scenes), splits=("val_seen",)),
            tmp_path / "run",
            progress=False,
        )
    assert summary["splits"]["val_seen"]["episodes"] == 1
    (rec,) = read_records(tmp_path / "run")
    assert rec["success"] and rec["spl"] > 0.8
    # The dataset folder itself also works as --scenes (docs/spec.md#episode-records: the scene_id rule).
    specs = load_specs(str(data), str(scenes / "hm3d"), "val_seen", None)
    assert specs[0].scene.endswith("FixtureScn01.glb")


def test_cli_evaluate_report_and_video(tiny_dataset, tiny_scenes, tmp_path, capsys):
    run = tmp_path / "cli_sp"
    assert (
        ovon(
            [
                "evaluate",
                "--agent",
                "shortest-path",
                "--data",
                str(tiny_dataset),
                "--scenes",
                str(tiny_scenes),
                "--splits",
                "val_seen,val_unseen",
                "--episodes",
                "3",
                "--workers",
                "1",
                "--no-progress",
                "--out",
                str(run),
            ]
        )
        == 0
    )
    out = capsys.readouterr().out
    assert "| shortest-path |" in out and "val_unseen SR" in out
    assert (run / "summary.json").exists() and (run / "table.md").exists()
    assert ovon(["report", str(run), "--out", str(tmp_path / "rep")]) == 0
    for name in ("report.md", "sr_vs_distance.png", "failures_shortest-path.png", "sr_per_category_shortest-path.png"):
        assert (tmp_path / "rep" / name).stat().st_size > 0
    report = (tmp_path / "rep" / "report.md").read_text()
    assert "Power: with 3 episodes, a paired comparison detects an SR difference of 161.7 points at worst" in report
    ep = read_records(run)[0]
    assert (
        ovon(
            [
                "video",
                "--run",
                str(run),
                "--episode",
                ep["episode_id"],
                "--split",
                ep["split"],
                "--scene",
                Path(ep["scene"]).parent.name,
                "--out",
                str(tmp_path / "ep.mp4"),
            ]
        )
        == 0
    )
    import imageio.v2 as imageio

    n_frames = sum(1 for _ in imageio.get_reader(tmp_path / "ep.mp4"))
    assert n_frames >= ep["steps"] + 1
    assert ovon(["video", "--run", str(run), "--episode", "no-such", "--out", str(tmp_path / "x.mp4")]) == 2


def test_seeds_that_ran_the_same_episodes_to_the_same_ends_are_flagged():
    """A deterministic agent without noise repeats one run per seed: its std over seeds (0) is flagged, so
    that a report does not read it as precision."""
    from ovon.evaluate.results import summarize

    def rec(seed: int, ep: str, success: bool, steps: int = 40) -> dict:
        return {"split": "val_seen", "scene": "s", "episode_id": ep, "seed": seed, "success": success,
                "spl": 0.5 * success, "soft_spl": 0.5, "distance_to_goal": 1.0, "steps": steps,
                "collisions": 0, "failure": None if success else "timeout"}  # fmt: skip

    same = [rec(seed, ep, ep == "1") for seed in (0, 1) for ep in ("1", "2")]
    assert summarize(same)["val_seen"]["seeds_identical"] is True
    assert summarize(same[:2])["val_seen"]["seeds_identical"] is False  # one seed: nothing to compare
    other = same[:3] + [rec(1, "2", False, steps=41)]  # same outcome, another path
    assert summarize(other)["val_seen"]["seeds_identical"] is False
