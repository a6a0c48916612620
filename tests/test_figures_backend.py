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
