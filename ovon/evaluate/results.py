"""The run folder: an append-only `episodes.jsonl` (resumable) and its aggregation into summaries."""

from __future__ import annotations

import json
import math
import os
from collections import defaultdict
from pathlib import Path

EPISODES_FILE = "episodes.jsonl"


def record_key(r: dict) -> tuple:
    return (r["split"], int(r["seed"]), r["scene"], str(r["episode_id"]))


def read_records(run_dir: str | Path, repair: bool = False) -> list[dict]:
    """Records written so far. A run killed mid-write can leave a torn last line: it is ignored (and cut
    off the file when `repair`), so a resumed run re-runs exactly that episode."""
    path = Path(run_dir) / EPISODES_FILE
    if not path.exists():
        return []
    data = path.read_bytes()
    records, good_end = [], 0
    pos = 0
    for line in data.splitlines(keepends=True):
        pos += len(line)
        if not line.endswith(b"\n"):
            break
        try:
            records.append(json.loads(line))
        except json.JSONDecodeError:
            break
        good_end = pos
    if repair and good_end != len(data):
        with open(path, "r+b") as f:
            f.truncate(good_end)
    # Keep the first record per key: a duplicate can only come from a crash between write and flush.
    seen, unique = set(), []
    for r in records:
        k = record_key(r)
        if k not in seen:
            seen.add(k)
            unique.append(r)
    return unique


class RecordWriter:
    """Single writer (the parent process); one line per episode, flushed and fsynced as it goes."""

    def __init__(self, run_dir: str | Path):
        Path(run_dir).mkdir(parents=True, exist_ok=True)
        self._f = open(Path(run_dir) / EPISODES_FILE, "a", encoding="utf-8")

    def write(self, record: dict) -> None:
        self._f.write(json.dumps(record, sort_keys=True) + "\n")
        self._f.flush()
        os.fsync(self._f.fileno())

    def close(self) -> None:
        self._f.close()


def _mean_std(values: list[float]) -> tuple[float, float]:
    if not values:
        return float("nan"), float("nan")
    m = sum(values) / len(values)
    var = sum((v - m) ** 2 for v in values) / len(values)
    return m, math.sqrt(var)


def summarize(records: list[dict]) -> dict:
    """Per split: per-seed means, then mean and std over seeds (the paper's table convention)."""
    by_split: dict[str, dict[int, list[dict]]] = defaultdict(lambda: defaultdict(list))
    for r in records:
        by_split[r["split"]][int(r["seed"])].append(r)
    out: dict = {}
    for split in sorted(by_split):
        seeds = by_split[split]
        per_seed = {}
        for seed, rs in sorted(seeds.items()):
            n = len(rs)
            per_seed[seed] = {
                "episodes": n,
                "sr": sum(r["success"] for r in rs) / n,
                "spl": sum(r["spl"] for r in rs) / n,
                "soft_spl": sum(r["soft_spl"] for r in rs) / n,
                "distance_to_goal": sum(r["distance_to_goal"] for r in rs) / n,
                "steps": sum(r["steps"] for r in rs) / n,
                "collisions": sum(r["collisions"] for r in rs) / n,
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
        out[split] = entry
    return out


SPLIT_ORDER = ("val_seen", "val_seen_synonyms", "val_unseen")


def paper_table(rows: dict[str, dict], splits: tuple[str, ...] = SPLIT_ORDER) -> str:
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
            for metric in ("sr", "spl"):
                m, sd = summ[s][metric]["mean"], summ[s][metric]["std"]
                cells.append(f"{100 * m:.1f} ± {100 * sd:.1f}")
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return "\n".join(lines)
