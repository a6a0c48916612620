"""Run an experiment plan: prepare the data, train what is not finished, evaluate, write the report.

Each cell runs as its `ovon` command in a child process (training under `torchrun` at paper scale):
a crash, an out-of-memory kill or a GPU error in one cell is that cell's failure, not the runner's,
and the command the runner executes is the one `--dry-run` prints. Children die with the runner
(Linux parent-death signal), cells are locked while they run (two invocations never run one cell
twice) and everything finished is skipped, so a killed run resumes where it stopped.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

from rich.console import Console

from ovon.experiments.cells import Cell, Plan
from ovon.experiments.definitions import DefinitionError
from ovon.experiments.identity import config_unknown, resolved_config
from ovon.experiments.inputs import inputs
from ovon.experiments.outputs import count_lines, finished_outputs, last_update
from ovon.experiments.plan import display
from ovon.experiments.provenance import code_version
from ovon.experiments.records import cell_lock, lock_holder, log_path, read_record, record_path, write_record
from ovon.experiments.select import match_cells, select
from ovon.experiments.status import Status, plan_status
from ovon.experiments.tokens import full_commands

POLL_S = 2.0
STAMP = "%Y-%m-%d %H:%M:%S"  # attempt starts and log headers; parsed back to time a killed attempt


def say(console: Console, text: str) -> None:
    """Plain text: commands hold brackets and colons that rich would read as markup or emoji codes."""
    console.print(text, markup=False, highlight=False, emoji=False, soft_wrap=True)


@dataclass
class RunResult:
    statuses: dict[str, Status] = field(default_factory=dict)  # final status of every selected cell
    ran: list[str] = field(default_factory=list)  # cells whose command ran (to the end) in this run
    failed: list[str] = field(default_factory=list)
    report: Path | None = None

    @property
    def ok(self) -> bool:
        return not self.failed


# ----- child processes -------------------------------------------------------------------------------
def _parent_death_signal():
    """A preexec function that makes the child get SIGKILL when the runner dies (Linux), else None."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        import ctypes
        import signal

        prctl = ctypes.CDLL(None, use_errno=True).prctl  # resolved here: the child only calls it
    except (OSError, AttributeError):
        return None
    return lambda: prctl(1, int(signal.SIGKILL), 0, 0, 0)  # PR_SET_PDEATHSIG


def exec_argv(cell: Cell, argv: list[str]) -> list[str]:
    """What runs: this Python with `-m ovon.cli.main` (or `-m torch.distributed.run` = torchrun)."""
    if cell.launcher:
        return [sys.executable, "-m", "torch.distributed.run", *cell.launcher[1:], "-m", "ovon.cli.main", *argv]
    return [sys.executable, "-m", "ovon.cli.main", *argv]


def child_env() -> dict[str, str]:
    """The runner's environment; children import the same `ovon` as the runner."""
    import ovon

    env = dict(os.environ)
    pkg_parent = str(Path(ovon.__file__).resolve().parent.parent)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (pkg_parent, env.get("PYTHONPATH", "")) if p)
    env["PYTHONUNBUFFERED"] = "1"
    return env


# A stopped training child finishes its update and writes a checkpoint of it before it exits
STOP_GRACE_S = 120.0


def _stop(proc: subprocess.Popen) -> None:
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(timeout=STOP_GRACE_S)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def _progress_count(cell: Cell) -> int | None:
    if cell.kind == "train":
        return last_update(cell.folder)
    if cell.kind == "eval":
        return count_lines(cell.folder / "episodes.jsonl")
    return None


def run_command(cell: Cell, argv: list[str], log: Path, on_poll=None, on_start=None) -> int:
    """Run one command of a cell, output appended to `log`; returns its exit code. `on_start(pid)` is
    called once the child runs, `on_poll()` every `POLL_S` seconds while it does."""
    log.parent.mkdir(parents=True, exist_ok=True)
    with open(log, "ab") as f:
        f.write(f"\n===== {time.strftime(STAMP)} {display(cell, argv)}\n".encode())
        f.flush()
        proc = subprocess.Popen(
            exec_argv(cell, argv),
            stdout=f,
            stderr=subprocess.STDOUT,
            stdin=subprocess.DEVNULL,
            env=child_env(),
            preexec_fn=_parent_death_signal(),
        )
    if on_start is not None:
        on_start(proc.pid)
    try:
        while True:
            try:
                proc.wait(timeout=POLL_S)
                break
            except subprocess.TimeoutExpired:
                if on_poll is not None:
                    on_poll()
    except BaseException:
        _stop(proc)
        raise
    return int(proc.returncode)


def log_tail(log: Path, lines: int = 6) -> str:
    try:
        text = log.read_bytes()[-8000:].decode("utf-8", "replace")
    except OSError:
        return ""
    keep = [ln for ln in text.splitlines() if ln.strip() and not ln.startswith("=====")]
    return "\n".join(keep[-lines:])


# ----- one cell --------------------------------------------------------------------------------------
def commands_to_run(cell: Cell) -> list[list[str]]:
    """The cell's commands as run now: a training folder that holds anything is resumed (`--resume`
    continues from its checkpoint, or starts afresh when none was written yet)."""
    if cell.kind == "train" and cell.folder.is_dir() and any(cell.folder.iterdir()):
        return [[*argv, "--resume"] for argv in cell.commands]
    return cell.commands


def execute(plan: Plan, cell: Cell, progress=None) -> int:
    """Run the cell's commands under its record; returns the exit code (0 = finished)."""
    rec = read_record(plan, cell) or {}
    log = log_path(plan, cell)
    if rec.get("state") == "running":  # the attempt before died with its runner: keep what it ran with
        wall = killed_wall_s(rec.get("started"), log)
        _add_attempt(
            rec,
            {"started": rec.get("started"), "wall_s": wall, "rc": "killed", "code": rec.get("code")}
            | ({"wall_estimated": True} if wall is not None else {}),
        )
    rec.update(
        {
            "kind": cell.kind,
            "name": cell.name,
            "state": "running",
            "attempts": int(rec.get("attempts", 0)) + 1,
            "started": time.strftime(STAMP),
            "code": code_version(),
            "config": resolved_config(plan, cell),
            "inputs": inputs(plan, cell),
        }
    )  # an unfinished attempt's inputs too: see `cell_status`
    write_record(plan, cell, rec)
    t0 = time.perf_counter()
    rc = 0
    task = None
    if progress is not None:
        task = progress.add_task(cell.id, total=cell.total)

    def poll() -> None:
        n = _progress_count(cell)
        if task is not None and n is not None:
            progress.update(task, completed=n)

    def started(pid: int) -> None:
        rec["pid"] = pid
        write_record(plan, cell, rec)

    try:
        for argv in commands_to_run(cell):
            rc = run_command(cell, argv, log, poll, started)
            if rc != 0:
                break
    except BaseException:
        rec.update({"state": "failed", "rc": "interrupted"})
        _finish_record(plan, cell, rec, t0)
        raise
    finally:
        if task is not None:
            progress.remove_task(task)
    if rc == 0:
        if finished_outputs(plan, cell):
            rec.update({"state": "done", "rc": 0, "commands": full_commands(plan, cell), "inputs": inputs(plan, cell)})
        else:
            rc = -1
            rec.update({"state": "failed", "rc": "exited 0 without its outputs"})
    else:
        rec.update({"state": "failed", "rc": rc})
    _finish_record(plan, cell, rec, t0)
    return rc


def killed_wall_s(started: str | None, log: Path) -> float | None:
    """A killed attempt's wall time, estimated as its start to the last line it logged (the runner died
    with it and could not time it); None when either is missing or they disagree."""
    try:
        begin = time.mktime(time.strptime(started or "", STAMP))
        wall = log.stat().st_mtime - begin
    except (OSError, ValueError, OverflowError):
        return None
    return round(wall, 1) if wall >= 0 else None


def _finish_record(plan: Plan, cell: Cell, rec: dict, t0: float) -> None:
    wall = time.perf_counter() - t0
    end = code_version()  # the tree may have changed while the cell ran: then it ran with both
    if end != rec.get("code"):
        rec["code_end"] = end
    else:
        rec.pop("code_end", None)
    _add_attempt(
        rec,
        {
            "started": rec["started"],
            "wall_s": round(wall, 1),
            "rc": rec.get("rc"),
            "code": rec.get("code"),
            **({"code_end": end} if "code_end" in rec else {}),
        },
    )
    write_record(plan, cell, rec)


def _add_attempt(rec: dict, attempt: dict) -> None:
    """One place that appends an attempt and adds its time to the cell's (an untimed one adds none)."""
    rec.setdefault("history", []).append(attempt)
    rec["wall_s"] = round(float(rec.get("wall_s", 0.0)) + (attempt["wall_s"] or 0.0), 1)


# ----- redo ------------------------------------------------------------------------------------------
def dependents(plan: Plan, ids: list[str]) -> list[str]:
    """`ids` and every cell that (transitively) depends on them, in plan order."""
    out = set(ids)
    for cid, cell in plan.cells.items():
        if any(d in out for d in cell.deps):
            out.add(cid)
    return [c for c in plan.cells if c in out]


def move_aside(plan: Plan, cell: Cell) -> Path | None:
    """Keep a cell's old results as `<folder>.old-N` (its record inside), so it starts afresh."""
    rec = record_path(plan, cell)
    if not cell.folder.exists():
        rec.unlink(missing_ok=True)
        return None
    n = 1
    while cell.folder.with_name(f"{cell.folder.name}.old-{n}").exists():
        n += 1
    dest = cell.folder.with_name(f"{cell.folder.name}.old-{n}")
    cell.folder.rename(dest)
    if rec.exists():
        shutil.move(str(rec), str(dest / "experiment_record.json"))
    return dest


# ----- the run ---------------------------------------------------------------------------------------
def describe_plan(plan: Plan, ids: list[str], statuses: dict[str, Status]) -> list[str]:
    """`--dry-run`: each cell's status and the exact command(s) it runs."""
    lines = []
    for cid in ids:
        cell, st = plan.cells[cid], statuses[cid]
        lines.append(f"{cid:<22} {st}")
        for argv in cell.commands if st.state in ("done", "redo") else commands_to_run(cell):
            lines.append(f"    {display(cell, argv)}")
    return lines


def _preflight(plan: Plan, ids: list[str], statuses: dict[str, Status], redone: list[str]) -> None:
    """Refuse, before any work, cells changed since they ran (unless redone) and a missing user dataset."""
    stale = [c for c in ids if statuses[c].state == "changed" and c not in redone]
    if stale:
        changed = [f"{c} ({statuses[c].detail})" for c in stale]

        # a bare name (`rl`) takes the cell's training and evaluation: only where both are stale
        names = ",".join(
            dict.fromkeys(
                bare if set(match_cells(plan, [bare := c.split(":", 1)[1]])) <= set(stale) else c for c in stale
            )
        )
        raise DefinitionError(
            f"cell(s) changed since they ran: {'; '.join(changed)}; fix: --redo {names} recomputes "
            "them and what depends on them (old folders are kept as <folder>.old-N), or restore "
            "the definition"
        )
    data = plan.cells["data:data"]
    if not data.commands and statuses["data:data"].state != "done":
        raise DefinitionError(
            f"scale {plan.scale.name!r} reads its episodes from {plan.episodes_dir}, which holds no "
            "episode files (*.json.gz); fix: --set data.episodes=/path/to/hm3d_ovon_episodes --set "
            "data.scenes=/path/to/scene_datasets"
        )


def redo(plan: Plan, cascade: list[str], console: Console) -> None:
    """Move the old results of the cells in `cascade` aside (see `dependents`), holding every one's lock
    meanwhile so that no other runner starts one of them half-moved."""
    locks = {}
    try:
        for cid in cascade:
            lock = cell_lock(plan, plan.cells[cid])
            if lock is None:
                who = lock_holder(plan, plan.cells[cid]) or "another process"
                raise DefinitionError(f"--redo: cell {cid} is in use by {who}; fix: wait for it, then re-run")
            locks[cid] = lock
        for cid in cascade:
            dest = move_aside(plan, plan.cells[cid])
            if dest is not None:
                say(console, f"{cid}: old results kept in {dest}")
    finally:
        for lock in locks.values():
            lock.release()


def run(
    plan: Plan,
    only: list[str] | None = None,
    shard: tuple[int, int] | None = None,
    redo_cells: list[str] | tuple = (),
    dry_run: bool = False,
    wait: bool = True,
    write_report: bool = True,
    console: Console | None = None,
) -> RunResult:
    """Run the plan's selected cells (see the module docstring); `wait`: when cells are being run by
    another process, wait for them instead of leaving them (and what needs them) for a later run."""

    console = console or Console()
    ids = select(plan, only, shard)
    statuses = plan_status(plan)
    cascade = dependents(plan, match_cells(plan, list(redo_cells), flag="--redo")) if redo_cells else []
    if "data:data" in cascade and not plan.cells["data:data"].commands:
        raise DefinitionError(
            f"--redo data: scale {plan.scale.name!r} reads your own dataset ({plan.episodes_dir}), "
            "which the runner never moves; fix: --redo the training or evaluation cells instead"
        )
    outside = [c for c in cascade if c not in ids]
    if outside:  # moved aside but never recomputed: what reads them would then be missing
        raise DefinitionError(
            f"--redo {','.join(redo_cells)} also recomputes {', '.join(outside)} (they read what "
            "is redone), which --only/--shard leaves out; fix: add them to --only, or drop --only "
            "/ --shard"
        )
    for cid in cascade:
        statuses[cid] = Status("redo", "its old folder will be kept as <folder>.old-N")
    unknown = [c for c in config_unknown(plan, ids) if c not in cascade]
    if unknown:
        say(
            console,
            f"note: {len(unknown)} finished cell(s) ran before ovon recorded resolved configs "
            f"({', '.join(unknown)}): only their run folder's identity is compared; --redo them to record it",
        )
    if dry_run:
        head = f"{plan.names} at scale {plan.scale.name}, root {plan.root}: {len(ids)} of {len(plan.cells)} cells"
        say(console, head + (f" (shard {shard[0]}/{shard[1]})" if shard else ""))
        for line in describe_plan(plan, ids, statuses):
            say(console, line)
        return RunResult({c: statuses[c] for c in ids})
    _preflight(plan, ids, statuses, cascade)
    if cascade:
        redo(plan, cascade, console)
    (plan.base / "data").mkdir(parents=True, exist_ok=True)  # the shared goal-text cache lives there
    result = _loop(plan, ids, wait, console)
    if write_report:
        from ovon.experiments.report import write_experiment_report

        result.report = write_experiment_report(plan, plan.base / "reports" / plan.names)
        say(console, f"report: {result.report}")
    return result


def _loop(plan: Plan, ids: list[str], wait: bool, console: Console) -> RunResult:
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    result = RunResult()
    blocked: set[str] = set()  # failed in this run, or needing a failed cell
    progress = (
        Progress(
            TextColumn("{task.description}"),
            BarColumn(),
            MofNCompleteColumn(),
            TimeElapsedColumn(),
            console=console,
            transient=True,
        )
        if console.is_terminal
        else None
    )
    if progress is not None:
        progress.start()
    try:
        while True:
            statuses = plan_status(plan)
            todo = [c for c in ids if statuses[c].state not in ("done", "unavailable") and c not in blocked]
            startable = [c for c in todo if statuses[c].state in ("missing", "partial", "failed")]
            started = False
            for cid in startable:
                cell = plan.cells[cid]
                lock = cell_lock(plan, cell)
                if lock is None:
                    continue
                try:
                    st = plan_status(plan, check_lock=False)[cid]  # re-read under the lock
                    if st.state == "done":
                        continue
                    started = True
                    _run_one(plan, cell, st, progress, console, result, blocked)
                finally:
                    lock.release()
                break
            if started:
                continue
            for cid in todo:  # cells needing a failed one are blocked for this run
                if any(d in blocked for d in plan.cells[cid].deps):
                    blocked.add(cid)
            others = [c for c in todo if c not in blocked]
            if not others or not wait:
                break
            time.sleep(POLL_S * 5)  # the rest is running (or waits for cells running) elsewhere
    finally:
        if progress is not None:
            progress.stop()
    result.statuses = {c: s for c, s in plan_status(plan).items() if c in ids}
    left = [f"{c}: {s}" for c, s in result.statuses.items() if s.state not in ("done", "unavailable")]
    for c, s in result.statuses.items():
        if s.state == "unavailable":
            say(console, f"{c}: not run: {s.detail}")
    if left:
        say(console, "not finished: " + "; ".join(left))
    return result


def _run_one(
    plan: Plan, cell: Cell, st: Status, progress, console: Console, result: RunResult, blocked: set[str]
) -> None:
    cmds = commands_to_run(cell)
    say(console, f"{cell.id}: {st} -> " + " && ".join(display(cell, a) for a in cmds))
    t0 = time.perf_counter()
    rc = execute(plan, cell, progress)
    minutes = (time.perf_counter() - t0) / 60
    if rc == 0:
        result.ran.append(cell.id)
        say(console, f"{cell.id}: done in {minutes:.1f} min")
        return
    result.failed.append(cell.id)
    blocked.add(cell.id)
    say(
        console,
        f"{cell.id}: FAILED (exit {rc}) after {minutes:.1f} min; log {log_path(plan, cell)}:\n"
        f"{log_tail(log_path(plan, cell))}",
    )
