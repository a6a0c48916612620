"""Run folders that know what they are: identity, resume comparison, lock, records set aside (item 2)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ovon.evaluate.config import EvalConfig
from ovon.evaluate.harness import evaluate
from ovon.evaluate.results import REJECTED_FILE, read_records, record_key
from ovon.runfolder import IDENTITY_FILE, LOCK_FILE, RunFolder, RunFolderError

ROOT = Path(__file__).resolve().parents[1]


def test_out_naming_a_file_is_refused(tmp_path):
    f = tmp_path / "x"
    f.write_text("keep me")
    with pytest.raises(RunFolderError, match=r"--out .*x is an existing file.*fix:"):
        RunFolder.open(f, "evaluate", {})
    assert f.read_text() == "keep me"


def test_identity_is_written_then_compared_with_every_difference_named(tmp_path):
    cfg = {"agent": "random", "task": {"max_steps": 500, "success_distance": 0.25}, "workers": 2}
    with RunFolder.open(tmp_path / "r", "evaluate", cfg, {"data": {"sha": "a"}}, may_change=("workers",)) as run:
        assert not run.resumed
    stored = json.loads((tmp_path / "r" / IDENTITY_FILE).read_text())
    assert stored["kind"] == "evaluate" and "workers" not in stored["config"]
    assert not (tmp_path / "r" / LOCK_FILE).exists()  # released
    same = {**cfg, "workers": 7}
    with RunFolder.open(tmp_path / "r", "evaluate", same, {"data": {"sha": "a"}}, may_change=("workers",)) as run:
        assert run.resumed
    other = {"agent": "frontier", "task": {"max_steps": 300, "success_distance": 0.25}}
    with pytest.raises(RunFolderError) as ei:
        RunFolder.open(tmp_path / "r", "evaluate", other, {"data": {"sha": "b"}})
    msg = str(ei.value)
    assert "\n" not in msg
    for part in ('agent "random" -> "frontier"', "task.max_steps 500 -> 300", 'inputs.data.sha "a" -> "b"', "fix:"):
        assert part in msg
    with pytest.raises(RunFolderError, match="holds a run of kind 'evaluate', not 'train'"):
        RunFolder.open(tmp_path / "r", "train", cfg)
    with pytest.raises(RunFolderError, match="pass --resume"):
        RunFolder.open(tmp_path / "r", "evaluate", cfg, resume=False)


def test_keys_added_later_join_the_identity(tmp_path):
    RunFolder.open(tmp_path, "evaluate", {}, {"splits": {"val_seen": "h1"}}).close()
    RunFolder.open(tmp_path, "evaluate", {}, {"splits": {"val_seen": "h1", "val_unseen": "h2"}}).close()
    with pytest.raises(RunFolderError, match='inputs.splits.val_unseen "h2" -> "h3"'):
        RunFolder.open(tmp_path, "evaluate", {}, {"splits": {"val_unseen": "h3"}})


def test_legacy_folder_without_identity_is_refused(tmp_path):
    (tmp_path / "episodes.jsonl").write_text("{}\n")
    with pytest.raises(RunFolderError, match="holds episodes.jsonl but no run_identity.json"):
        RunFolder.open(tmp_path, "evaluate", {}, markers=("episodes.jsonl",))


def test_a_failed_new_run_leaves_no_identity(tmp_path):
    with pytest.raises(KeyError), RunFolder.open(tmp_path / "new", "evaluate", {"a": 1}):
        raise KeyError("boom")
    assert not (tmp_path / "new").exists()


def test_second_writer_is_refused_and_the_lock_of_a_dead_process_is_recovered(tmp_path):
    run = RunFolder.open(tmp_path, "evaluate", {})
    with pytest.raises(RunFolderError, match=rf"in use by another ovon process \(pid {os.getpid()}"):
        RunFolder.open(tmp_path, "evaluate", {})
    run.close()
    RunFolder.open(tmp_path, "evaluate", {}).close()
    # a process that dies holding the lock (kill -9): its lock file stays, the next open takes it over
    code = (
        "import sys, time; sys.path.insert(0, sys.argv[2]); from ovon.runfolder import RunFolder; "
        "RunFolder.open(sys.argv[1], 'evaluate', {}); print('locked', flush=True); time.sleep(60)"
    )
    p = subprocess.Popen([sys.executable, "-c", code, str(tmp_path), str(ROOT)], stdout=subprocess.PIPE, text=True)
    assert p.stdout.readline().strip() == "locked"
    with pytest.raises(RunFolderError, match=f"pid {p.pid}"):
        RunFolder.open(tmp_path, "evaluate", {})
    p.send_signal(signal.SIGKILL)
    p.wait()
    assert (tmp_path / LOCK_FILE).exists()
    RunFolder.open(tmp_path, "evaluate", {}).close()


def test_temp_files_of_a_killed_write_are_swept(tmp_path):
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / ".x.json.gz.abc123.tmp").write_bytes(b"half")
    RunFolder.open(tmp_path, "dataset", {}).close()
    assert not list(tmp_path.rglob("*.tmp"))


# -- evaluate ------------------------------------------------------------------------------------------
def _cfg(tiny_dataset, tiny_scenes, **kw):
    return EvalConfig(
        agent="random", data=str(tiny_dataset), scenes=str(tiny_scenes), splits=("val_seen",), episodes=4, **kw
    )


def test_evaluate_refuses_another_agent_or_task_and_accepts_other_spellings(
    tiny_dataset, tiny_scenes, tmp_path, monkeypatch
):
    out = tmp_path / "run"
    evaluate(_cfg(tiny_dataset, tiny_scenes), out, progress=False)
    n = len(read_records(out))
    with pytest.raises(RunFolderError, match='agent "random" -> "shortest-path"'):
        evaluate(replace(_cfg(tiny_dataset, tiny_scenes), agent="shortest-path"), out, progress=False)
    cfg = _cfg(tiny_dataset, tiny_scenes)
    with pytest.raises(RunFolderError, match="task.max_steps 500 -> 300"):
        evaluate(replace(cfg, task=replace(cfg.task, max_steps=300)), out, progress=False)
    # the same scenes and data spelled differently, and more workers: the same run, nothing duplicated
    monkeypatch.chdir(tiny_scenes.parent)
    spelled = replace(
        _cfg(tiny_dataset, tiny_scenes), scenes=f"./{tiny_scenes.name}/", data=str(tiny_dataset) + "/", workers=2
    )
    summary = evaluate(spelled, out, progress=False)
    assert len(read_records(out)) == n == summary["splits"]["val_seen"]["episodes"]


def test_a_torn_or_unparsable_line_never_costs_complete_records(tiny_dataset, tiny_scenes, tmp_path):
    out = tmp_path / "run"
    full = evaluate(_cfg(tiny_dataset, tiny_scenes, seeds=(0, 1)), out, progress=False)
    lines = (out / "episodes.jsonl").read_bytes().splitlines(keepends=True)
    assert len(lines) == 8
    damaged = lines[:2] + [b'{"split": "val_seen", "seed": 0, "sce\n', b"garbage\n"] + lines[2:] + [lines[5]]
    (out / "episodes.jsonl").write_bytes(b"".join(damaged) + b'{"torn')
    with pytest.warns(UserWarning, match=r"4 line\(s\) that are not complete records moved to"):
        again = evaluate(_cfg(tiny_dataset, tiny_scenes, seeds=(0, 1)), out, progress=False)
    assert again == full
    assert (out / "episodes.jsonl").read_bytes() == b"".join(lines)
    rejected = [json.loads(x) for x in (out / REJECTED_FILE).read_text().splitlines()]
    assert [r["reason"].split(" ")[0] for r in rejected] == ["unparsable", "unparsable", "duplicate", "torn"]
    assert len({record_key(r) for r in read_records(out)}) == 8


GATE = "OVON_TEST_GATE"


class GatedAgent:
    """Ten steps an episode; its first step waits for the file named by $OVON_TEST_GATE (at most 300 s),
    after writing that name + ".waiting": the test knows this run is under way (its folder locked), and the
    run lasts until the test lets it go, however slowly a loaded machine starts a second process."""

    privileged = False
    released = False

    def reset(self, episode_info: dict) -> None:
        self.t = 0

    def act(self, observation: dict) -> int:
        self.t += 1
        gate = os.environ.get(GATE)
        if gate and not GatedAgent.released:
            Path(gate + ".waiting").touch()
            deadline = time.monotonic() + 300
            while not Path(gate).exists() and time.monotonic() < deadline:
                time.sleep(0.05)
            GatedAgent.released = True
        return 0 if self.t >= 10 else 2


def _wait_for(condition, timeout_s: float) -> None:
    deadline = time.monotonic() + timeout_s
    while not condition() and time.monotonic() < deadline:
        time.sleep(0.05)


def test_two_evaluations_on_one_folder_do_not_both_write(tiny_dataset, tiny_scenes, tmp_path):
    out = tmp_path / "run"
    cmd = [
        sys.executable,
        "-m",
        "ovon.cli.main",
        "evaluate",
        "--agent",
        "tests.test_reliability_runfolder:GatedAgent",
        "--data",
        str(tiny_dataset),
        "--scenes",
        str(tiny_scenes),
        "--splits",
        "val_seen",
        "--episodes",
        "6",
        "--workers",
        "1",
        "--no-progress",
        "--out",
        str(out),
    ]
    gate = tmp_path / "gate"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    err = tmp_path / "first.err"  # a file, not a pipe: what the first run writes never blocks it
    with open(err, "w") as first_err:
        first = subprocess.Popen(
            cmd, env={**env, GATE: str(gate)}, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=first_err
        )
    try:
        _wait_for(lambda: Path(f"{gate}.waiting").exists() or first.poll() is not None, 300)
        assert first.poll() is None and (out / LOCK_FILE).exists(), err.read_text()
        second = subprocess.run(cmd, env=env, cwd=ROOT, capture_output=True, text=True, timeout=300)
    finally:
        gate.touch()  # the first run goes on to its end
        first.wait(timeout=300)
    assert first.returncode == 0, err.read_text()
    assert second.returncode == 2 and "in use by another ovon process" in second.stderr
    assert len(second.stderr.strip().splitlines()) == 1
    keys = [record_key(r) for r in read_records(out)]
    assert len(keys) == len(set(keys))


# -- canonical order: the summary does not depend on the order in which workers finished ----------------
def _record(i: int, split: str, seed: int) -> dict:
    return {
        "split": split,
        "seed": seed,
        "scene": f"/s/{i % 3}.glb",
        "episode_id": str(i),
        "success": i % 3 == 0,
        "spl": (i * 0.1234567) % 1,
        "soft_spl": (i * 0.7654321) % 1,
        "distance_to_goal": i * 0.1,
        "steps": i,
        "collisions": i % 5,
        "failure": None if i % 3 == 0 else "stop_too_far",
    }


RECORDS = [_record(i, sp, seed) for i in range(30) for sp in ("val_seen", "val_unseen") for seed in (0, 1, 2)]


@settings(max_examples=50, deadline=None)
@given(st.permutations(RECORDS))
def test_summary_and_file_bytes_do_not_depend_on_record_order(tmp_path_factory, order):
    from ovon.evaluate.results import summarize, write_canonical

    d = tmp_path_factory.mktemp("c")
    write_canonical(d, order)
    assert (d / "episodes.jsonl").read_bytes() == _CANON.setdefault("bytes", (d / "episodes.jsonl").read_bytes())
    s = json.dumps(summarize(order), sort_keys=True)
    assert s == _CANON.setdefault("summary", s)


_CANON: dict = {}


def test_file_lock_alone(tmp_path):
    from ovon.runfolder import FileLock

    with FileLock(tmp_path / "locks" / "cell.lock", "--only"):
        with pytest.raises(RunFolderError, match="in use by another ovon process"):
            FileLock(tmp_path / "locks" / "cell.lock")
    assert not (tmp_path / "locks" / "cell.lock").exists()
    FileLock(tmp_path / "locks" / "cell.lock").release()
