"""The experiment report: the paper's number beside ours in every cell, the findings, the figures.

`write_experiment_report(plan, out)` writes `report.md`, `report.json` and PNG figures under `out/`. Ours are
means ± std over evaluation seeds of finished evaluation cells only; a cell that did not finish shows
as "not run" with the reason (never as a zero). Row setups name the perception or detection each agent
used ("oracle perception", "oracle detection"), taken from the cells' resolved configs. The first line
says which code the cells ran with; entries resting on a cell from another commit or a dirty tree are
marked (`provenance`). Commands name no path of the machine they ran on: `$ROOT` (the run root) and,
for a dataset outside it, `$EPISODES` / `$SCENES`.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from ovon.atomic import atomic_write_text, write_json
from ovon.config.base import to_dict
from ovon.evaluate.results import spread_text
from ovon.experiments.cells import Cell, EvalRun, Plan, render_value
from ovon.experiments.definitions import Experiment, Finding, paper_numbers, parse_ref, row_eval
from ovon.experiments.findings import (
    INTERVAL_NOTE,
    PAIRED_NOTE,
    PAIRED_NOTE_BEFORE_MDE,
    RULE_NOTE,
    SAME_SEEDS,
    fill_sentence,
    judge,
    same_seeds_lines,
)
from ovon.experiments.outputs import last_update
from ovon.experiments.plan import PERCEPTION
from ovon.experiments.provenance import (
    MARK,
    cell_provenance,
    code_version,
    headline,
    marked_chain,
    provenance_markdown,
)
from ovon.experiments.records import read_record
from ovon.experiments.status import Status, plan_status
from ovon.experiments.tokens import (
    EPISODES_TOKEN,
    ROOT_TOKEN,
    SCENES_TOKEN,
    full_commands,
    portable_text,
    shell_word,
)
from ovon.reports.power import mde_sentence
from ovon.runfolder import flatten


# ----- what the cells hold ---------------------------------------------------------------------------
def _done_seeds(record: dict | None) -> set[int] | None:
    """The seeds of the config that last finished the cell (None: any)."""
    seeds = ((record or {}).get("config") or {}).get("seeds")
    return {int(s) for s in seeds} if isinstance(seeds, list) else None


def eval_records(plan: Plan, cell: Cell) -> list[dict]:
    """Episode records of a finished evaluation cell: those its last command wanted (its summary's), for
    its splits and finished seeds."""
    from ovon.evaluate.results import selected_records

    seeds = _done_seeds(read_record(plan, cell))
    splits = set(cell.eval_cell.splits) if cell.eval_cell else None
    return [
        r
        for r in selected_records(cell.folder)
        if (seeds is None or int(r["seed"]) in seeds) and (splits is None or r["split"] in splits)
    ]


def setup_label(plan: Plan, cell: Cell) -> str:
    """What the agent of an evaluation cell perceives with, and its noise, in words."""
    ec = cell.eval_cell
    assert ec is not None
    if ec.agent == "policy" and ec.checkpoint:
        image = plan.cells[f"train:{ec.checkpoint}"].train_cfg.encoder.image
        label = PERCEPTION.get(image, image)
    else:
        label = _describe_agent(ec.agent, plan.cells, cell)
    return label + (f"; noise: {ec.noise.replace(',', ', ')}" if ec.noise else "")


def _describe_agent(agent: str, cells: dict, cell: Cell) -> str:
    """The agent's own description (`describe(**agent_args)`, e.g. "VLFM, oracle detection, ...")."""
    from ovon.agents import load_agent_class

    ec = cell.eval_cell
    args = _agent_args(cell)
    if ec.checkpoint:
        args.setdefault("checkpoint", str(cells[f"train:{ec.checkpoint}"].folder / "policy.pt"))
    try:
        describe = getattr(load_agent_class(agent), "describe", None)
        if callable(describe):
            text = str(describe(**args))
            if ec.checkpoint and "perception" not in text:
                image = cells[f"train:{ec.checkpoint}"].train_cfg.encoder.image
                text += f" (policy: {PERCEPTION.get(image, image)})"
            return text
    except Exception:  # noqa: BLE001 - a report renders even when an agent's package is missing or broken
        pass
    shown = {k: v for k, v in args.items() if k != "checkpoint"}
    return f"agent {agent}, " + (", ".join(f"{k}={v}" for k, v in sorted(shown.items())) or "defaults")


def _agent_args(cell: Cell) -> dict[str, Any]:
    """The cell's `--agent-arg` values (flattened keys, as its command passes them)."""
    assert isinstance(cell.run, EvalRun)
    return dict(flatten(cell.run.agent_args))


# ----- collection ------------------------------------------------------------------------------------
def _pct(entry: dict, metric: str) -> tuple[float, float]:
    return 100.0 * entry[metric]["mean"], 100.0 * entry[metric]["std"]


def collect(plan: Plan) -> dict:
    """Everything the report shows, as JSON-able data; paths are written `$ROOT`, `$EPISODES`, `$SCENES`."""
    from ovon.evaluate.results import summarize

    statuses = plan_status(plan)
    prov = cell_provenance(plan, statuses, code_version())
    evals: dict[str, dict] = {}
    for cid, cell in plan.cells.items():
        if cell.kind != "eval":
            continue
        st = statuses[cid]
        info: dict[str, Any] = {
            "status": st.state if st.state == "done" else portable_text(plan, str(st)),
            "setup": setup_label(plan, cell),
            "summary": None,
            "marked": st.state == "done" and marked_chain(plan, prov, cid),
        }
        if st.state == "done":
            records = eval_records(plan, cell)
            info["summary"] = summarize(records)
            info["records"] = records
        evals[cell.name] = info
    out = {
        "experiments": {},
        "scale": plan.scale.name,
        "scale_description": plan.scale.description,
        "root": ROOT_TOKEN,
        "command": run_command_line(plan),
        "paths": path_legend(plan),
        "provenance": prov,
        "cells": _cells_info(plan, statuses, prov),
    }
    for exp in plan.experiments:
        out["experiments"][exp.name] = experiment_results(exp, evals, plan.scale.name)
    for info in evals.values():
        info.pop("records", None)
    out["evaluations"] = evals
    return out


def experiment_results(exp: Experiment, evals: dict[str, dict], scale: str) -> dict:
    """An experiment's table, figures and findings from `evals` (evaluation cell -> {"summary", "status",
    "setup", "records"}); findings are judged on ours and on the paper's numbers. `scale` picks each
    finding's `differs` sentence (required: an empty one would print a fix naming no scale)."""
    from ovon.reports.compare import failure_breakdown

    res: dict[str, Any] = {"title": exp.title, "paper_ref": exp.paper_ref, "description": exp.description}
    entries: dict[tuple[str, str], dict] = {}
    if exp.table is not None:
        rows = []
        for row in exp.table.rows:
            cells = {}
            for col in exp.table.columns:
                name = row_eval(row, col.name)
                ev = evals[name]
                summ = (ev["summary"] or {}).get(col.split)
                ours = None
                if summ is not None:
                    ours = {m: _pct(summ, m) for m in ("sr", "spl")}
                    ours["episodes"] = summ["episodes"]
                    ours["seeds"] = len(summ["seeds"])
                    ours["seeds_identical"] = bool(summ.get("seeds_identical"))
                entry = {
                    "eval": name,
                    "split": col.split,
                    "ours": ours,
                    "status": ev["status"] if ours is None else "done",
                    "marked": ours is not None and bool(ev.get("marked")),
                    "paper": paper_numbers(row, col.name, exp.source),
                }
                cells[col.name] = entry
                entries[(row.name, col.name)] = entry
            setups = list(dict.fromkeys(evals[row_eval(row, c.name)]["setup"] for c in exp.table.columns))
            rows.append({"name": row.name, "setup": "; ".join(setups), "cells": cells})
        res["table"] = {"caption": exp.table.caption, "columns": [c.name for c in exp.table.columns], "rows": rows}
    figures = []
    for fig in exp.figures:
        ev = evals[fig.eval]
        recs = ev.get("records")
        fb = failure_breakdown(recs) if recs else {}
        groups = []
        for g in fig.groups:
            ours = {s: 100.0 * sum(fb[s][lb] for lb in g.labels) for s in fig.splits if s in fb} if fb else None
            groups.append(
                {
                    "name": g.name,
                    "color": g.color,
                    "labels": list(g.labels),
                    "ours": ours,
                    "paper": dict(zip(fig.splits, g.paper)) if g.paper else None,
                    "paper_range": list(g.paper_range) or None,
                }
            )
        success = {s: 100.0 * fb[s]["success"] for s in fig.splits if s in fb} if fb else None
        figures.append(
            {
                "name": fig.name,
                "caption": fig.caption,
                "eval": fig.eval,
                "splits": list(fig.splits),
                "setup": ev["setup"],
                "status": ev["status"],
                "marked": bool(recs and ev.get("marked")),
                "groups": groups,
                "success": success,
            }
        )
    res["figures"] = figures

    def look(source: str):
        def lookup(ref: str, metric: str):
            e = entries[parse_ref(ref, exp.source)]
            if source == "ours":
                return e["ours"][metric] if e["ours"] else None
            p = e["paper"]
            return (p[metric], p[f"{metric}_std"] or 0.0) if p else None

        return lookup

    def paired(ref_a: str, ref_b: str, metric: str) -> dict | None:
        return paired_difference(
            evals, entries[parse_ref(ref_a, exp.source)], entries[parse_ref(ref_b, exp.source)], metric
        )

    def spread(refs: tuple[str, ...]) -> dict | None:
        return split_gaps(evals, {r: entries[parse_ref(r, exp.source)] for r in refs})

    def fill(text: str) -> str:
        return fill_sentence(text, look("ours"), paired)

    res["findings"] = [
        finding_result(f, judge(f, look("ours"), paired, spread), judge(f, look("paper")), scale, exp.source, fill)
        for f in exp.findings
    ]
    return res


def finding_result(
    f: Finding, ours: dict, paper: dict, scale: str, source: str, fill: Callable[[str], str] = str
) -> dict:
    """A judged finding; where our verdict and the paper's differ (both judged), `differs` holds the
    definition's sentence for `scale` with its quoted table values filled in (`fill_sentence`), or says
    where to write one (a difference is never left silent)."""
    out = {"id": f.id, "claim": f.claim, "note": f.note, "ours": ours, "paper": paper}
    judged = "not run" not in (ours["verdict"], paper["verdict"])
    if judged and ours["verdict"] != paper["verdict"]:
        out["differs"] = fill(f.differs.get(scale, "")) or (
            f"not explained yet (fix: add `differs: {{{scale}: SENTENCE}}` to finding {f.id} in {source})"
        )
    return out


def paired_difference(evals: dict[str, dict], a: dict, b: dict, metric: str) -> dict | None:
    """a - b in % points on the episodes both table entries ran (`ovon.reports.paired`); None when they are
    on different splits or episodes, or either has not run."""
    from ovon.reports.paired import compare_pairs, pair_records

    if a["split"] != b["split"]:
        return None
    ra, rb = ([r for r in evals[e["eval"]].get("records") or [] if r["split"] == e["split"]] for e in (a, b))
    if not ra or not rb:
        return None
    try:
        result = compare_pairs(pair_records(rb, ra, b["eval"], a["eval"]))[0]
    except ValueError:  # different episodes: nothing to pair
        return None
    st = next(s for s in result.stats if s.metric == metric)
    return {
        "diff": 100 * st.diff,
        "ci_low": 100 * st.ci_low,
        "ci_high": 100 * st.ci_high,
        "p": result.sign.p_value,
        "mde": 100 * result.mde,  # SR's, whatever the metric: the finding's verdict names it
    }


def split_gaps(evals: dict[str, dict], entries: dict[str, dict]) -> dict | None:
    """`ovon.reports.splits.split_spread` over table entries' episodes, each entry (ref) one group; None when
    any has no episode records."""
    from ovon.reports.splits import split_spread

    records = []
    for ref, e in entries.items():
        mine = [r for r in evals[e["eval"]].get("records") or [] if r["split"] == e["split"]]
        if not mine:
            return None
        records += [{**r, "split": ref} for r in mine]
    return split_spread(records)


def run_command_line(plan: Plan) -> str:
    """The `ovon experiment run` that makes every cell of the report: its scale overrides included."""
    default = flatten(to_dict(plan.catalogue.scales[plan.scale.name]))
    now = flatten(to_dict(plan.scale))
    sets = [f"{k}={render_value(v)}" for k, v in now.items() if default.get(k, object()) != v]
    words = [
        "ovon",
        "experiment",
        "run",
        ",".join(e.name for e in plan.experiments),
        "--scale",
        plan.scale.name,
        "--root",
        ROOT_TOKEN,
        *(w for kv in sets for w in ("--set", portable_text(plan, kv))),
    ]
    return " ".join(shell_word(w) for w in words)


def path_legend(plan: Plan) -> dict[str, str]:
    """What the path tokens of the commands stand for."""
    out = {ROOT_TOKEN: "the run root (`--root`)"}
    if plan.scale.data.source == "paths":
        out[EPISODES_TOKEN] = "the episode dataset (the scale's `data.episodes`)"
        out[SCENES_TOKEN] = "the scene datasets (the scale's `data.scenes`)"
    return out


def _cells_info(plan: Plan, statuses: dict[str, Status], prov: dict) -> dict:
    out = {}
    for cid, cell in plan.cells.items():
        rec = read_record(plan, cell) or {}
        mine = prov["cells"].get(cid, {})
        info = {
            "status": statuses[cid].state,
            "detail": portable_text(plan, statuses[cid].detail),
            "commands": full_commands(plan, cell),
            "wall_min": round(float(rec.get("wall_s", 0.0)) / 60, 1),
            "untimed": sum(1 for h in rec.get("history", []) if h.get("wall_s") is None),
            "attempts": rec.get("attempts", 0),
            "code": ", ".join(mine.get("code", [])),
            "marked": bool(mine.get("marked")),
        }
        if cell.kind == "train":
            info["updates"] = last_update(cell.folder)
            info["planned_updates"] = cell.total
        out[cid] = info
    return out


# ----- markdown --------------------------------------------------------------------------------------
def wall_text(info: dict) -> str:
    """The cell's wall time in minutes; killed attempts from before their time was estimated are named, so
    the sum is read as the lower bound it is."""
    n = info.get("untimed", 0)
    return f"{info['wall_min']}" + (f" (+ {n} killed attempt{'s' * (n > 1)}, time not recorded)" if n else "")


def fmt(ours: dict | None, metric: str) -> str:
    """Our entry's mean ± std over seeds; without the ± where it measures nothing (`spread_text`)."""
    if ours is None:
        return "–"
    m, sd = ours[metric]
    return spread_text(m, sd, ours.get("seeds", 2), bool(ours.get("seeds_identical")), SAME_SEEDS)


def fmt_paper(p: dict | None, metric: str) -> str:
    if p is None:
        return "–"
    std = p[f"{metric}_std"]
    return f"{p[metric]:.1f}" + (f" ± {std:.1f}" if std is not None else "")


def table_markdown(table: dict) -> list[str]:
    cols = table["columns"]
    head = "| method | ours: setup | " + " | ".join(f"{c} SR | {c} SPL" for c in cols) + " |"
    lines = [head, "|---|---|" + "---|---|" * len(cols)]
    notes: dict[str, str] = {}
    for row in table["rows"]:
        cells = []
        for c in cols:
            e = row["cells"][c]
            for m in ("sr", "spl"):
                paper = fmt_paper(e["paper"], m)
                if e["ours"] is None:
                    cells.append(f"not run (paper {paper})")
                    notes.setdefault(e["eval"], e["status"])
                else:
                    mark = MARK if e.get("marked") else ""
                    cells.append(f"**{fmt(e['ours'], m)}**{mark} (paper {paper})")
        lines.append(f"| {row['name']} | {row['setup']} | " + " | ".join(cells) + " |")
    if notes:
        lines.append("")
        lines += [f"- `{k}` not run: {v}" for k, v in notes.items()]
    if any(e.get("marked") for r in table["rows"] for e in r["cells"].values()):
        lines += [
            "",
            f"{MARK} its evaluation, or a cell it needs, ran with another commit than most cells or from a "
            'dirty tree (table "Provenance").',
        ]
    lines += same_seeds_lines(table["rows"])
    done = [e["ours"] for r in table["rows"] for e in r["cells"].values() if e["ours"]]
    counts = {(o["episodes"], o["seeds"]) for o in done}
    if counts:
        # every seed runs the same episodes: a paired comparison has episodes / seeds of them
        fewest = min(n // max(s, 1) for n, s in counts)
        sr = sum(o["sr"][0] for o in done) / len(done) / 100
        lines.append("")
        lines.append(
            "Ours: "
            + ", ".join(f"{n // max(s, 1)} episodes x {s} seeds" for n, s in sorted(counts))
            + f" per entry; mean ± std over seeds. Paper: as printed (3 seeds). Power: {mde_sentence(fewest, sr)}; "
            "each finding's paired verdict states its own."
        )
    return lines


def findings_markdown(findings: list[dict]) -> list[str]:
    lines = []
    for f in findings:
        ours, paper = f["ours"], f["paper"]
        verdict = ours["verdict"] + (" (within noise)" if ours["within_noise"] else "")
        lines.append(f"- **({f['id']}) {f['claim']}**: here **{verdict}**; paper: {paper['verdict']}.")
        for c in ours["checks"]:
            lines.append(f"  - rule: {c['rule']}; ours: {c['numbers']}")
            if c.get("paired"):
                lines.append(f"  - paired: **{c['paired']['verdict']}**: {c['paired']['numbers']}")
            if c.get("interval"):
                lines.append(f"  - episodes: **{c['interval']['verdict']}**: {c['interval']['numbers']}")
        if "differs" in f:
            lines.append(f"  - why it differs from the paper's: {f['differs']}")
        if f["note"]:
            lines.append(f"  - note: {f['note']}")
    return lines


def markdown(data: dict, figures: dict[str, list[str]]) -> str:
    parts = [
        f"# Experiments at scale `{data['scale']}`",
        "",
        headline(data["provenance"]),
        "",
        data["scale_description"],
        "",
        "Each entry: **ours** (mean ± std over evaluation seeds) and the paper's number. A cell that did "
        "not finish shows as *not run*.",
        "",
    ]
    all_findings = []
    for name, exp in data["experiments"].items():
        parts += [f"## {exp['title']} (`{name}`)", "", f"Paper: {exp['paper_ref']}. {exp['description']}", ""]
        if "table" in exp:
            parts += [f"{exp['table']['caption']}:", "", *table_markdown(exp["table"]), ""]
        for fig in exp["figures"]:
            mark = MARK if fig.get("marked") else ""
            parts += [f"{fig['caption']} - ours{mark}: {fig['setup']} ({fig['status']}).", ""]
            parts += _failure_table(fig) + [""]
        parts += [f"![{p}]({p})" for p in figures.get(name, [])] + [""]
        all_findings += exp["findings"]
    if all_findings:
        unshown = [
            c["paired"]["verdict"]
            for f in all_findings
            for c in f["ours"]["checks"]
            if c.get("paired") and c["paired"]["verdict"].startswith("not shown")
        ]
        paired = any(c.get("paired") for f in all_findings for c in f["ours"]["checks"])
        note = PAIRED_NOTE if all("MDE" in v for v in unshown) else PAIRED_NOTE_BEFORE_MDE
        beside = f" Beside it, {note}." if paired else ""  # a report judged before paired checks existed has none
        if any(c.get("interval") for f in all_findings for c in f["ours"]["checks"]):
            beside += f" And {INTERVAL_NOTE}."
        parts += [
            "## The paper's findings here",
            "",
            f"Rules on {RULE_NOTE}; the paper's verdict is the same rule on its own numbers.{beside}",
            "",
            *findings_markdown(all_findings),
            "",
        ]
    parts += ["## Training", "", "| cell | status | updates | wall time (min) | attempts |", "|---|---|---|---|---|"]
    for cid, info in data["cells"].items():
        if cid.startswith("train:"):
            mark = MARK if info["marked"] else ""
            parts.append(
                f"| {cid[6:]}{mark} | {info['status']} | {info['updates'] or '–'} / "
                f"{info['planned_updates'] or '?'}"
                f" | {wall_text(info)} | {info['attempts']} |"
            )
    legend = "; ".join(f"`{k}` is {v}" for k, v in data["paths"].items())
    parts += [
        "",
        *[f"![curve {p}]({p})" for p in figures.get("_curves", [])],
        "",
        "## Provenance",
        "",
        *provenance_markdown(data["provenance"]),
        "",
        "## Commands",
        "",
        f"Every cell's command (all of them: `{data['command']}`); {legend}.",
        "",
        "```",
    ]
    for cid, info in data["cells"].items():
        code = f", {info['code']}" if info["code"] else ""
        mark = f" {MARK}" if info["marked"] else ""
        parts += [f"# {cid}: {info['status']}, {wall_text(info)} min{code}{mark}", *info["commands"]]
    parts += ["```", ""]
    return "\n".join(parts)


def _failure_table(fig: dict) -> list[str]:
    splits = fig["splits"]
    lines = ["| failure (% of episodes) | " + " | ".join(splits) + " |", "|---|" + "---|" * len(splits)]
    for g in fig["groups"]:
        cells = []
        for s in splits:
            ours = f"**{g['ours'][s]:.1f}**" if g["ours"] and s in g["ours"] else "not run"
            if g["paper"]:
                paper = f"{g['paper'][s]:.1f}"
            elif g["paper_range"]:
                paper = f"{g['paper_range'][0]:.1f}-{g['paper_range'][1]:.1f} over the splits"
            else:
                paper = "–"
            cells.append(f"{ours} (paper {paper})")
        lines.append(f"| {g['name']} ({', '.join(g['labels'])}) | " + " | ".join(cells) + " |")
    if fig["success"]:
        lines.append("| success | " + " | ".join(f"{fig['success'].get(s, float('nan')):.1f}" for s in splits) + " |")
    return lines


# ----- entry point -----------------------------------------------------------------------------------
def write_experiment_report(plan: Plan, out: str | Path) -> Path:
    """Write `report.md`, `report.json` and the figures for the plan's experiments into `out`."""
    from ovon.experiments.figures import failure_figure, table_figure, training_curve

    out = Path(out)
    (out / "figures").mkdir(parents=True, exist_ok=True)
    data = collect(plan)
    figures: dict[str, list[str]] = {}
    for name, exp in data["experiments"].items():
        paths = []
        if "table" in exp:
            paths.append(table_figure(exp["title"], exp["table"], out / "figures" / f"{name}_table.png"))
        for fig in exp["figures"]:
            paths.append(failure_figure(fig, out / "figures" / f"{fig['name']}.png"))
        figures[name] = [str(p.relative_to(out)) for p in paths]
    curves = []
    for cell in plan.cells.values():
        if cell.kind == "train":
            p = training_curve(cell.name, cell.folder, out / "figures" / f"curve_{cell.name}.png")
            if p is not None:
                curves.append(str(p.relative_to(out)))
    figures["_curves"] = curves
    write_json(out / "report.json", data)
    atomic_write_text(out / "report.md", markdown(data, figures))
    return out / "report.md"


def report_figures(data: dict, folder: Path) -> dict[str, list[str]]:
    """The figure list `markdown` links, from the PNGs a report folder holds (the names
    `write_experiment_report` gives them, in its order)."""
    figures: dict[str, list[str]] = {}
    for name, exp in data["experiments"].items():
        names = [f"{name}_table.png"] if "table" in exp else []
        names += [f"{fig['name']}.png" for fig in exp["figures"]]
        figures[name] = [f"figures/{n}" for n in names if (folder / "figures" / n).is_file()]
    curves = [f"figures/curve_{cid[6:]}.png" for cid in data["cells"] if cid.startswith("train:")]
    figures["_curves"] = [c for c in curves if (folder / c).is_file()]
    return figures


def render_report(folder: str | Path) -> Path:
    """Rewrite a report folder's `report.md` from its `report.json` with this version's wording: the numbers
    are the JSON's, untouched; no run folder is needed (a committed report outlives its runs)."""
    folder = Path(folder)
    data = load_report(folder)
    out = folder / "report.md"
    atomic_write_text(out, markdown(data, report_figures(data, folder)))
    return out


def load_report(folder: Path) -> dict:
    """A report folder's `report.json`, checked for what `markdown` reads; one-line ValueError otherwise."""
    import json

    src = folder / "report.json"
    try:
        data = json.loads(src.read_text(encoding="utf-8"))
    except OSError as e:
        raise ValueError(
            f"{src}: cannot read it ({e.strerror}); fix: name a folder `ovon experiment report` wrote"
        ) from None
    except json.JSONDecodeError as e:
        raise ValueError(
            f"{src}: not JSON ({e.msg}, line {e.lineno}); fix: regenerate it with `ovon experiment report`"
        ) from None
    need = ("experiments", "scale", "scale_description", "provenance", "cells", "paths", "command")
    missing = [k for k in need if not isinstance(data, dict) or k not in data]
    if missing:
        raise ValueError(
            f"{src}: no {', '.join(missing)}: expected the JSON `ovon experiment report` writes; fix: regenerate it"
        )
    _mark_agreeing_seeds(data)
    return data


def _mark_agreeing_seeds(data: dict) -> None:
    """Reports written before entries recorded `seeds_identical` print a deterministic agent as "± 0.0";
    an entry of 2+ seeds whose SR and SPL both have a std of exactly 0 is what identical seeds give, so it
    is marked as such and renders without the ± (entries that record the check keep theirs)."""
    for exp in data["experiments"].values():
        for row in ((exp or {}).get("table") or {}).get("rows", []):
            for cell in row.get("cells", {}).values():
                ours = cell.get("ours")
                if not ours or "seeds_identical" in ours or ours.get("seeds", 2) < 2:
                    continue
                ours["seeds_identical"] = all(ours.get(m, [0, 1])[1] == 0 for m in ("sr", "spl"))


__all__ = ["collect", "load_report", "render_report", "write_experiment_report"]
