"""The evaluation protocol: the same episodes give the same results wherever the data lives.

Seeds and records name a scene by the dataset's own id (as written in the episode file), never by the
resolved path of its file, so two labs evaluating one agent on one released dataset get the same bytes.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from ovon.cli.main import main as ovon
from ovon.evaluate.results import read_records


def _evaluate(data: Path, scenes: Path, out: Path, *extra: str) -> bytes:
    args = ["evaluate", "--agent", "random", "--data", str(data), "--scenes", str(scenes)]
    args += ["--splits", "val_seen", "--episodes", "4", "--seeds", "0", "--workers", "1", "--no-progress"]
    assert ovon([*args, *extra, "--out", str(out)]) in (0, None)
    return (out / "episodes.jsonl").read_bytes()


@pytest.mark.parametrize("extra", [(), ("--noise", "actuation,odometry")], ids=["stochastic", "noisy"])
def test_results_do_not_depend_on_where_the_data_lives(tiny_dataset, tiny_scenes, tmp_path, extra):
    # A second copy under a deeper, differently named folder: every resolved path differs.
    moved = tmp_path / "another" / "lab's disk"
    shutil.copytree(tiny_dataset, moved / "episodes")
    shutil.copytree(tiny_scenes, moved / "scene_datasets")
    here = _evaluate(tiny_dataset, tiny_scenes, tmp_path / "a", *extra)
    there = _evaluate(moved / "episodes", moved / "scene_datasets", tmp_path / "b", *extra)
    assert here == there
    recs = read_records(tmp_path / "a")
    assert recs and all(not Path(r["scene"]).is_absolute() for r in recs)
    assert len({tuple(r["actions"]) for r in recs}) > 1  # the random agent really drew different actions


def _config(**camera) -> dict:
    from dataclasses import asdict

    from ovon.config.sim import CameraConfig, SimConfig
    from ovon.config.task import TaskConfig

    return {"sim": asdict(SimConfig(camera=CameraConfig(**camera))), "task": asdict(TaskConfig())}


def test_the_authors_settings_are_named_and_anything_else_is_custom_with_its_differences():
    from ovon.evaluate.protocol import protocol_card

    episodes = {"set": "whole splits", "splits": {"val_seen": 3}, "seeds": [0], "ids_sha256": "ab"}
    agent = {"privileged": False, "oracle_perception": False, "description": "random"}
    paper = protocol_card(_config(), episodes, agent)
    assert paper["name"] == "hm3d-ovon" and paper["differs_from"] == {}
    assert paper["task"]["success_distance"] == 0.25 and paper["task"]["max_steps"] == 500
    cpu = protocol_card(_config(width=72, height=128), episodes, agent)
    assert cpu["name"] == "custom"
    assert cpu["differs_from"]["hm3d-ovon"] == [
        "camera.width 72 (hm3d-ovon: 360)",
        "camera.height 128 (hm3d-ovon: 640)",
    ]
    assert cpu["fingerprint"] != paper["fingerprint"]
    assert protocol_card(_config(), episodes, agent)["fingerprint"] == paper["fingerprint"]
    oracle = protocol_card(_config(), episodes, {**agent, "oracle_perception": True})
    assert oracle["name"] == "hm3d-ovon" and oracle["fingerprint"] != paper["fingerprint"]
