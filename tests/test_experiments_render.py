"""`ovon experiment render`: a committed report's markdown rewritten from its report.json, numbers untouched."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from ovon.experiments.report import render_report
from tests.cli_errors import one_line, run

RESULTS = Path(__file__).resolve().parents[1] / "experiments" / "results"


def test_a_committed_report_renders_from_its_json_alone(tmp_path, capsys):
    folder = tmp_path / "main"
    shutil.copytree(RESULTS / "main", folder)
    (folder / "report.md").write_text("stale\n")
    rc, out, _ = run(["experiment", "render", str(folder)], capsys)
    assert rc == 0 and f"report: {folder / 'report.md'}" in out
    md = (folder / "report.md").read_text()
    data = json.loads((folder / "report.json").read_text())
    vlfm = next(r for r in data["experiments"]["main"]["table"]["rows"] if r["name"] == "VLFM")
    sr = vlfm["cells"]["val_seen"]["ours"]["sr"]
    assert vlfm["cells"]["val_seen"]["ours"]["seeds_identical"] and sr[1] == 0.0
    assert f"**{sr[0]:.1f}‡**" in md and f"**{sr[0]:.1f} ± 0.0**" not in md  # identical seeds print no ± 0.0
    assert "100 episodes x 4 seeds per entry" in md and "Power: with 100 episodes" in md
    assert "judged before they named their minimum detectable difference" in md  # its verdicts predate the MDE
    assert "![figures/main_table.png](figures/main_table.png)" in md
    assert render_report(folder).read_text() == md  # deterministic


def test_render_refuses_what_is_not_a_report_before_rewriting_any(tmp_path, capsys):
    good = tmp_path / "good"
    shutil.copytree(RESULTS / "main", good)
    before = (good / "report.md").read_text()
    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / "report.json").write_text('{"scale": "cpu"}')
    rc, _, errors = run(["experiment", "render", str(good), str(bad)], capsys)
    one_line(rc, errors, f"{bad / 'report.json'}: no experiments")
    assert (good / "report.md").read_text() == before  # nothing rewritten
    with pytest.raises(ValueError, match="cannot read it"):
        render_report(tmp_path)
    (bad / "report.json").write_text("{")
    with pytest.raises(ValueError, match="not JSON"):
        render_report(bad)
