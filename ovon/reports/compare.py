"""Tables that compare run folders written by `ovon evaluate`."""

from __future__ import annotations

import json
from collections import defaultdict
from pathlib import Path

from ovon.dataset.io import VAL_SPLITS
from ovon.evaluate.results import coverage_lines, entry_text, paper_table, selected_records, summarize
from ovon.reports.labels import agent_label, noise_label
from ovon.reports.power import mde_sentence
from ovon.reports.splits import split_spread, spread_lines
from ovon.task.tracker import FAILURE_LABELS


def read_run_json(path: Path) -> dict:
    """A run folder's JSON file as a dict ({} when absent); a damaged one is one line naming it."""
    if not path.is_file():
        return {}
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as e:
        raise ValueError(f"{path}: not readable JSON ({e}); fix: re-run `ovon evaluate` into that folder") from None
    return doc if isinstance(doc, dict) else {}


def load_meta(run_dir: str | Path) -> dict:
    """The run's `run.json` (agent, agent_kwargs, sim incl. noise, name), {} when absent."""
    return read_run_json(Path(run_dir) / "run.json")


def load_protocol(run_dir: str | Path) -> dict:
    """The run's protocol card (summary.json), {} for a run written before cards existed or whose summary is
    damaged (a report still renders; `finalize` rewrites the summary)."""
    try:
        card = read_run_json(Path(run_dir) / "summary.json").get("protocol")
    except ValueError:
        return {}
    return card if isinstance(card, dict) else {}


def load_run(run_dir: str | Path) -> tuple[str, list[dict]]:
    run_dir = Path(run_dir)
    if not (run_dir / "episodes.jsonl").exists():
        raise FileNotFoundError(
            f"{run_dir} is not a run folder (no episodes.jsonl); run `ovon evaluate --out {run_dir}`"
        )
    name = load_meta(run_dir).get("name") or run_dir.name
    return name, selected_records(run_dir)


def load_skipped(run_dir: str | Path) -> list[str]:
    """The run's episodes skipped before it ran, one line per split (`coverage_lines` of its summary.json);
    empty when none was skipped or the run has no summary yet."""
    path = Path(run_dir) / "summary.json"
    try:
        splits = json.loads(path.read_text()).get("splits", {}) if path.exists() else {}
    except (OSError, ValueError, AttributeError):
        return []
    return coverage_lines(splits) if isinstance(splits, dict) else []


def failure_breakdown(records: list[dict]) -> dict[str, dict[str, float]]:
    """Per split: share of *all* episodes (as in the paper's figure) ending with each failure label."""
    out: dict[str, dict[str, float]] = {}
    by_split: dict[str, list[dict]] = defaultdict(list)
    for r in records:
        by_split[r["split"]].append(r)
    for split, rs in sorted(by_split.items()):
        n = len(rs)
        out[split] = {label: sum(r["failure"] == label for r in rs) / n for label in FAILURE_LABELS}
        out[split]["success"] = sum(r["success"] for r in rs) / n
    return out


def sr_by(records: list[dict], key) -> dict[str, dict[str, tuple[float, int]]]:
    """split -> group -> (success rate, episodes) for a grouping function of a record."""
    acc: dict[str, dict[str, list[int]]] = defaultdict(lambda: defaultdict(list))
    for r in records:
        acc[r["split"]][key(r)].append(int(r["success"]))
    return {s: {g: (sum(v) / len(v), len(v)) for g, v in sorted(groups.items())} for s, groups in acc.items()}


DISTANCE_BINS = (0.0, 2.5, 5.0, 7.5, 10.0, 15.0, 20.0, 30.0, float("inf"))


def distance_bin(d: float) -> str:
    for lo, hi in zip(DISTANCE_BINS, DISTANCE_BINS[1:]):
        if lo <= d < hi:
            return f"{lo:g}-{hi:g} m" if hi != float("inf") else f">= {lo:g} m"
    return "nan"


def noise_table(rows: list[tuple[str, str, dict]]) -> str:
    """The paper's noise table: one line per (agent, eval noise), agents in first-seen order, the run
    without noise first; SR / SPL per split (mean ± std over seeds, %)."""
    splits = [s for s in VAL_SPLITS if any(s in summ for _, _, summ in rows)]
    head = "| method | eval noise | " + " | ".join(f"{s} SR | {s} SPL" for s in splits) + " |"
    lines = [head, "|---|---|" + "---|---|" * len(splits)]
    order = list(dict.fromkeys(label for label, _, _ in rows))
    for label in order:
        for _, noise, summ in sorted((r for r in rows if r[0] == label), key=lambda r: r[1] != ""):
            cells = []
            for s in splits:
                for metric in ("sr", "spl"):
                    if s not in summ:
                        cells.append("–")
                        continue
                    cells.append(entry_text(summ[s], metric))
            lines.append(f"| {label} | {'✓ ' + noise if noise else '–'} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def markdown_report(
    runs: list[tuple[str, list[dict]]], metas: list[dict] | None = None, skipped: list[list[str]] | None = None
) -> str:
    """`runs` = (row name, records); `metas` (run.json per run) adds the noise table when any run has noise;
    `skipped` (`load_skipped` per run) lists the episodes each run skipped before it ran."""
    rows = {name: summarize(recs) for name, recs in runs}
    parts = ["# ovon evaluation report", "", "## SR / SPL (%), mean ± std over seeds", "", paper_table(rows), ""]
    per_seed = [e["seeds"][k]["episodes"] for summ in rows.values() for e in summ.values() for k in e["seeds"]]
    if per_seed:
        srs = [e["sr"]["mean"] for summ in rows.values() for e in summ.values()]
        parts += [
            f"Power: {mde_sentence(min(per_seed), sum(srs) / len(srs))} (`ovon compare` measures it for two runs).",
            "",
        ]
    spreads = [(name, split_spread(recs)) for name, recs in runs]
    if any(sp for _, sp in spreads):
        parts += ["## Across splits (SR, one agent's splits against each other)", ""]
        for name, sp in spreads:
            if sp:
                parts += [f"### {name}", "", *spread_lines(sp), ""]
    notes = [f"- {name}, {line}" for (name, _), lines in zip(runs, skipped or []) for line in lines]
    if notes:
        parts += ["Episodes skipped before the run (the numbers above cover the others):", "", *notes, ""]
    if metas and any(noise_label(m) for m in metas):
        noisy = [(agent_label(m), noise_label(m), rows[name]) for (name, _), m in zip(runs, metas)]
        parts += ["## Noise (each agent with and without evaluation noise)", "", noise_table(noisy), ""]
    parts += ["## Failure breakdown (% of all episodes)", ""]
    for name, recs in runs:
        fb = failure_breakdown(recs)
        parts.append(f"### {name}")
        parts.append("| split | success | " + " | ".join(FAILURE_LABELS) + " |")
        parts.append("|---|---|" + "---|" * len(FAILURE_LABELS))
        for split, shares in fb.items():
            cells = [f"{100 * shares['success']:.1f}"] + [f"{100 * shares[lbl]:.1f}" for lbl in FAILURE_LABELS]
            parts.append(f"| {split} | " + " | ".join(cells) + " |")
        parts.append("")
    parts += ["## Extra metrics (mean over seeds)", ""]
    parts.append("| agent | split | SoftSPL | dist. to goal (m) | steps | collisions |")
    parts.append("|---|---|---|---|---|---|")
    for name, summ in rows.items():
        for split, e in summ.items():
            parts.append(
                f"| {name} | {split} | {100 * e['soft_spl']['mean']:.1f} | {e['distance_to_goal']['mean']:.2f} "
                f"| {e['steps']['mean']:.0f} | {e['collisions']['mean']:.1f} |"
            )
    return "\n".join(parts) + "\n"
