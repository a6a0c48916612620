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


def test_a_report_from_before_the_seed_check_drops_only_a_std_that_is_zero_on_both_metrics(tmp_path):
    """The -oracle reports predate `seeds_identical`: an entry whose SR and SPL stds are both 0 over 2+ seeds
    renders without "± 0.0"; one whose SPL still varies keeps its ± (its SR std is a coincidence of counts)."""
    folder = tmp_path / "main-oracle"
    shutil.copytree(RESULTS / "main-oracle", folder)
    data = json.loads((folder / "report.json").read_text())
    rows = data["experiments"]["main"]["table"]["rows"]
    assert not any("seeds_identical" in (c["ours"] or {}) for r in rows for c in r["cells"].values())
    md = render_report(folder).read_text()
    line = {r["name"]: next(x for x in md.splitlines() if x.startswith(f"| {r['name']} |")) for r in rows}
    for row in rows:
        for cell in row["cells"].values():
            (sr, sr_sd), (_, spl_sd), seeds = cell["ours"]["sr"], cell["ours"]["spl"], cell["ours"]["seeds"]
            agree = seeds >= 2 and sr_sd == 0 and spl_sd == 0
            assert (f"**{sr:.1f}‡**" in line[row["name"]]) == agree
            if not agree:
                assert f"**{sr:.1f} ± {sr_sd:.1f}**" in line[row["name"]]
    assert any(c["ours"]["sr"][1] == 0 and c["ours"]["spl"][1] > 0 for r in rows for c in r["cells"].values())
    assert "‡ every evaluation seed ran each episode to the same end" in md
