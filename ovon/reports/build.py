"""`ovon report RUN_DIR [RUN_DIR ...]`: the report folder (markdown + figures)."""

from __future__ import annotations

import re
from pathlib import Path

from ovon.atomic import atomic_write_text
from ovon.reports.compare import load_run, markdown_report
from ovon.reports.plots import plot_failures, plot_sr_per_category, plot_sr_vs_distance


def _slug(s: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", s)


def build_report(run_dirs: list[str | Path], out_dir: str | Path) -> Path:
    runs = [load_run(d) for d in run_dirs]
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    md = markdown_report(runs)
    figs = [plot_sr_vs_distance(runs, out / "sr_vs_distance.png")]
    for name, recs in runs:
        figs.append(plot_failures(name, recs, out / f"failures_{_slug(name)}.png"))
        figs.append(plot_sr_per_category(name, recs, out / f"sr_per_category_{_slug(name)}.png"))
    md += "\n## Figures\n\n" + "\n".join(f"![{f.stem}]({f.name})" for f in figs) + "\n"
    atomic_write_text(out / "report.md", md)
    return out / "report.md"
