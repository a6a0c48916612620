"""`ovon experiment`: the paper's experiments (tables, figures) as one resumable command each."""

from __future__ import annotations

from pathlib import Path


def register(sub) -> None:
    p = sub.add_parser("experiment", help="run the paper's experiments (main, trajectories, memory, noise, failures)")
    s = p.add_subparsers(dest="experiment_command", required=True)

    ls = s.add_parser("list", help="the built-in experiments and scales")
    ls.set_defaults(func=cmd_list)

    r = s.add_parser("run", help="prepare data, train what is missing, evaluate, write the report; resumable")
    _common(r)
    r.add_argument("--scale", required=True, help="tiny | cpu | paper (scales.yaml)")
    r.add_argument("--shard", help="i/n (0-based): take shard i of n; shards are whole dependency chains")
    r.add_argument("--only", help="comma-separated cells (NAME, train:NAME or eval:NAME), with what they need")
    r.add_argument(
        "--redo",
        help="comma-separated cells to recompute, with what depends on them (old folders are kept as <folder>.old-N)",
    )
    r.add_argument("--dry-run", action="store_true", help="print each cell's status and exact command; run nothing")
    r.add_argument(
        "--no-wait",
        action="store_true",
        help="leave cells another process is running (and what needs them) instead of waiting",
    )
    r.add_argument("--no-report", action="store_true", help="do not write <root>/<scale>/reports/<name>/")
    r.set_defaults(func=cmd_run)

    rep = s.add_parser("report", help="markdown + JSON + figures: the paper's numbers beside ours")
    _common(rep)
    rep.add_argument("--scale", help="tiny | cpu | paper (default: the only scale under --root)")
    rep.add_argument("--out", help="report folder (default: <root>/<scale>/reports/<name>)")
    rep.set_defaults(func=cmd_report)

    rr = s.add_parser(
        "render",
        help="rewrite report.md of report folders from their report.json with this version's wording "
        "(numbers unchanged; no run folders needed)",
    )
    rr.add_argument("folders", nargs="+", help="report folders, e.g. experiments/results/main")
    rr.set_defaults(func=cmd_render)

    h = s.add_parser(
        "headline",
        help="the README's results tables from the committed reports: print them, rewrite the README's block, "
        "or check it",
    )
    h.add_argument("--results", default="experiments/results", help="folder of the committed reports")
    h.add_argument("--names", default="main", help="comma-separated experiments whose tables to show")
    h.add_argument("--write", metavar="FILE", help="rewrite the generated block of FILE (e.g. README.md)")
    h.add_argument("--check", metavar="FILE", help="exit 1 when FILE's generated block differs from the reports")
    h.set_defaults(func=cmd_headline)


def _common(p) -> None:
    p.add_argument(
        "name",
        help="experiment: main | trajectories | memory | noise | failures, a comma-separated "
        "list, all, or the path of an experiment .yaml",
    )
    p.add_argument("--root", required=True, help="run root: data, cells, logs and reports go to <root>/<scale>/")
    p.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="scale override, e.g. evaluate.episodes=50, data.episodes=PATH, train.nproc_per_node=4",
    )


def _experiments(name: str) -> list:
    """The experiments NAME names (once each). No name at all ("" or ",") is refused: an empty plan would
    still prepare the data and report success."""
    from ovon.experiments import DefinitionError, experiment_names, load_experiment

    names = experiment_names() if name == "all" else [n.strip() for n in name.split(",") if n.strip()]
    if not names:
        raise DefinitionError(
            f"experiment name {name!r} names no experiment; expected one of "
            f"{', '.join(experiment_names())}, a comma-separated list, all, or the path of an "
            "experiment .yaml; fix: name one, e.g. main"
        )
    return [load_experiment(n) for n in dict.fromkeys(names)]


def _check_root(root: str, writable: bool = False) -> Path:
    """--root is a folder: "" (the current folder), a file or a path under a file are refused here, before
    the plan is resolved (a file would otherwise read as unreadable cell records). `writable`: it is
    written now (a run; a dry run or a report only reads it)."""
    from ovon.atomic import check_output_path
    from ovon.experiments import DefinitionError

    return check_output_path(root, "--root", folder=True, writable=writable, error=DefinitionError)


def _plan(args, scale: str):
    from ovon.experiments import resolve

    _check_root(args.root, writable=getattr(args, "experiment_command", "") == "run" and not args.dry_run)
    return resolve(_experiments(args.name), scale, args.root, args.set)


def _csv(text: str | None) -> list[str]:
    return [x.strip() for x in (text or "").split(",") if x.strip()]


def cmd_list(args) -> int:
    from ovon.experiments import experiment_names, load_catalogue, load_experiment

    for n in experiment_names():
        exp = load_experiment(n)
        print(f"{n:<14} {exp.title} - {exp.paper_ref}")
    for name, sc in load_catalogue().scales.items():
        print(f"scale {name:<8} {sc.description}")
    return 0


def cmd_run(args) -> int:
    from ovon.experiments import parse_shard, run
    from ovon.experiments.select import match_cells

    plan = _plan(args, args.scale)
    shard = parse_shard(args.shard)
    redo = _csv(args.redo)
    match_cells(plan, redo, flag="--redo")  # an unknown --redo cell, named as --redo, before any work
    try:
        result = run(
            plan,
            only=_csv(args.only) or None,
            shard=shard,
            redo_cells=redo,
            dry_run=args.dry_run,
            wait=not args.no_wait,
            write_report=not args.no_report,
        )
    except KeyboardInterrupt:  # with --redo the old results are already aside: --redo again would redo anew
        print("interrupted: re-run the same command " + ("without --redo " if redo else "") + "to resume")
        return 130
    return 0 if result.ok else 1


def cmd_report(args) -> int:
    from ovon.atomic import check_output_path
    from ovon.experiments import write_experiment_report

    scale = args.scale or _only_scale(_check_root(args.root))
    plan = _plan(args, scale)
    out = check_output_path(
        args.out if args.out is not None else plan.base / "reports" / plan.names, "--out", folder=True
    )
    path = write_experiment_report(plan, out)
    print(f"report: {path}")
    return 0


def cmd_render(args) -> int:
    from ovon.experiments.report import load_report, render_report

    for folder in args.folders:  # every folder checked before any report is rewritten
        if not Path(folder).is_dir():
            raise ValueError(f"{folder}: not a folder; fix: name a report folder (it holds report.json)")
        load_report(Path(folder))
    for folder in args.folders:
        print(f"report: {render_report(folder)}")
    return 0


def _only_scale(root: Path) -> str:
    from ovon.experiments import load_catalogue

    found = [s for s in load_catalogue().scales if (root / s / "cells").is_dir()]
    if len(found) != 1:
        raise ValueError(
            f"--root {root} holds runs of scale(s) {found or 'none'}; fix: pass --scale (tiny | cpu | paper)"
        )
    return found[0]


def cmd_headline(args) -> int:
    from ovon.atomic import atomic_write_text
    from ovon.experiments.headline import headline, replace_block

    names = tuple(_csv(args.names))
    block = headline(args.results, names, prefix=args.results.rstrip("/") + "/")
    target = args.write or args.check
    if not target:
        print(block, end="")
        return 0
    path = Path(target)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as e:
        raise ValueError(f"{target}: cannot read it ({e.strerror}); fix: name an existing file") from None
    new = replace_block(text, block, target)
    if args.check:
        if new != text:
            fix = f"ovon experiment headline --write {target}"
            print(f"{target}: its results block differs from {args.results}; fix: {fix}")
            return 1
        print(f"{target}: its results block matches {args.results}")
        return 0
    if new != text:
        atomic_write_text(path, new)
    print(f"{target}: results block {'rewritten' if new != text else 'already up to date'}")
    return 0
