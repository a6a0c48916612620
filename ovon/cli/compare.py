"""`ovon compare`: paired per-episode comparison of evaluation runs (see `ovon.reports.paired`)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from ovon.config.base import ExistingDir, from_args, in_range, non_empty


@dataclass(frozen=True)
class CompareArgs:
    runs: tuple[str, ...] = non_empty((), each=ExistingDir(), distinct=True, flag="RUNS")
    resamples: int = in_range(10_000, 100, 1_000_000, flag="--resamples")


def register(sub) -> None:
    p = sub.add_parser(
        "compare",
        help="paired comparison of runs on the same episodes: SR/SPL differences with bootstrap 95%% intervals, "
        "a sign test and the SR difference the episodes can detect (MDE, 80%% power)",
    )
    p.add_argument("runs", nargs="+", help="run folders of `ovon evaluate`; the first is the baseline A")
    p.add_argument("--resamples", help="bootstrap resamples (default 10000)")
    p.add_argument("--out", help="folder for compare.json and compare.md (default: print only)")
    p.set_defaults(func=cmd_compare)


def cmd_compare(args) -> int:
    from ovon.atomic import atomic_write_text, write_json
    from ovon.reports.paired import compare_runs, paired_table

    a = from_args(CompareArgs, args, runs=tuple(args.runs))
    result = compare_runs(list(a.runs), a.resamples)
    table = paired_table(result)
    print(table, end="")
    if args.out:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        write_json(out / "compare.json", result)
        atomic_write_text(out / "compare.md", table)
        print(f"compare: {out / 'compare.md'}")
    return 0
