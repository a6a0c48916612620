"""The run folder's records: an append-only `episodes.jsonl` (resumable), its repair, its canonical order
and its aggregation into summaries.

Why a canonical order: workers finish episodes in any order; records are appended as they come (so a
kill loses at most the episode in flight) and rewritten in (split, seed, scene, episode) order when the
run finishes, and summaries are computed in that order, so 1 or N workers, processes or Ray give
byte-identical files. Why set lines aside: a torn or unparsable line (a kill mid-write, a disk error, a
hand edit) must never cost the complete records after it; it is moved to `episodes.rejected.jsonl`.
"""

from __future__ import annotations

import json
import math
import os
import warnings
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path

from ovon.atomic import atomic_write_bytes
from ovon.dataset.io import VAL_SPLITS

EPISODES_FILE = "episodes.jsonl"
REJECTED_FILE = "episodes.rejected.jsonl"
_NUMBERS = ("spl", "soft_spl", "distance_to_goal", "steps", "collisions")


class RecordWarning(UserWarning):
    """Lines of episodes.jsonl set aside (torn, unparsable, not a record, or a duplicate)."""


def record_key(r: dict) -> tuple:
    return (r["split"], int(r["seed"]), r["scene"], str(r["episode_id"]))


def _natural(s: str) -> tuple:
    return (0, int(s), "") if s.isdigit() else (1, 0, s)


def canonical_key(r: dict) -> tuple:
    """Sort key: splits in the paper's order, then seed, scene, episode id (numeric ids by value)."""
    split = r["split"]
    rank = VAL_SPLITS.index(split) if split in VAL_SPLITS else len(VAL_SPLITS)
    return (rank, split, int(r["seed"]), r["scene"], _natural(str(r["episode_id"])))


def record_problem(r: object) -> str | None:
    """Why a parsed line is not an episode record, or None."""
    if not isinstance(r, dict):
        return "not a JSON object"
    for k in ("split", "scene"):
        if not isinstance(r.get(k), str):
            return f"{k} is not a string"
    if not isinstance(r.get("episode_id"), str | int) or isinstance(r.get("episode_id"), bool):
        return "episode_id is not a string"
    if not isinstance(r.get("seed"), int) or isinstance(r.get("seed"), bool):
        return "seed is not an integer"
    if not isinstance(r.get("success"), bool):
        return "success is not true/false"
    for k in _NUMBERS:
        v = r.get(k)
        if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
            return f"{k} is not a finite number"
    if not (r.get("failure") is None or isinstance(r.get("failure"), str)):
        return "failure is not a string"
    if not isinstance(r.get("category"), str):
        return "category is not a string"
    g = r.get("geodesic_distance")  # reports bin by it; an unreachable start may hold Infinity
    if isinstance(g, bool) or not isinstance(g, int | float):
        return "geodesic_distance is not a number"
    return None


def encode(record: dict) -> bytes:
    """The one serialisation of a record (sorted keys: equal records give equal bytes)."""
    return (json.dumps(record, sort_keys=True) + "\n").encode("utf-8")


@dataclass
class RecordFile:
    """What `episodes.jsonl` holds: complete records (first per key) and the lines that are not."""

    records: list[dict] = field(default_factory=list)
    rejected: list[dict] = field(default_factory=list)  # {"line", "reason", "text"}


def parse_records(data: bytes) -> RecordFile:
    out = RecordFile()
    seen: set[tuple] = set()
    lines = data.split(b"\n")
    torn_tail = lines[-1] != b""  # no newline at the end: the last write did not finish
    if not torn_tail:
        lines = lines[:-1]
    for i, line in enumerate(lines, 1):
        text = line.decode("utf-8", errors="replace")
        if i == len(lines) and torn_tail:
            out.rejected.append({"line": i, "reason": "torn (no end of line)", "text": text})
            continue
        if not line.strip():
            continue
        try:
            r = json.loads(line)
        except (ValueError, RecursionError) as e:
            out.rejected.append({"line": i, "reason": f"unparsable ({type(e).__name__})", "text": text})
            continue
        why = record_problem(r)
        if why:
            out.rejected.append({"line": i, "reason": f"not a record: {why}", "text": text})
            continue
        k = record_key(r)
        if k in seen:
            out.rejected.append({"line": i, "reason": "duplicate of an earlier record", "text": text})
            continue
        seen.add(k)
        out.records.append(r)
    return out


def read_records(run_dir: str | Path, repair: bool = False) -> list[dict]:
    """Complete records of a run folder, in file order. Lines that are not (torn, unparsable, duplicates)
    are skipped with a warning; with `repair` (only the holder of the run-folder lock) they are moved to
    `episodes.rejected.jsonl` and the file is rewritten with the complete records only - never fewer."""
    path = Path(run_dir) / EPISODES_FILE
    if not path.exists():
        return []
    data = path.read_bytes()
    rf = parse_records(data)
    if rf.rejected:
        where = ", ".join(str(r["line"]) for r in rf.rejected[:10]) + (" ..." if len(rf.rejected) > 10 else "")
        action = f"moved to {REJECTED_FILE}" if repair else "skipped"
        warnings.warn(
            f"{path}: {len(rf.rejected)} line(s) that are not complete records {action} "
            f"(line {where}); {len(rf.records)} complete records kept",
            RecordWarning,
            stacklevel=2,
        )
        if repair:
            side = Path(run_dir) / REJECTED_FILE
            with open(side, "ab") as f:
                for r in rf.rejected:
                    f.write((json.dumps(r, sort_keys=True) + "\n").encode("utf-8"))
                f.flush()
                os.fsync(f.fileno())
            atomic_write_bytes(path, b"".join(encode(r) for r in rf.records))
    return rf.records


SELECTION_FILE = "selection.json"  # the episodes the run's last command wanted (summary.json's records)


def write_selection(run_dir: str | Path, wanted: set | None) -> None:
    """Record which records the run's summary covers: a run extended and then asked for fewer episodes or
    seeds keeps every record in episodes.jsonl, and a report must show the summary's numbers, not all of
    them. None (every record): no file."""
    path = Path(run_dir) / SELECTION_FILE
    if wanted is None:
        path.unlink(missing_ok=True)
        return
    keys = sorted([split, int(seed), scene, str(eid)] for split, seed, scene, eid in wanted)
    atomic_write_bytes(path, json.dumps({"episodes": keys}).encode())


def selected_records(run_dir: str | Path) -> list[dict]:
    """The records the run's summary covers (`write_selection`): all of them when the run names none."""
    records = read_records(run_dir)
    path = Path(run_dir) / SELECTION_FILE
    if not path.exists():
        return records
    wanted = {tuple(k) for k in json.loads(path.read_text(encoding="utf-8"))["episodes"]}
    return [r for r in records if record_key(r) in wanted]


def write_canonical(run_dir: str | Path, records: list[dict]) -> list[dict]:
    """Rewrite episodes.jsonl with `records` in canonical order (atomically); returns them sorted."""
    ordered = sorted(records, key=canonical_key)
    atomic_write_bytes(Path(run_dir) / EPISODES_FILE, b"".join(encode(r) for r in ordered))
    return ordered


class RecordWriter:
    """Single writer (the parent process, holding the run-folder lock); one line per episode, flushed and
    fsynced as it goes."""

    def __init__(self, run_dir: str | Path):
        Path(run_dir).mkdir(parents=True, exist_ok=True)
        self._f = open(Path(run_dir) / EPISODES_FILE, "ab")

    def write(self, record: dict) -> None:
        self._f.write(encode(record))
        self._f.flush()
        os.fsync(self._f.fileno())

    def close(self) -> None:
        self._f.close()


def _mean_std(values: list[float]) -> tuple[float, float]:
    """Mean and population std (ddof 0, numpy's default) of per-seed values."""
    if not values:
        return float("nan"), float("nan")
    m = math.fsum(values) / len(values)
    var = math.fsum((v - m) ** 2 for v in values) / len(values)
    return m, math.sqrt(var)


def summarize(records: list[dict]) -> dict:
    """Per split: per-seed means, then mean and std over seeds (the paper's table convention).

    Sums are exact (`math.fsum`) over records in canonical order, so the numbers do not depend on the
    order in which workers finished."""
    by_split: dict[str, dict[int, list[dict]]] = defaultdict(lambda: defaultdict(list))
    for r in sorted(records, key=canonical_key):
        by_split[r["split"]][int(r["seed"])].append(r)
    out: dict = {}
    for split in sorted(by_split):
        seeds = by_split[split]
        per_seed = {}
        for seed, rs in sorted(seeds.items()):
            n = len(rs)
            per_seed[seed] = {
                "episodes": n,
                "sr": math.fsum(float(r["success"]) for r in rs) / n,
                "spl": math.fsum(r["spl"] for r in rs) / n,
                "soft_spl": math.fsum(r["soft_spl"] for r in rs) / n,
                "distance_to_goal": math.fsum(r["distance_to_goal"] for r in rs) / n,
                "steps": math.fsum(r["steps"] for r in rs) / n,
                "collisions": math.fsum(r["collisions"] for r in rs) / n,
            }
        entry: dict = {"seeds": per_seed}
        for metric in ("sr", "spl", "soft_spl", "distance_to_goal", "steps", "collisions"):
            m, s = _mean_std([v[metric] for v in per_seed.values()])
            entry[metric] = {"mean": m, "std": s}
        failures: dict[str, int] = defaultdict(int)
        for rs in seeds.values():
            for r in rs:
                if not r["success"]:
                    failures[r["failure"] or "unknown"] += 1
        entry["failures"] = dict(sorted(failures.items()))
        entry["episodes"] = sum(len(rs) for rs in seeds.values())
        entry["seeds_identical"] = seeds_identical(seeds)
        out[split] = entry
    return out


def seeds_identical(seeds: dict[int, list[dict]]) -> bool:
    """Whether every seed ran the same episodes to the same ends (a deterministic agent in a run without
    noise): the std over such seeds is 0 by construction and is no measure of uncertainty."""
    if len(seeds) < 2:
        return False
    ends = {
        tuple((r["scene"], str(r["episode_id"]), bool(r["success"]), r["steps"], r["spl"]) for r in rs)
        for rs in seeds.values()
    }
    return len(ends) == 1


def coverage_lines(splits: dict[str, dict]) -> list[str]:
    """One line per split of a summary that skipped episodes before the run, e.g. "val_seen: 2998 of
    3000 episodes (2 skipped: 1 rotation, 1 start_off_map; ...)": the table's SR covers the 2998."""
    out = []
    for split in sorted(splits, key=lambda s: (VAL_SPLITS.index(s) if s in VAL_SPLITS else len(VAL_SPLITS), s)):
        sk = splits[split].get("skipped") or {}
        if sk.get("count"):
            reasons = ", ".join(f"{n} {k}" for k, n in sk.get("reasons", {}).items())
            per_seed = " per seed" if len(splits[split].get("seeds", {})) > 1 else ""
            out.append(
                f"{split}: {sk['picked'] - sk['count']} of {sk['picked']} episodes{per_seed} ({sk['count']} "
                f"skipped before the run: {reasons}; `ovon dataset validate` lists them)"
            )
    return out


def spread_text(
    mean: float, std: float, seeds: int, identical: bool = False, identical_mark: str = "", bold: bool = False
) -> str:
    """'mean ± std' over seeds, in the value's unit (one decimal; `bold`: the mean in markdown bold). One seed,
    or seeds that all ran to the same ends, have a std of 0 that measures nothing, so no ± is printed:
    "(1 seed)", or `identical_mark` (a table whose note explains it) or "(seeds agree)"."""
    head = f"**{mean:.1f}**" if bold else f"{mean:.1f}"
    if seeds < 2:
        return f"{head} (1 seed)"
    if identical:
        return head + (identical_mark or " (seeds agree)")
    return f"{head} ± {std:.1f}"


def entry_text(entry: dict, metric: str) -> str:
    """A `summarize` entry's metric in % as tables print it (`spread_text`)."""
    m, sd = entry[metric]["mean"], entry[metric]["std"]
    return spread_text(100 * m, 100 * sd, len(entry["seeds"]), bool(entry.get("seeds_identical")))


def paper_table(rows: dict[str, dict], splits: tuple[str, ...] = VAL_SPLITS) -> str:
    """Markdown table: rows = agents, columns = SR and SPL per split (mean ± std over seeds, in %)."""
    present = [s for s in splits if any(s in summ for summ in rows.values())]
    extra = sorted({s for summ in rows.values() for s in summ} - set(present))
    cols = present + extra
    head = "| agent | " + " | ".join(f"{s} SR | {s} SPL" for s in cols) + " |"
    sep = "|---|" + "---|---|" * len(cols)
    lines = [head, sep]
    for name, summ in rows.items():
        cells = []
        for s in cols:
            if s not in summ:
                cells += ["–", "–"]
                continue
            cells += [entry_text(summ[s], metric) for metric in ("sr", "spl")]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return "\n".join(lines)
