"""`ovon report RUN_DIR [RUN_DIR ...]`: the report folder (markdown + figures)."""

from __future__ import annotations

import re
from pathlib import Path

from ovon.atomic import atomic_write_text, check_output_path
from ovon.evaluate.protocol import card_line
from ovon.reports.compare import load_meta, load_protocol, load_run, load_skipped, markdown_report
from ovon.reports.labels import run_label
from ovon.reports.plots import plot_failures, plot_sr_per_category, plot_sr_vs_distance


def _slug(s: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", s)


MIXED_WARNING = (
    "**These runs ran under different evaluation protocols** (see Protocol at the end: noise, camera, step "
    "limit or episodes differ), so a gap between rows mixes the agents with the settings."
)


def protocol_section(labels: list[str], cards: list[dict], mixed: bool) -> str:
    """The protocol every row ran under (`ovon.evaluate.protocol`): one line when they agree, else a warning
    and one line per row, so numbers of different protocols are never read as comparable."""
    lines = ["## Protocol", ""]
    known = [c for c in cards if c.get("fingerprint")]
    if not mixed:
        lines.append(card_line(known[0]) if known else "Protocol: not recorded (runs older than protocol cards)")
        if known and len(known) < len(cards):
            lines.append("")
            lines.append("Some runs have no protocol card (written before cards existed).")
    else:
        lines += [f"- {label}: {card_line(c) if c else 'not recorded'}" for label, c in zip(labels, cards)]
    return "\n".join(lines) + "\n"


def build_report(run_dirs: list[str | Path], out_dir: str | Path) -> Path:
    """Tables and figures for the run folders. Rows are named by what the run uses (`run_label`: agent,
    perception, noise); figure files by the run's `name`. An `out_dir` that cannot be a folder (empty,
    a file, under a file) is refused before anything is read or drawn."""
    check_output_path(out_dir, "--out", folder=True)
    loaded = [load_run(d) for d in run_dirs]
    metas = [load_meta(d) for d in run_dirs]
    labels = [run_label(m) if m else name for (name, _), m in zip(loaded, metas)]
    seen: dict[str, int] = {}
    for i, label in enumerate(labels):  # two runs with one label stay two rows
        seen[label] = seen.get(label, 0) + 1
        if seen[label] > 1:
            labels[i] = f"{label} ({Path(run_dirs[i]).name})"
    cards = [load_protocol(d) for d in run_dirs]
    mixed = len({c["fingerprint"] for c in cards if c.get("fingerprint")}) > 1  # runs without a card: not known
    runs = [(label, recs) for label, (_, recs) in zip(labels, loaded)]
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    md = markdown_report(runs, metas, [load_skipped(d) for d in run_dirs])
    if mixed:  # said before the first table: rows of different protocols are not comparable as they stand
        title, _, rest = md.partition("\n")
        md = f"{title}\n\n{MIXED_WARNING}\n{rest}"
    md += "\n" + protocol_section(labels, cards, mixed)
    figs = [plot_sr_vs_distance(runs, out / "sr_vs_distance.png")]
    names = [name for name, _ in loaded]
    for i, (label, recs) in enumerate(runs):
        slug = _slug(names[i] if names.count(names[i]) == 1 else f"{names[i]}_{Path(run_dirs[i]).name}")
        figs.append(plot_failures(label, recs, out / f"failures_{slug}.png"))
        figs.append(plot_sr_per_category(label, recs, out / f"sr_per_category_{slug}.png"))
    md += "\n## Figures\n\n" + "\n".join(f"![{f.stem}]({f.name})" for f in figs) + "\n"
    atomic_write_text(out / "report.md", md)
    return out / "report.md"
