"""Workers die with their parent; kill -9 then re-run gives byte-identical outputs; 1 or N workers (or Ray)
give byte-identical files (issue 13, items 3 and 7)."""

from __future__ import annotations

import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from ovon.evaluate.config import EvalConfig
from ovon.evaluate.harness import evaluate

ROOT = Path(__file__).resolve().parents[1]
OUTPUTS = ("episodes.jsonl", "summary.json", "table.md", "run_identity.json")


def _children(pid: int) -> list[int]:
    """The processes whose parent is `pid`: from /proc (slim Linux images have no pgrep), else pgrep (macOS)."""
    if not Path("/proc/self/stat").exists():
        return sorted(
            int(x) for x in subprocess.run(["pgrep", "-P", str(pid)], capture_output=True, text=True).stdout.split()
        )
    kids = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()  # after the command name, which may hold spaces
        except (OSError, IndexError):
            continue  # the process ended meanwhile
        if int(fields[1]) == pid:
            kids.append(int(stat.parent.name))
    return sorted(kids)


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    try:  # a zombie (dead, not yet reaped by its new parent) counts as gone
        return Path(f"/proc/{pid}/stat").read_text().split(")")[-1].split()[0] != "Z"
    except OSError:
        return True


def _wait_gone(pids: list[int], timeout: float = 10.0) -> list[int]:
    deadline = time.time() + timeout
    while time.time() < deadline and any(_alive(p) for p in pids):
        time.sleep(0.1)
    return [p for p in pids if _alive(p)]


PARENT = """
import sys, time
sys.path.insert(0, {root!r})
from ovon.parallel import run_jobs
from tests.test_reliability_workers import sleepy_job
for _ in run_jobs(sleepy_job, [{out!r}] * 4, workers=2):
    pass
"""


def sleepy_job(out: str) -> int:
    with open(Path(out) / f"{os.getpid()}.pid", "w") as f:
        f.write(str(os.getpid()))
    time.sleep(120)
    return os.getpid()


def test_pool_workers_die_when_the_parent_is_killed(tmp_path):
    parent = subprocess.Popen([sys.executable, "-c", PARENT.format(root=str(ROOT), out=str(tmp_path))], cwd=ROOT)
    deadline = time.time() + 60
    while len(list(tmp_path.glob("*.pid"))) < 2 and time.time() < deadline:
        time.sleep(0.1)
    pids = [int(p.stem) for p in tmp_path.glob("*.pid")]
    assert len(pids) == 2 and all(_alive(p) for p in pids)
    parent.send_signal(signal.SIGKILL)
    parent.wait()
    assert _wait_gone(pids) == [], "orphan workers after kill -9 of their parent"


RAW = """
import multiprocessing as mp, sys, time
sys.path.insert(0, {root!r})
from tests.test_reliability_workers import raw_worker
if __name__ == "__main__":
    ps = [mp.get_context(ctx).Process(target=raw_worker, args=({out!r},)) for ctx in ("spawn", "fork")]
    for p in ps:
        p.start()
    time.sleep(120)
"""


def raw_worker(out: str) -> None:
    """Any worker process of the project (e.g. the training vector env's) calls init_worker()."""
    from ovon.parallel import init_worker

    init_worker()
    sleepy_job(out)


def test_any_process_that_calls_init_worker_dies_with_its_parent(tmp_path):
    script = tmp_path / "raw.py"
    script.write_text(RAW.format(root=str(ROOT), out=str(tmp_path)))
    parent = subprocess.Popen([sys.executable, str(script)], cwd=ROOT)
    deadline = time.time() + 60
    while len(list(tmp_path.glob("*.pid"))) < 2 and time.time() < deadline:
        time.sleep(0.1)
    pids = [int(p.stem) for p in tmp_path.glob("*.pid")]
    assert len(pids) == 2
    parent.send_signal(signal.SIGKILL)
    parent.wait()
    assert _wait_gone(pids) == []


def test_init_worker_does_not_arm_the_main_process():
    from ovon import parallel

    parallel.init_worker()
    assert parallel._ARMED is False  # a command must not die with the shell that launched it


def _cfg(tiny_dataset, tiny_scenes, **kw) -> EvalConfig:
    return EvalConfig(agent="frontier", data=str(tiny_dataset), scenes=str(tiny_scenes), **kw)


def test_one_or_two_workers_give_byte_identical_files(tiny_dataset, tiny_scenes, tmp_path):
    splits = ("val_seen", "val_unseen")
    evaluate(_cfg(tiny_dataset, tiny_scenes, workers=1, chunk=3, splits=splits), tmp_path / "w1", progress=False)
    evaluate(_cfg(tiny_dataset, tiny_scenes, workers=2, chunk=5, splits=splits), tmp_path / "w2", progress=False)
    for name in OUTPUTS:
        assert (tmp_path / "w1" / name).read_bytes() == (tmp_path / "w2" / name).read_bytes(), name


@pytest.mark.slow
def test_ray_gives_the_same_bytes(tiny_dataset, tiny_scenes, tmp_path):
    pytest.importorskip("ray")
    evaluate(_cfg(tiny_dataset, tiny_scenes, splits=("val_seen",)), tmp_path / "p", progress=False)
    evaluate(
        _cfg(tiny_dataset, tiny_scenes, splits=("val_seen",), workers=2, executor="ray"), tmp_path / "r", progress=False
    )
    for name in OUTPUTS:
        assert (tmp_path / "p" / name).read_bytes() == (tmp_path / "r" / name).read_bytes(), name


# -- kill -9 at random moments, then re-run -------------------------------------------------------------
def kill_and_resume(cmd: list[str], out: Path, progress, stops: list[int], env: dict) -> list[int]:
    """Start `cmd` and SIGKILL its main process once `progress(out)` reaches each of `stops` (work on disk),
    then let it finish; returns the pids of the workers alive at the kills (all must be gone afterwards)."""
    seen: list[int] = []
    for stop in stops:
        p = subprocess.Popen(cmd, env=env, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        deadline = time.time() + 600
        while p.poll() is None and progress(out) < stop and time.time() < deadline:
            time.sleep(0.02)
        seen += _children(p.pid)
        p.send_signal(signal.SIGKILL)  # the main process only: its workers must follow it
        p.wait()
    res = subprocess.run(cmd, env=env, cwd=ROOT, capture_output=True, text=True, timeout=1200)
    assert res.returncode == 0, res.stderr
    return seen


def records_on_disk(out: Path) -> int:
    f = out / "episodes.jsonl"
    return f.read_bytes().count(b"\n") if f.exists() else 0


def files_on_disk(out: Path) -> int:
    return len(list(out.glob(".cache/goals/*.json.gz"))) + len(list(out.glob("*/content/*.json.gz")))


def _env() -> dict:
    return {**os.environ, "PYTHONPATH": str(ROOT)}


def test_kill_9_during_evaluate_then_rerun_is_byte_identical(tiny_dataset, tiny_scenes, tmp_path):
    ref = tmp_path / "ref"
    evaluate(_cfg(tiny_dataset, tiny_scenes, seeds=(0, 1), splits=("val_seen",)), ref, progress=False)
    out = tmp_path / "killed"
    cmd = [
        sys.executable,
        "-m",
        "ovon.cli.main",
        "evaluate",
        "--agent",
        "frontier",
        "--data",
        str(tiny_dataset),
        "--scenes",
        str(tiny_scenes),
        "--splits",
        "val_seen",
        "--seeds",
        "0,1",
        "--workers",
        "2",
        "--no-progress",
        "--out",
        str(out),
    ]
    rng = random.Random(13)
    n = records_on_disk(ref)
    workers = kill_and_resume(cmd, out, records_on_disk, sorted(rng.sample(range(1, n), 2)), _env())
    assert _wait_gone(workers) == []
    for name in OUTPUTS:
        assert (out / name).read_bytes() == (ref / name).read_bytes(), name
    assert not (out / ".lock").exists() and not list(out.glob(".*.tmp"))


@pytest.mark.slow
def test_kill_9_during_dataset_generate_then_rerun_is_byte_identical(tiny_scenes, tmp_path):
    args = [
        "dataset",
        "generate",
        "--scenes",
        str(tiny_scenes),
        "--preset",
        "fast",
        "--split",
        "val_seen",
        "--split",
        "val_unseen",
        "--set",
        "episodes_per_val_split=16",
        "--set",
        "viewpoints.render_size=48",
        "--set",
        "viewpoints.max_viewpoints=6",
        "--workers",
        "2",
        "--no-progress",
    ]
    ref, out = tmp_path / "ref", tmp_path / "killed"
    subprocess.run(
        [sys.executable, "-m", "ovon.cli.main", *args, "--out", str(ref)],
        env=_env(),
        cwd=ROOT,
        check=True,
        capture_output=True,
    )
    rng = random.Random(7)
    cmd = [sys.executable, "-m", "ovon.cli.main", *args, "--out", str(out)]
    n = files_on_disk(ref)
    workers = kill_and_resume(cmd, out, files_on_disk, sorted(rng.sample(range(1, n), min(3, n - 1))), _env())
    assert _wait_gone(workers) == []

    def files(root: Path) -> dict[str, bytes]:  # the dataset (reports hold timings, .cache holds timings)
        return {
            str(p.relative_to(root)): p.read_bytes()
            for p in root.rglob("*")
            if p.is_file() and ".cache" not in p.parts and p.name != "generation_report.json"
        }

    assert files(out) == files(ref)


def checkpoints_on_disk(out: Path) -> int:
    return len(list(out.glob("snapshots/policy_*.pt")))


def test_kill_9_during_train_then_resume_gives_the_same_losses(tmp_path):
    """SIGKILL of `ovon train` (env workers included) between checkpoints, then `--resume`: the same
    per-update losses and the same final weights as an uninterrupted run, no orphan workers."""
    import torch

    from ovon.train.logging import read_metrics

    def cmd(out: Path) -> list[str]:
        return [
            sys.executable,
            "-m",
            "ovon.cli.main",
            "train",
            "--algo",
            "dagger",
            "--preset",
            "tiny",
            "--expert",
            "shortest-path",
            "--procedural",
            "0-1",
            "--episodes",
            "6",
            "--resume",
            "--set",
            "max_updates=6",
            "--set",
            "env_workers=2",
            "--set",
            "keep_checkpoints=10",
            "--set",
            f"text_cache={tmp_path / 'text.pt'}",
            "--out",
            str(out),
        ]

    env = {**_env(), "OMP_NUM_THREADS": "1"}
    ref, out = tmp_path / "ref", tmp_path / "killed"
    assert subprocess.run(cmd(ref), env=env, cwd=ROOT, capture_output=True, timeout=600).returncode == 0
    workers = kill_and_resume(cmd(out), out, checkpoints_on_disk, [2, 4], env)
    assert _wait_gone(workers) == []

    def losses(d: Path) -> list:
        return [(r["update"], r["loss"]) for r in read_metrics(d)]

    assert losses(out) == losses(ref)
    a = torch.load(out / "policy.pt", weights_only=True)["state_dict"]
    b = torch.load(ref / "policy.pt", weights_only=True)["state_dict"]
    assert a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)
    assert not (out / ".lock").exists()


@pytest.mark.parametrize("group", [False, True], ids=["process", "process-group"])
def test_sigterm_stops_train_after_its_update_with_a_checkpoint_and_the_same_command_resumes(tmp_path, group):
    """SIGTERM (kill, `timeout`, a cluster scheduler) stops `ovon train` as Ctrl-C does: the current update
    finishes and is checkpointed although no checkpoint is scheduled, then exit 130 with the one-line hint,
    env workers shut down, no shared memory left behind (Python's resource tracker would warn of leaked
    segments), the run lock released; the same command with `--resume` then finishes it, to the weights of
    an uninterrupted run. To the process alone, and to its whole process group (workers included) followed
    by more SIGTERMs to the process until it exits (`timeout`, then the experiment runner's own stop)."""
    import torch

    from ovon.train.checkpoint import load_checkpoint
    from ovon.train.logging import read_metrics

    def cmd(out: Path) -> list[str]:
        return [
            sys.executable,
            "-m",
            "ovon.cli.main",
            "train",
            "--algo",
            "dagger",
            "--preset",
            "tiny",
            "--expert",
            "shortest-path",
            "--procedural",
            "0-1",
            "--episodes",
            "6",
            "--resume",
            "--set",
            "max_updates=40",
            "--set",
            "checkpoint_every=1000",
            "--set",
            "env_workers=2",
            "--set",
            f"text_cache={tmp_path / 'text.pt'}",
            "--out",
            str(out),
        ]

    env = {**_env(), "OMP_NUM_THREADS": "1"}
    out, ref = tmp_path / "run", tmp_path / "ref"
    p = subprocess.Popen(
        cmd(out),
        env=env,
        cwd=ROOT,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=group,
    )
    deadline = time.time() + 600
    while p.poll() is None and len(read_metrics(out)) < 2 and time.time() < deadline:
        time.sleep(0.02)
    workers = _children(p.pid)
    assert p.poll() is None and workers, "the run should be mid-way, with its env workers"
    assert not (out / "checkpoint.pt").exists(), "no checkpoint is scheduled before the last update"
    if group:
        os.killpg(p.pid, signal.SIGTERM)
        while p.poll() is None:  # more SIGTERMs all through the update, the checkpoint and the exit: all ignored
            p.send_signal(signal.SIGTERM)
            time.sleep(0.02)
    p.send_signal(signal.SIGTERM)
    _, err = p.communicate(timeout=120)
    assert p.returncode == 130, err
    assert "stopping after this update, with a checkpoint" in err
    assert "interrupted (re-run the same command to resume)" in err
    assert "leaked" not in err and "Traceback" not in err, err
    assert _wait_gone(workers) == []
    assert not (out / ".lock").exists()
    stopped_at = load_checkpoint(out)["update"]
    assert 2 <= stopped_at < 40 and read_metrics(out)[-1]["update"] == stopped_at
    for folder in (out, ref):
        res = subprocess.run(cmd(folder), env=env, cwd=ROOT, capture_output=True, text=True, timeout=1200)
        assert res.returncode == 0, res.stderr
    a = torch.load(out / "policy.pt", weights_only=True)["state_dict"]
    b = torch.load(ref / "policy.pt", weights_only=True)["state_dict"]
    assert a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)
