"""The README's results tables are generated from the committed reports, and a stale copy fails here."""

from __future__ import annotations

import contextlib
import io
import json
from pathlib import Path

import pytest

from ovon.cli.main import main
from ovon.experiments.findings import SAME_SEEDS, SAME_SEEDS_NOTE
from ovon.experiments.headline import BEGIN, END, HeadlineError, headline, replace_block

ROOT = Path(__file__).resolve().parents[1]


def _run(argv: list[str]) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main(argv)
        except SystemExit as e:  # argparse errors
            code = int(e.code or 0)
    return code, out.getvalue(), err.getvalue()


def test_the_readme_block_is_what_the_committed_reports_say() -> None:
    code, out, _ = _run(
        ["experiment", "headline", "--results", str(ROOT / "experiments/results"), "--check", str(ROOT / "README.md")]
    )
    # the README's links are relative to the checkout: compare with the block written from there
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    block = text[text.index(BEGIN) + len(BEGIN) : text.index(END)].strip()
    expected = headline(ROOT / "experiments/results", prefix="experiments/results/").strip()
    assert block == expected, "README.md is stale: run `ovon experiment headline --write README.md`"
    assert "| DAgRL |" in block and "[full report](experiments/results/main/report.md)" in block


def _report(folder: Path, dagrl_ours: dict | None, name: str = "main", verdict: str = "not run") -> None:
    cell = {"paper": {"sr": 41.3, "sr_std": 0.3, "spl": 21.2, "spl_std": 0.3}}
    rows = [
        {"name": "DAgRL", "setup": "learned perception (world-vl)",
         "cells": {"val_seen": {**cell, "ours": dagrl_ours}}},
        {"name": "VLFM (oracle perception, upper bound)", "setup": "VLFM, oracle detection, oracle-vl value",
         "cells": {"val_seen": {"paper": None, "ours": {"sr": [80.0, 0.0], "spl": [40.0, 0.0], "seeds": 4}}}},
    ]  # fmt: skip
    finding = {"id": "g", "claim": "DAgRL beats DAgger", "ours": {"verdict": verdict}, "paper": {"verdict": "holds"}}
    report = {
        "scale": "cpu",
        "provenance": {"cells": {}, "report": "ovon 0.1.0 (abc)", "one_clean_commit": True, "reference": ""},
        "experiments": {"main": {"title": "Performance", "table": {"columns": ["val_seen"], "rows": rows},
                                 "findings": [finding]}},
    }  # fmt: skip
    (folder / name).mkdir(parents=True)
    (folder / name / "report.json").write_text(json.dumps(report), encoding="utf-8")


def test_tables_show_unfinished_cells_upper_bounds_and_verdicts(tmp_path: Path) -> None:
    _report(tmp_path, None)
    text = headline(tmp_path, prefix="r/")
    assert "| DAgRL | learned perception (world-vl) | not run (41.3) |" in text
    upper = "| VLFM (oracle perception, upper bound) | VLFM, oracle detection, oracle-vl value | **80.0** ± 0.0 |"
    assert upper in text
    assert "| (g) | DAgRL beats DAgger | holds | **not run** | – |" in text
    _report(tmp_path, None, name="main-oracle", verdict="does not hold")  # the oracle run kept beside it
    assert "| (g) | DAgRL beats DAgger | holds | **not run** | does not hold |" in headline(tmp_path)
    assert "[full report](r/main/report.md)" in text and "4 evaluation seeds" in text
    assert SAME_SEEDS not in text  # reports written before seeds were compared carry no mark


def test_seeds_that_ran_the_same_episodes_are_marked(tmp_path: Path) -> None:
    _report(tmp_path, {"sr": [30.0, 0.0], "spl": [10.0, 0.0], "seeds": 4, "seeds_identical": True})
    text = headline(tmp_path)
    assert f"| **30.0**{SAME_SEEDS} (41.3) |" in text and "± 0.0" not in text.replace("**80.0** ± 0.0", "")
    assert SAME_SEEDS_NOTE in text and "| **80.0** ± 0.0 |" in text  # no mark: seeds not compared


def test_one_seed_prints_no_spread(tmp_path: Path) -> None:
    _report(tmp_path, {"sr": [30.0, 0.0], "spl": [10.0, 0.0], "seeds": 1})
    assert "| **30.0** (1 seed) (41.3) |" in headline(tmp_path)


def test_write_then_check_and_clear_errors(tmp_path: Path) -> None:
    _report(tmp_path / "results", {"sr": [30.0, 2.0], "spl": [10.0, 1.0], "seeds": 4})
    readme = tmp_path / "README.md"
    readme.write_text(f"# x\n\n{BEGIN}\nstale\n{END}\n\ntail\n", encoding="utf-8")
    results = str(tmp_path / "results")
    assert _run(["experiment", "headline", "--results", results, "--check", str(readme)])[0] == 1
    code, out, _ = _run(["experiment", "headline", "--results", results, "--write", str(readme)])
    assert code == 0 and "rewritten" in out
    text = readme.read_text(encoding="utf-8")
    assert "**30.0** ± 2.0 (41.3)" in text and text.endswith(f"{END}\n\ntail\n") and "stale" not in text
    assert _run(["experiment", "headline", "--results", results, "--check", str(readme)])[0] == 0
    # errors: one line naming the file, before anything is written
    code, _, err = _run(["experiment", "headline", "--results", str(tmp_path / "none"), "--write", str(readme)])
    assert code == 2 and "none/main/report.json: no such report" in err and len(err.strip().splitlines()) == 1
    with pytest.raises(HeadlineError, match="no '<!-- ovon:headline"):
        replace_block("no block here\n", "x", "README.md")
    (tmp_path / "results" / "main" / "report.json").write_text('{"experiments": {"main": {}}}', encoding="utf-8")
    code, _, err = _run(["experiment", "headline", "--results", results])
    assert code == 2 and "has no table" in err
    broken = '{"scale": "cpu", "experiments": {"main": {"title": "t", "table": {"columns": ["v"], "rows": [{}]}}}}'
    (tmp_path / "results" / "main" / "report.json").write_text(broken, encoding="utf-8")
    code, _, err = _run(["experiment", "headline", "--results", results])
    assert code == 2 and "lacks what `ovon experiment report` writes" in err and len(err.strip().splitlines()) == 1
    (tmp_path / "results" / "main" / "report.json").write_text("{", encoding="utf-8")
    code, _, err = _run(["experiment", "headline", "--results", results])
    assert code == 2 and "not a report" in err
