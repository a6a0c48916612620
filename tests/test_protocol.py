"""The evaluation protocol: the same episodes give the same results wherever the data lives.

Seeds and records name a scene by the dataset's own id (as written in the episode file), never by the
resolved path of its file, so two labs evaluating one agent on one released dataset get the same bytes.
"""

from __future__ import annotations

import json
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
    # the fingerprint is the protocol (rules and episodes), not the agent: the card states the oracle beside it
    assert oracle["name"] == "hm3d-ovon" and oracle["fingerprint"] == paper["fingerprint"]
    assert oracle["agent"]["oracle_perception"] and not paper["agent"]["oracle_perception"]


def test_cards_subsets_and_reports_from_the_command_line(tiny_dataset, tiny_scenes, tmp_path, capsys):
    import json

    sub = tmp_path / "two.json"
    assert ovon(["dataset", "subset", str(tiny_dataset), "--size", "2", "--name", "two", "--out", str(sub)]) == 0
    common = ["--data", str(tiny_dataset), "--scenes", str(tiny_scenes), "--splits", "val_seen", "--seeds", "0"]
    common += ["--workers", "1", "--no-progress", "--agent", "shortest-path"]
    assert ovon(["evaluate", *common, "--subset", str(sub), "--out", str(tmp_path / "cpu")]) == 0
    card = json.loads((tmp_path / "cpu" / "summary.json").read_text())["protocol"]
    assert card["name"] == "custom" and card["episodes"]["set"] == "subset two"
    assert card["episodes"]["splits"] == {"val_seen": 2} and card["agent"]["privileged"]
    assert "Protocol: custom" in (tmp_path / "cpu" / "table.md").read_text()
    paper = ["--subset", str(sub), "--protocol", "hm3d-ovon", "--set", "task.max_steps=60"]
    assert ovon(["evaluate", *common, *paper, "--out", str(tmp_path / "paper")]) == 0
    card2 = json.loads((tmp_path / "paper" / "summary.json").read_text())["protocol"]
    assert card2["differs_from"]["hm3d-ovon"] == ["task.max_steps 60 (hm3d-ovon: 500)"]
    assert card2["episodes"]["ids_sha256"] == card["episodes"]["ids_sha256"]
    assert card2["fingerprint"] != card["fingerprint"]
    assert ovon(["report", str(tmp_path / "cpu"), str(tmp_path / "paper"), "--out", str(tmp_path / "rep")]) == 0
    report = (tmp_path / "rep" / "report.md").read_text()
    assert "ran under different evaluation protocols" in report and f"fingerprint {card['fingerprint']}" in report
    assert f"fingerprint {card2['fingerprint']}" in report
    one = tmp_path / "one.json"
    assert ovon(["dataset", "subset", str(tiny_dataset), "--size", "1", "--name", "one", "--split", "val_seen",
                 "--out", str(one)]) == 0  # fmt: skip
    capsys.readouterr()
    for bad, says in (
        (["--subset", "nope"], "--subset 'nope': neither a subset file nor a named subset"),
        (["--protocol", "habitat"], "--protocol 'habitat' is not a protocol ovon knows (known: hm3d-ovon)"),
        (["--subset", str(one), "--splits", "val_unseen"], "subset 'one' holds splits ['val_seen'], not 'val_unseen'"),
    ):
        assert ovon(["evaluate", *common, *bad, "--out", str(tmp_path / "bad")]) == 2
        err = capsys.readouterr().err.strip()
        assert says in err and "\n" not in err
    assert ovon(["dataset", "verify", str(tiny_dataset), "--scenes", str(tiny_scenes)]) == 0
    assert "usable episodes" in capsys.readouterr().out
    mini = ["dataset", "subset", str(tiny_dataset), "--size", "5", "--name", "mini", "--out", str(tmp_path / "m.json")]
    assert ovon(mini) == 2 and "--name 'mini' is the named subset of 360" in capsys.readouterr().err


def test_a_run_folder_of_path_keyed_records_is_refused_not_mixed(tiny_dataset, tiny_scenes, tmp_path, capsys):
    """Records of an older ovon named scenes by their resolved path (and were seeded by it): continuing such a
    folder would run every episode again beside the stale records."""
    run = tmp_path / "old"
    _evaluate(tiny_dataset, tiny_scenes, run)
    lines = (run / "episodes.jsonl").read_text().splitlines()
    old = [line.replace('"scene": "', f'"scene": "{tiny_scenes}/', 1) for line in lines]
    (run / "episodes.jsonl").write_text("\n".join(old) + "\n")
    capsys.readouterr()
    args = ["evaluate", "--agent", "random", "--data", str(tiny_dataset), "--scenes", str(tiny_scenes)]
    args += ["--splits", "val_seen", "--episodes", "5", "--seeds", "0", "--workers", "1", "--no-progress"]
    assert ovon([*args, "--out", str(run)]) == 2
    err = capsys.readouterr().err
    assert "its records name scenes by file path" in err and "fix: evaluate into a new --out folder" in err


def test_hm3d_episodes_default_to_the_authors_protocol(tmp_path, capsys):
    from tests.test_evaluate import write_release_fixture

    data, scenes = write_release_fixture(tmp_path)
    args = ["evaluate", "--agent", "shortest-path", "--data", str(data), "--scenes", str(scenes)]
    args += ["--splits", "val_seen", "--workers", "1", "--no-progress"]
    assert ovon([*args, "--out", str(tmp_path / "auto")]) == 0
    assert "protocol hm3d-ovon: the episodes name HM3D scenes" in capsys.readouterr().out
    card = json.loads((tmp_path / "auto" / "summary.json").read_text())["protocol"]
    assert card["name"] == "hm3d-ovon" and card["camera"]["width"] == 360 and card["task"]["max_steps"] == 500
    assert ovon([*args, "--preset", "cpu", "--out", str(tmp_path / "cpu")]) == 0
    card = json.loads((tmp_path / "cpu" / "summary.json").read_text())["protocol"]
    assert card["name"] == "custom" and "camera.width 72 (hm3d-ovon: 360)" in card["differs_from"]["hm3d-ovon"]
    assert ovon([*args, "--protocol", "none", "--out", str(tmp_path / "none")]) == 0
    assert json.loads((tmp_path / "none" / "summary.json").read_text())["protocol"]["camera"]["width"] == 72
