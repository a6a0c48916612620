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
