"""Figures never switch the global matplotlib backend (a notebook user's backend stays as it is): the
report, experiment and top-down figures draw on `Figure` objects and `savefig`, without pyplot."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

SCRIPT = """
import sys
from pathlib import Path
import matplotlib
matplotlib.use("svg")  # what a user chose before importing ovon
import ovon.experiments.figures as figures
import ovon.reports.plots as plots
from ovon.scenes.procedural import generate_house
from ovon.scenes.topdown import render_topdown

out = Path(sys.argv[1])
rec = {"split": "val_seen", "success": 0, "failure": "timeout_missed_goal", "geodesic_distance": 3.0,
       "category": "bed"}
plots.plot_failures("x", [rec, {**rec, "success": 1, "failure": None}], out / "failures.png")
plots.plot_sr_vs_distance([("x", [rec])], out / "distance.png")
(out / "run").mkdir()
rows = ['{"update": 1, "step": 8, "loss": 1.5}', '{"update": 2, "step": 16, "loss": 1.2}']
(out / "run" / "metrics.jsonl").write_text("\\n".join(rows) + "\\n")
assert figures.training_curve("x", out / "run", out / "curve.png") == out / "curve.png"
render_topdown(generate_house(0), out / "house.png")
print(matplotlib.get_backend(), "matplotlib.pyplot" in sys.modules)
"""


def test_figures_leave_the_backend_alone(tmp_path: Path) -> None:
    r = subprocess.run(
        [sys.executable, "-c", SCRIPT, str(tmp_path)], cwd=ROOT, capture_output=True, text=True, timeout=300
    )
    assert r.returncode == 0, r.stderr[-2000:]
    assert r.stdout.split() == ["svg", "False"]
    for name in ("failures.png", "distance.png", "curve.png", "house.png"):
        assert (tmp_path / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", name


def _png_size(path: Path) -> tuple[int, int]:
    import struct

    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n", path
    return struct.unpack(">II", data[16:24])


def _table(rows: int, cols: int) -> dict:
    columns = [f"split{j}" for j in range(cols)]
    return {
        "columns": columns,
        "rows": [
            {
                "name": f"agent-{i}",
                "cells": {
                    c: {
                        "ours": None if (i, j) == (0, 0) else {"sr": (10.0 + 5 * i + j, 2.0)},
                        "paper": None if (i, j) == (1, 1) else {"sr": 20.0 + i},
                    }
                    for j, c in enumerate(columns)
                },
            }
            for i in range(rows)
        ],
    }


def test_table_figure_is_page_shaped_grouped_bars(tmp_path: Path) -> None:
    """The summary figure: ours beside the paper per split, one panel per split, not a 6:1 strip."""
    from ovon.experiments.figures import table_figure

    for rows, cols in ((6, 4), (3, 1), (8, 5)):
        out = table_figure("main", _table(rows, cols), tmp_path / f"t{rows}x{cols}.png")
        w, h = _png_size(out)
        assert 0.8 <= w / h <= 3.0, (rows, cols, w, h)


def test_training_curve_panels_wrap(tmp_path: Path) -> None:
    import json

    from ovon.experiments.figures import training_curve

    run = tmp_path / "run"
    run.mkdir()
    keys = ("episode/success", "episode/spl", "reward/mean", "value_loss", "entropy", "lr/actor")
    rows = [{"update": i, "step": 300_000 * i, **{k: 0.1 * i for k in keys}} for i in range(1, 30)]
    (run / "metrics.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
    w, h = _png_size(training_curve("ppo", run, tmp_path / "curve.png"))
    assert w / h <= 2.5, (w, h)


def test_sr_vs_distance_colours_are_distinct(tmp_path: Path) -> None:
    from ovon.reports import plots

    for n in (3, 12, 25):
        colors = plots.distinct_colors(n)
        assert len(colors) == n and len({tuple(c) for c in colors}) == n
    recs = [
        {"split": s, "success": k % 2, "failure": None, "geodesic_distance": 1.0 + k, "category": "bed"}
        for s in ("val_seen", "val_seen_synonyms", "val_unseen")
        for k in range(8)
    ]
    runs = [(f"run{i}", recs) for i in range(4)]  # 12 lines: the default cycle would repeat two colours
    assert _png_size(plots.plot_sr_vs_distance(runs, tmp_path / "d.png"))[0] > 0
