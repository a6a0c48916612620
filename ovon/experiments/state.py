"""What the runner knows about a cell: its record, its identity, its inputs, its lock and its status.

Why records: a cell is finished when its command exited 0 and its outputs exist; the record
(`<root>/<scale>/cells/<kind>-<name>.json`, written atomically) says so, with the command, the
identities of what it read (data listing, init/checkpoint content hashes), the number of attempts and
the wall time, the code it ran with (`ovon 0.1.0 (commit[+dirty])`, per attempt) and its resolved
config. A cell whose definition, resolved config (a preset changed in code) or inputs changed since it
ran is "changed": never silently reused, never silently recomputed (`--redo` moves the old folder aside).
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import json
import os
import re
import shlex
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ovon.atomic import check_output_path, write_json
from ovon.config.base import to_dict
from ovon.experiments.definitions import DefinitionError
from ovon.experiments.plan import Cell, Plan, display
from ovon.runfolder import FileLock, RunFolderError, differences

# Options that may change between the sessions of one evaluation folder without changing an episode's
# result (the evaluation resumes and adds what is missing), and the one that marks a training resume.
EVAL_MAY_CHANGE = ("--seeds", "--episodes", "--splits", "--workers", "--executor", "--no-progress")
FLAGS = ("--no-progress", "--resume")
# A training cell's budget may grow after it finished: the runner resumes its folder to the new budget (no
# schedule depends on the budget, so the result is the run trained that long from the start). A smaller
# budget makes the cell "changed": a finished training is never cut back.
TRAIN_BUDGET = ("max_updates", "total_steps")
EXTEND = "to extend"  # the detail of a finished cell whose budget, seeds, episodes or splits grew
ROOT_TOKEN, EPISODES_TOKEN, SCENES_TOKEN = "$ROOT", "$EPISODES", "$SCENES"
TOKENS = (ROOT_TOKEN, EPISODES_TOKEN, SCENES_TOKEN)

try:
    import fcntl
except ImportError:  # pragma: no cover - Windows
    fcntl = None  # type: ignore[assignment]


@dataclass
class Status:
    state: str  # done | partial | missing | failed | changed | running | waiting | unavailable | redo
    detail: str = ""

    def __str__(self) -> str:
        return f"{self.state} ({self.detail})" if self.detail else self.state


# ----- paths -----------------------------------------------------------------------------------------
def record_path(plan: Plan, cell: Cell) -> Path:
    return plan.base / "cells" / f"{cell.kind}-{cell.name}.json"


def log_path(plan: Plan, cell: Cell) -> Path:
    return plan.base / "logs" / f"{cell.kind}-{cell.name}.log"


def lock_path(plan: Plan, cell: Cell) -> Path:
    return plan.base / "locks" / f"{cell.kind}-{cell.name}.lock"


def read_record(plan: Plan, cell: Cell) -> dict | None:
    """The cell's record, None when it has none, {"state": "unreadable"} when it is torn or garbage. A
    file where a folder of the root should be is not an unreadable record (every cell would read as
    "changed"): it is refused as the root it is."""
    path = record_path(plan, cell)
    try:
        return json.loads(path.read_text())
    except FileNotFoundError:
        return None
    except NotADirectoryError:
        check_output_path(plan.root, "--root", folder=True, writable=False, error=DefinitionError)
        check_output_path(
            path.parent, f"--root {plan.root}: the cells folder", folder=True, writable=False, error=DefinitionError
        )
        return {"state": "unreadable"}
    except (OSError, ValueError):
        return {"state": "unreadable"}


def write_record(plan: Plan, cell: Cell, record: dict) -> None:
    write_json(record_path(plan, cell), record)


# ----- identity --------------------------------------------------------------------------------------
def path_tokens(plan: Plan, legacy: bool = False) -> list[tuple[str, str]]:
    """(path, token) pairs that commands and reports write as a token: the run root as `$ROOT`, and a dataset
    read from elsewhere (`data.source: paths`) as `$EPISODES` / `$SCENES`, so that nothing names the
    machine it ran on. `legacy`: only the root, as records written before ovon 0.1.0's provenance did."""
    pairs = [] if str(plan.root) in ("", ".") else [(str(plan.root), ROOT_TOKEN)]
    if not legacy and plan.scale.data.source == "paths":
        pairs += [(str(plan.episodes_dir), EPISODES_TOKEN), (str(plan.scenes_dir), SCENES_TOKEN)]
    return sorted(pairs, key=lambda p: -len(p[0]))  # the most specific path first


def _tokenised(path: str, pairs: list[tuple[str, str]]) -> str:
    for prefix, token in pairs:
        if path == prefix or path.startswith(prefix.rstrip("/") + "/"):
            return token + path[len(prefix.rstrip("/")) :]
    return path


def _portable(plan: Plan, arg: str, legacy: bool = False) -> str:
    """`arg` with a leading root or dataset path (or a `key=` value starting with one) written as its token."""
    pairs = path_tokens(plan, legacy)
    whole = _tokenised(arg, pairs)
    if whole != arg:
        return whole
    key, eq, value = arg.partition("=")
    return key + eq + _tokenised(value, pairs) if eq else arg


def portable_text(plan: Plan, text: str) -> str:
    """Free text (a status detail) with every root or dataset path in it written as its token."""
    for prefix, token in path_tokens(plan):
        text = re.sub(re.escape(prefix.rstrip("/")) + r"(?=/|$|[\s,;:)'\"])", lambda _m, t=token: t, text)
    return text


def shell_word(arg: str) -> str:
    """`arg` quoted for a POSIX shell, leaving the path tokens expandable: `$ROOT/cpu/train/x` stays bare
    (or double-quoted around other special characters), so a command can be pasted after `ROOT=...`."""
    plain = arg
    for token in TOKENS:
        plain = plain.replace(token, "T")
    if plain == arg or "$" in plain:
        return shlex.quote(arg)
    if shlex.quote(plain) == plain:
        return arg
    return f'"{arg}"' if not any(c in plain for c in '"\\`') else shlex.quote(arg)


def portable_display(plan: Plan, cell: Cell, argv: list[str], legacy: bool = False) -> str:
    """The command as `display` writes it, with its paths written as tokens (see `path_tokens`)."""
    return " ".join([display(cell, []), *(shell_word(_portable(plan, a, legacy)) for a in argv)])


def full_commands(plan: Plan, cell: Cell, legacy: bool = False) -> list[str]:
    """The commands as text with the root written `$ROOT` and a dataset outside it `$EPISODES` / `$SCENES`
    (moving either changes nothing)."""
    return [portable_display(plan, cell, argv, legacy) for argv in cell.commands]


def identity(plan: Plan, cell: Cell, legacy: bool = False) -> list[str]:
    """What must not change for a finished cell to count: its commands without the options that only
    extend an evaluation (seeds, episodes, splits) or set its parallelism."""
    out = []
    for argv in cell.commands:
        kept, skip = [], False
        for a in argv:
            if skip:
                skip = False
                continue
            if cell.kind == "eval" and a in EVAL_MAY_CHANGE:
                skip = a not in FLAGS
                continue
            kept.append(a)
        out.append(portable_display(plan, cell, without_budget(kept) if cell.kind == "train" else kept, legacy))
    return out


def without_budget(words: list[str]) -> list[str]:
    """A training command's words without its `--set` budget options (`TRAIN_BUDGET`)."""
    out: list[str] = []
    i = 0
    while i < len(words):
        if words[i] == "--set" and i + 1 < len(words) and words[i + 1].partition("=")[0] in TRAIN_BUDGET:
            i += 2
            continue
        out.append(words[i])
        i += 1
    return out


def _recorded_identity(rec: dict, cell: Cell) -> list[str] | None:
    """The record's identity; a training record written before budgets could grow still names its budget."""
    ident = rec.get("identity")
    if cell.kind != "train" or not isinstance(ident, list):
        return ident
    try:
        return [shlex.join(without_budget(shlex.split(c))) for c in ident]
    except ValueError:
        return ident


def _in_form_of(recorded: list[str] | None, plan: Plan, cell: Cell, what) -> list[str]:
    """The cell's `what(plan, cell)` in the form of `recorded` (older records: only the root a token), so
    a message names the real difference, not the form."""
    new_form = any(t in c for c in recorded or [] for t in (EPISODES_TOKEN, SCENES_TOKEN))
    return what(plan, cell, legacy=not new_form and plan.scale.data.source == "paths")


PAIRED = ("--set", "--agent-arg")  # options whose pairs may come in any order (when their keys differ)


def _normal(words: list[str], kind: str) -> list[str]:
    """A command's words as compared: `--set` / `--agent-arg` pairs sorted unless a key repeats (then the
    last one wins: order matters), and a data cell's `--workers` left out (generation gives the same files
    whatever the number of workers)."""
    rest, pairs, i = [], [], 0
    while i < len(words):
        w = words[i]
        if w in PAIRED and i + 1 < len(words):
            pairs.append((w, words[i + 1]))
            i += 2
        elif kind == "data" and w == "--workers" and i + 1 < len(words):
            i += 2
        else:
            rest.append(w)
            i += 1
    keys = [(o, v.partition("=")[0]) for o, v in pairs]
    if len(set(keys)) == len(keys):
        pairs.sort()
    return rest + [x for p in pairs for x in p]


def same_commands(recorded: list[str] | None, plan: Plan, cell: Cell, what) -> bool:
    """Whether recorded command text is the cell's `what(plan, cell)` (full_commands or identity), word by
    word (quoting and the order of `--set` pairs aside, see `_normal`), also in the form records had before
    datasets outside the root were tokens."""
    if recorded is None:
        return False
    try:
        words = [_normal(shlex.split(c), cell.kind) for c in recorded]
    except ValueError:
        return False
    return any(
        words == [_normal(shlex.split(c), cell.kind) for c in what(plan, cell, legacy=legacy)]
        for legacy in (False, True)
    )


def first_difference(old: list[str], new: list[str]) -> str:
    """The first differing token of two command lists, for messages."""
    if len(old) != len(new):
        return f"{len(old)} command(s) -> {len(new)}"
    for a, b in zip(old, new):
        ta, tb = shlex.split(a), shlex.split(b)
        for i, (x, y) in enumerate(zip(ta, tb)):
            if x != y:
                opt = ta[i - 1] + " " if i and ta[i - 1].startswith("--") and ta[i - 1] == tb[i - 1] else ""
                return f"{opt}{x} -> {opt}{y}"
        if len(ta) != len(tb):
            extra = ta[len(tb) :] or tb[len(ta) :]
            return f"{'removed' if len(ta) > len(tb) else 'added'} {' '.join(extra[:4])}"
    return ""


# ----- resolved config -------------------------------------------------------------------------------
# Keys of a resolved config that say where or how fast a cell runs, or what an evaluation extends (seeds,
# episodes, splits): they may change without making a finished cell stale. Inputs (the dataset, a
# checkpoint) are compared by content (`inputs`), not by path.
CONFIG_MAY_CHANGE = {
    "train": (
        "env_workers",
        "threads",
        "rollout_threads",
        "device",
        "encoder.device",
        "progress",
        "log_every",
        "checkpoint_every",
        "keep_checkpoints",
        "text_cache",
        "bc.record_workers",
        *TRAIN_BUDGET,
    ),
    "eval": ("data", "scenes", "splits", "seeds", "episodes", "workers", "executor", "name"),
    "data": (),
}


def resolved_config(plan: Plan, cell: Cell) -> dict | None:
    """The config the cell's command resolves to now, as JSON (paths as tokens): `ovon train`'s TrainConfig
    (presets and `--set`), `ovon evaluate`'s EvalConfig (agent arguments, noise, camera, task) with the
    agent's own config where its class resolves one (`resolved_config(**agent_args)`, e.g. VLFM's preset),
    `ovon dataset generate`'s GenerationConfig. A preset changed in code changes it where the command line
    does not. None when the cell has no command (the user's own dataset) or cannot be resolved now (e.g.
    its checkpoint is gone)."""
    if not cell.commands:
        return None
    try:
        return _tokenised_values(plan, _config(cell, cell.commands[-1]))
    except (OSError, ValueError, TypeError, KeyError, ImportError):  # ConfigError is a ValueError
        return None


def _config(cell: Cell, argv: list[str]) -> dict:
    from ovon.experiments.plan import parse_cli

    if cell.kind == "train":
        return to_dict(cell.train_cfg)
    args = parse_cli(argv, cell.id)
    if cell.kind == "data":
        from ovon.cli.dataset import generation_config

        return to_dict(generation_config(args))
    from ovon.agents import load_agent_class
    from ovon.cli.evaluate import eval_config

    with contextlib.redirect_stdout(io.StringIO()):  # "camera of the checkpoint: ..."
        cfg = eval_config(args)
    out = to_dict(cfg)
    agent = getattr(load_agent_class(cfg.agent), "resolved_config", None)  # an agent's own presets (VLFM)
    if callable(agent):
        out["agent_config"] = to_dict(agent(**dict(cfg.agent_kwargs)))
    return out


def _tokenised_values(plan: Plan, value: Any) -> Any:
    value = json.loads(json.dumps(value, default=str))
    pairs = path_tokens(plan)

    def walk(v: Any) -> Any:
        if isinstance(v, dict):
            return {k: walk(x) for k, x in v.items()}
        if isinstance(v, list):
            return [walk(x) for x in v]
        return _tokenised(v, pairs) if isinstance(v, str) else v

    return walk(value)


def config_change(plan: Plan, cell: Cell, record: dict) -> str:
    """ "" when the cell's recorded resolved config is its config now (or either is unknown), else the
    first differing key, e.g. `finetune.anchor "none" -> "kl"` (and how many more differ)."""
    old = record.get("config")
    if not isinstance(old, dict):
        return ""
    now = resolved_config(plan, cell)
    if now is None:
        return ""
    diffs = differences(old, now, CONFIG_MAY_CHANGE[cell.kind])
    if cell.kind == "train":
        diffs = budget_shrunk(old, now) + diffs
    if not diffs:
        return ""
    return diffs[0] + (f" (and {len(diffs) - 1} more)" if len(diffs) > 1 else "")


def budget_shrunk(old: dict, now: dict) -> list[str]:
    """The budget keys of a training config that went down (`max_updates` 0 = no cap)."""
    out = []
    for key in TRAIN_BUDGET:
        a, b = old.get(key), now.get(key)
        if not (isinstance(a, int) and isinstance(b, int)):
            continue
        cap_a, cap_b = (a or float("inf"), b or float("inf")) if key == "max_updates" else (a, b)
        if cap_b < cap_a:
            out.append(f"{key} {a} -> {b} (a finished training is never cut back)")
    return out


def config_unknown(plan: Plan, ids: list[str]) -> list[str]:
    """Finished cells whose record predates resolved configs: only their commands can be compared."""
    out = []
    for cid in ids:
        cell = plan.cells[cid]
        rec = read_record(plan, cell) if cell.commands else None
        if rec and rec.get("state") == "done" and "config" not in rec:
            out.append(cid)
    return out


# ----- inputs ----------------------------------------------------------------------------------------
_HASHES: dict[tuple, str] = {}


HASH_CACHE = ".file_hashes.json"  # under the scale's folder: content hashes by path, size and mtime


def file_hash(path: Path, persistent: dict[str, list] | None = None) -> str | None:
    """Content hash of a file (cached by size and mtime within the process, and in `persistent` when
    given), None when absent."""
    try:
        st = path.stat()
    except OSError:
        return None
    key = (str(path), st.st_size, st.st_mtime_ns)
    if key not in _HASHES:
        known = (persistent or {}).get(key[0])
        if known is not None and known[:2] == [st.st_size, st.st_mtime_ns]:
            _HASHES[key] = known[2]
        else:
            h = hashlib.sha256()
            with open(path, "rb") as f:
                for block in iter(lambda: f.read(1 << 20), b""):
                    h.update(block)
            _HASHES[key] = h.hexdigest()
    if persistent is not None:
        persistent[key[0]] = [st.st_size, st.st_mtime_ns, _HASHES[key]]
    return _HASHES[key]


def _read_hash_cache(path: Path) -> dict[str, list]:
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError):
        return {}  # absent or torn by a crash: it is only a cache
    ok = isinstance(data, dict) and all(isinstance(v, list) and len(v) == 3 for v in data.values())
    return data if ok else {}


def episodes_content_fingerprint(plan: Plan) -> str | None:
    """Identity of the episode files by their content: an episode file edited to the same size (a changed
    goal, a moved start) makes what read it stale. Why cheap enough: each file is read once per size and
    mtime; the hashes persist in the scale folder's `.file_hashes.json`, so a status pass stats the files."""
    root = plan.episodes_dir
    files = sorted(p for p in root.rglob("*.json.gz") if p.is_file()) if root.is_dir() else []
    if not files:
        return None
    cache_path = plan.base / HASH_CACHE
    cache = _read_hash_cache(cache_path)
    before = dict(cache)
    h = hashlib.sha256()
    for p in files:
        h.update(f"{p.relative_to(root).as_posix()}\0{file_hash(p, cache)}\n".encode())
    if cache != before and plan.base.is_dir():
        with contextlib.suppress(OSError):  # read-only root: hash again next time
            write_json(cache_path, cache)
    return h.hexdigest()


def data_fingerprint(plan: Plan) -> str | None:
    """Identity of the episode dataset: names and sizes of its episode files (cheap for any size)."""
    root = plan.episodes_dir
    if not root.is_dir():
        return None
    h = hashlib.sha256()
    files = sorted(p for p in root.rglob("*.json.gz") if p.is_file())
    if not files:
        return None
    for p in files:
        h.update(f"{p.relative_to(root).as_posix()}\0{p.stat().st_size}\n".encode())
    return h.hexdigest()


def scenes_fingerprint(plan: Plan) -> str | None:
    """Identity of the scenes: names and sizes of the files under the scenes root (another release of a
    scene dataset at the same path differs), without reading them."""
    root = plan.scenes_dir
    if not root.is_dir():
        return None
    h = hashlib.sha256()
    for p in sorted(p for p in root.rglob("*") if p.is_file()):
        h.update(f"{p.relative_to(root).as_posix()}\0{p.stat().st_size}\n".encode())
    return h.hexdigest()


def dataset_fingerprints(plan: Plan) -> dict[str, str | None]:
    """The episodes' and the scenes' identities, which every non-data cell reads. `data` (names and sizes)
    is kept beside `episodes` (content) so that records from before the content was recorded still compare."""
    return {
        "data": data_fingerprint(plan),
        "episodes": episodes_content_fingerprint(plan),
        "scenes": scenes_fingerprint(plan),
    }


def inputs(plan: Plan, cell: Cell, dataset: dict | None = None) -> dict[str, Any]:
    """Identities of what the cell reads (absent values are None); `dataset`: `dataset_fingerprints(plan)`
    when the caller has it (a status pass lists the files once, not once per cell)."""
    if cell.kind == "data":
        return {}
    out: dict[str, Any] = dict(dataset if dataset is not None else dataset_fingerprints(plan))
    for dep in cell.deps:
        if dep.startswith("train:"):
            out[dep] = file_hash(plan.cells[dep].folder / "policy.pt")
    return out


# ----- outputs ---------------------------------------------------------------------------------------
def finished_outputs(plan: Plan, cell: Cell) -> bool:
    if cell.kind == "train":
        return (cell.folder / "policy.pt").is_file()
    if cell.kind == "eval":
        return (cell.folder / "summary.json").is_file()
    return data_fingerprint(plan) is not None


def partial_outputs(plan: Plan, cell: Cell) -> str:
    """What a killed or failed attempt left ("" when nothing), e.g. "update 120/400"."""
    if cell.kind == "train":
        if not (cell.folder / "checkpoint.pt").is_file():
            return ""
        update = last_update(cell.folder)
        return f"update {update}/{cell.total or '?'}" if update is not None else "checkpoint"
    if cell.kind == "eval":
        n = count_lines(cell.folder / "episodes.jsonl")
        return f"{n}/{cell.total or '?'} episodes" if n else ""
    return "some files" if cell.folder.is_dir() and any(cell.folder.iterdir()) else ""


def last_update(folder: Path) -> int | None:
    path = folder / "metrics.jsonl"
    try:
        with open(path, "rb") as f:
            f.seek(0, os.SEEK_END)
            f.seek(max(0, f.tell() - 4096))
            lines = [ln for ln in f.read().splitlines() if ln.strip()]
        for ln in reversed(lines):
            try:
                return int(json.loads(ln)["update"])
            except (ValueError, KeyError):
                continue
    except OSError:
        return None
    return None


def count_lines(path: Path) -> int:
    try:
        with open(path, "rb") as f:
            return sum(1 for ln in f if ln.endswith(b"\n"))
    except OSError:
        return 0


# ----- locks -----------------------------------------------------------------------------------------
def cell_lock(plan: Plan, cell: Cell) -> FileLock | None:
    """The cell's lock (`ovon.runfolder.FileLock`: flock, released by the kernel when its holder dies, so a
    killed run never leaves a stale lock; works across machines on a shared file system with flock), or
    None when another process holds it."""
    try:
        return FileLock(lock_path(plan, cell), what="--root")
    except RunFolderError:
        return None


def lock_holder(plan: Plan, cell: Cell) -> str | None:
    """Who holds the cell's lock right now ("pid N on HOST since ..."), None when nobody does (a status
    check creates nothing)."""
    path = lock_path(plan, cell)
    if fcntl is None or not path.exists():
        return None
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return None
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
        return None
    except OSError:
        pass
    finally:
        os.close(fd)
    try:
        info = json.loads(lock_path(plan, cell).read_text())
        return f"pid {info['pid']} on {info['host']} since {info['since']}"
    except (OSError, ValueError, KeyError):
        return "another process"


# ----- status ----------------------------------------------------------------------------------------
def changed_inputs(plan: Plan, cell: Cell, rec: dict, dataset: dict | None = None) -> list[str]:
    """The inputs the record holds that differ now (records written before an input was recorded compare
    only what they hold)."""
    now = inputs(plan, cell, dataset)
    return [k for k, v in (rec.get("inputs") or {}).items() if now.get(k) != v]


def cell_status(
    plan: Plan, cell: Cell, statuses: dict[str, Status], check_lock: bool = True, dataset: dict | None = None
) -> Status:
    """The cell's status given the statuses of the cells before it (`statuses`, by id); `dataset` as in
    `inputs`."""
    if cell.unavailable:
        return Status("unavailable", cell.unavailable)
    if cell.kind == "data" and not cell.commands:  # the user's own dataset (paper scale)
        if data_fingerprint(plan) is None:
            return Status("missing", f"no episode files (*.json.gz) under {plan.episodes_dir}")
        return Status("done", f"episodes {plan.episodes_dir}, scenes {plan.scenes_dir}")
    if check_lock:
        holder = lock_holder(plan, cell)
        if holder:
            return Status("running", holder)
    rec = read_record(plan, cell)
    if rec is not None and rec.get("state") == "unreadable":
        return Status("changed", f"its record {record_path(plan, cell)} is unreadable")
    recorded_identity = _recorded_identity(rec, cell) if rec is not None else None
    if rec is not None and not same_commands(recorded_identity, plan, cell, identity):
        why = first_difference(recorded_identity or [], _in_form_of(recorded_identity, plan, cell, identity))
        return Status("changed", f"the definition changed since it ran: {why}")
    why = config_change(plan, cell, rec) if rec is not None else ""
    if why:
        return Status("changed", f"its resolved config changed since it ran: {why}")
    if rec is not None and rec.get("state") == "done" and finished_outputs(plan, cell):
        moved = changed_inputs(plan, cell, rec, dataset)
        if moved:
            return Status("changed", f"its input(s) {', '.join(moved)} changed since it ran")
        # a cell it reads that will be recomputed (its definition, config or inputs changed, or --redo)
        stale = [d for d in cell.deps if statuses.get(d, Status("done")).state in ("changed", "redo")]
        if stale:
            return Status("changed", f"{', '.join(stale)}, which it reads, changed since it ran")
        extended = [
            d
            for d in cell.deps
            if statuses.get(d, Status("done")).state == "partial" and statuses[d].detail.startswith(EXTEND)
        ]
        if extended:
            return Status("changed", f"{', '.join(extended)}, which it reads, is to be extended")
        if not same_commands(rec.get("commands"), plan, cell, full_commands):
            why = first_difference(
                rec.get("commands") or [], _in_form_of(rec.get("commands"), plan, cell, full_commands)
            )
            return Status("partial", f"{EXTEND}: {why}")
        return Status("done", f"{rec.get('wall_s', 0) / 60:.1f} min")
    waiting = [d for d in cell.deps if statuses.get(d, Status("done")).state != "done"]
    if waiting:
        return Status("waiting", ", ".join(waiting))
    if rec is not None and rec.get("inputs"):  # an unfinished attempt read other inputs: it cannot resume
        moved = changed_inputs(plan, cell, rec, dataset)
        if moved:
            return Status("changed", f"its input(s) {', '.join(moved)} changed since its last attempt")
    left = partial_outputs(plan, cell)
    if rec is not None and rec.get("state") == "failed":
        more = f"; {left}" if left else ""
        return Status("failed", f"exit code {rec.get('rc')}, see {log_path(plan, cell)}{more}")
    if left:
        return Status("partial", left)
    return Status("missing")


def plan_status(plan: Plan, ids: list[str] | None = None, check_lock: bool = True) -> dict[str, Status]:
    """Status of every cell (or of `ids` and what they depend on), in plan order."""
    out: dict[str, Status] = {}
    dataset = dataset_fingerprints(plan)
    for cid, cell in plan.cells.items():
        out[cid] = cell_status(plan, cell, out, check_lock, dataset)
    return out if ids is None else {k: v for k, v in out.items() if k in ids}
