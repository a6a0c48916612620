"""The results tables of the README and of the docs' results page, rendered from the committed reports
(`experiments/results/<name>/report.json`), so that no number is copied by hand and none goes stale: the
docs render them when the site builds, `ovon experiment headline --write README.md` rewrites the README's
block and a test fails when that block differs from what the reports say."""

from __future__ import annotations

import json
from pathlib import Path

from ovon.evaluate.results import spread_text
from ovon.experiments.definitions import experiment_names
from ovon.experiments.findings import SAME_SEEDS, same_seeds_lines
from ovon.experiments.provenance import headline as provenance_line

BEGIN = "<!-- ovon:headline (generated from experiments/results by `ovon experiment headline`; do not edit) -->"
END = "<!-- /ovon:headline -->"
DEFAULT = ("main",)
# `<name>-oracle/`: the same experiment run with oracle perception, kept beside the learned-perception report
ORACLE = "-oracle"


class HeadlineError(ValueError):
    """A report that is missing or not one `ovon experiment report` wrote, or a file without the block."""


def _load(results: Path, name: str, folder: str = "") -> dict:
    path = results / (folder or name) / "report.json"
    try:
        report = json.loads(path.read_text(encoding="utf-8"))
        return report["experiments"][name] | {"_report": report}
    except FileNotFoundError:
        raise HeadlineError(
            f"{path}: no such report; fix: write it with `ovon experiment report {name} --root ROOT --out "
            f"{results / name}`"
        ) from None
    except (json.JSONDecodeError, KeyError, TypeError) as e:
        raise HeadlineError(f"{path}: not a report `ovon experiment report` wrote ({e}); fix: write it again") from None


def _entry(cell: dict) -> str:
    ours = cell.get("ours")
    paper = cell.get("paper")
    if ours is None:
        text = "not run"
    else:
        identical = bool(ours.get("seeds_identical"))
        text = spread_text(*ours["sr"], ours.get("seeds", 2), identical, SAME_SEEDS, bold=True)
    return text + (f" ({paper['sr']:.1f})" if paper else "")


def table(results: Path, name: str, link: str) -> list[str]:
    """One experiment's SR table (ours ± std over evaluation seeds, the paper's in brackets) and its
    provenance; `link` is the report's path as seen from the page it goes into."""
    exp = _load(results, name)
    report = exp.pop("_report")
    tab = exp.get("table")
    if not tab:
        raise HeadlineError(f"{results / name / 'report.json'}: experiment {name!r} has no table")
    cols = tab["columns"]
    seeds = sorted({c["ours"]["seeds"] for r in tab["rows"] for c in r["cells"].values() if c.get("ours")})
    lines = [
        f"**{exp['title']}** (scale `{report['scale']}`; SR %, ours ± std over "
        f"{'/'.join(map(str, seeds)) or 'no'} evaluation seeds, the paper's in brackets; "
        f"[full report]({link})). {provenance_line(report['provenance'])}",
        "",
        "| method | perception | " + " | ".join(cols) + " |",
        "|---|---|" + "---|" * len(cols),
    ]
    for row in tab["rows"]:
        lines.append(f"| {row['name']} | {row['setup']} | " + " | ".join(_entry(row["cells"][c]) for c in cols) + " |")
    return lines + same_seeds_lines(tab["rows"])


def _verdict(found: dict | None) -> str:
    if found is None:
        return "–"
    text = found["verdict"] + (" (within noise)" if found.get("within_noise") else "")
    paired = [c["paired"]["verdict"] for c in found.get("checks", []) if c.get("paired")]
    episodes = [c["interval"]["verdict"] for c in found.get("checks", []) if c.get("interval")]
    return (
        text
        + (f"; paired: {', '.join(paired)}" if paired else "")
        + (f"; episodes: {', '.join(episodes)}" if episodes else "")
    )


def findings(results: Path) -> list[str]:
    """Every finding of the committed reports: the paper's verdict under the same rule, ours, and ours with
    oracle perception where that run is kept (`<name>-oracle/`); empty when no report has findings."""
    rows = []
    for name in experiment_names():
        if not (results / name / "report.json").is_file():
            continue
        oracle = {}
        if (results / f"{name}{ORACLE}" / "report.json").is_file():
            oracle = {f["id"]: f["ours"] for f in _load(results, name, f"{name}{ORACLE}").get("findings", [])}
        for f in _load(results, name).get("findings", []):
            rows.append(
                f"| ({f['id']}) | {f['claim']} | {f['paper']['verdict']} | **{_verdict(f['ours'])}** | "
                f"{_verdict(oracle.get(f['id']))} |"
            )
    if not rows:
        return []
    head = [
        "The paper's findings, each judged by the same rule on the paper's numbers, on ours, and on ours with "
        "oracle perception (the earlier run, kept as `<name>-oracle`):",
        "",
        "| finding | claim | paper | ours | ours, oracle perception |",
        "|---|---|---|---|---|",
    ]
    return head + sorted(rows)


def headline(results: str | Path, names: tuple[str, ...] = DEFAULT, prefix: str = "") -> str:
    """The tables of `names`, each report linked as `prefix + <name>/report.md`, then every finding."""
    results = Path(results)
    try:
        parts = [table(results, n, f"{prefix}{n}/report.md") for n in names]
        parts.append(findings(results))
    except (KeyError, TypeError, IndexError, ValueError) as e:
        if isinstance(e, HeadlineError):
            raise
        raise HeadlineError(
            f"{results}: a report there lacks what `ovon experiment report` writes ({type(e).__name__}: {e}); "
            "fix: write it again"
        ) from None
    return "\n\n".join("\n".join(p) for p in parts if p) + "\n"


def replace_block(text: str, block: str, where: str) -> str:
    """`text` with the lines between BEGIN and END replaced by `block`."""
    start, end = text.find(BEGIN), text.find(END)
    if start < 0 or end < start:
        raise HeadlineError(f"{where}: no '{BEGIN}' ... '{END}' block; fix: add the two lines where the table goes")
    return text[: start + len(BEGIN)] + "\n\n" + block + "\n" + text[end:]


__all__ = ["BEGIN", "END", "HeadlineError", "findings", "headline", "replace_block", "table"]
