"""Files given as policies (`--checkpoint`, `--init`, `navigator.checkpoint`) and the goal-text cache: a
file that is not what it should be is one line naming it, before any run folder is made."""

from __future__ import annotations

import os
import random
import subprocess
import sys
import warnings
from pathlib import Path

import pytest
import torch

from ovon.models.config import EncoderConfig, policy_preset
from ovon.models.policy import ActorCritic, build_policy, read_policy_file

torch.set_num_threads(1)
ROOT = Path(__file__).resolve().parents[1]


def _policy_file(path: Path, task: str | None = None) -> Path:
    policy = build_policy(policy_preset("tiny"), 8, 4, EncoderConfig())
    policy.save(path, extra={"task": {"kind": task}} if task else {})
    return path


def _bad_files(tmp_path: Path) -> dict[str, Path]:
    good = _policy_file(tmp_path / "good.pt")
    files = {
        "random": tmp_path / "rand.pt",
        "empty": tmp_path / "empty.pt",
        "truncated": tmp_path / "trunc.pt",
        "list": tmp_path / "list.pt",
        "resume state": tmp_path / "run" / "checkpoint.pt",
    }
    files["random"].write_bytes(random.Random(0).randbytes(3000))
    files["pickle-like"] = tmp_path / "pickle_like.pt"  # starts with a pickle PROTO opcode: torch warns first
    files["pickle-like"].write_bytes(b"\x80\x94" + random.Random(1).randbytes(3000))
    files["empty"].write_bytes(b"")
    files["truncated"].write_bytes(good.read_bytes()[:1500])
    torch.save([1, 2], files["list"])
    files["resume state"].parent.mkdir()
    torch.save({"algo": "ppo", "optimizer": {}, "ranks": [{"rng": Path(".")}]}, files["resume state"])
    return files


def test_a_file_that_is_not_a_policy_is_one_line_naming_it(tmp_path):
    for what, path in _bad_files(tmp_path).items():
        with pytest.raises(ValueError) as e:
            read_policy_file(path, "--checkpoint")
        msg = str(e.value)
        assert "\n" not in msg and str(path) in msg and "fix:" in msg, (what, msg)
        assert "weights_only" not in msg and "\x1b" not in msg, (what, msg)
    assert "resume state, not a policy" in str(
        pytest.raises(ValueError, read_policy_file, tmp_path / "run" / "checkpoint.pt").value
    )
    assert isinstance(ActorCritic.load(tmp_path / "good.pt"), ActorCritic)


def _ovon(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "ovon.cli.main", *args],
        cwd=cwd,
        capture_output=True,
        text=True,
        env={**os.environ, "PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": "1"},
        timeout=300,
    )


def test_evaluate_refuses_a_bad_or_other_task_checkpoint_before_its_run_folder(tmp_path, tiny_dataset, tiny_scenes):
    bad = _bad_files(tmp_path)
    pointnav, objectnav = _policy_file(tmp_path / "pn.pt", "pointnav"), _policy_file(tmp_path / "on.pt", "objectnav")
    cases = [
        (["--task", "pointnav", "--procedural", "80000", "--checkpoint", str(bad["pickle-like"])], "torch can read"),
        (["--task", "pointnav", "--procedural", "80000", "--checkpoint", str(bad["list"])], "not an ovon policy"),
        (
            ["--task", "pointnav", "--procedural", "80000", "--checkpoint", str(objectnav)],
            "is an ObjectNav policy, this is a PointNav evaluation; fix: leave --task pointnav out",
        ),
        (
            [
                "--data",
                str(tiny_dataset),
                "--scenes",
                str(tiny_scenes),
                "--splits",
                "val_seen",
                "--checkpoint",
                str(pointnav),
            ],
            "is a PointNav policy, this is an ObjectNav evaluation; fix:",
        ),
    ]
    for i, (args, expect) in enumerate(cases):
        out = tmp_path / f"eval{i}"
        res = _ovon("evaluate", "--agent", "policy", "--episodes", "1", *args, "--out", str(out), cwd=tmp_path)
        assert res.returncode == 2 and expect in res.stderr, (args, res.stderr)
        assert len(res.stderr.strip().splitlines()) == 1 and "Traceback" not in res.stderr, res.stderr
        assert not out.exists(), "refused before the run folder is made"


def test_train_refuses_a_bad_init_before_its_run_folder(tmp_path):
    bad = _bad_files(tmp_path)
    pointnav = _policy_file(tmp_path / "pn.pt", "pointnav")
    for init, expect in (
        (bad["random"], "torch can read"),
        (tmp_path / "missing.pt", "does not exist"),
        (pointnav, "is a pointnav policy, this run trains objectnav"),
    ):
        out = tmp_path / "train"
        res = _ovon(
            "train",
            "--algo",
            "ppo",
            "--preset",
            "tiny",
            "--procedural",
            "0",
            "--episodes",
            "2",
            "--init",
            str(init),
            "--out",
            str(out),
            cwd=tmp_path,
        )
        assert res.returncode == 2 and expect in res.stderr, res.stderr
        assert "Traceback" not in res.stderr and "internal error" not in res.stderr, res.stderr
        assert not out.exists(), "refused before the run folder is made"


def test_a_torn_text_cache_is_rebuilt_with_a_warning(tmp_path):
    from ovon.train.text import text_table

    cache = tmp_path / "text.pt"
    first = text_table(EncoderConfig(), ["chair"], cache)
    cache.write_bytes(cache.read_bytes()[:100])
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        again = text_table(EncoderConfig(), ["chair"], cache)
    assert any("is unreadable" in str(w.message) for w in caught)
    assert torch.equal(again["chair"], first["chair"])
    assert torch.equal(text_table(EncoderConfig(), ["chair"], cache)["chair"], first["chair"])  # rewritten whole
    cache.write_bytes(b"garbage")
    with pytest.raises(ValueError, match="is unreadable; fix: delete it"):
        text_table(EncoderConfig(), ["chair"], cache, write=False)
