"""Training throughput per algorithm: environment steps/s and time of one train step.

Usage: python benchmarks/train_throughput.py [--preset cpu-small] [--algos bc,dagger,dagger-bf16,ppo] [--updates 4]
       [--workers 2] [--houses 0,1] [--text hash|real] [--out benchmarks/results/train_throughput.json]
       [--baseline-rev REV --repeats 2 --warmup 1] [--set KEY=VALUE ...]

With `--baseline-rev REV` (e.g. the tag `baseline-old-stack`, the code before the env-stack rewrite; or
the directory of an existing worktree of it) this script measures, alternately, this tree and REV's
(a temporary git worktree), each in a fresh process, `--repeats` times; the JSON then holds both
medians, their ratio, the CPU seconds (process tree) of each run, and per algorithm whether every
logged loss, gradient norm and episode metric of every run equals the baseline's
(`same_learning_as_baseline`: a speed-up must not change what is learned). Compare ratios from one run:
the machine is shared and noisy. Each tree first runs once untimed (`--warmup`): a fresh worktree
compiles its numba kernels in its first run, which would otherwise count as the baseline's CPU.
`--set KEY=VALUE` (the CLI's config overrides, e.g. `threads=2`, `ppo.epochs=1`) measures a knob, in
both trees; a knob that changes the learning shows as `same_learning_as_baseline: false` only against
a baseline run without it.

A suffix names a variant that learns differently by design: `-overlap` sets `dagger.overlap=true`
(learning while the next rollout runs), `-bf16` sets `learn_dtype=bfloat16` (DAgger's forward and
backward under bfloat16 autocast); they combine (`dagger-bf16-overlap`). Against REV a variant is compared
with REV's plain algorithm. Each online algorithm (DAgger with the configured expert,
PPO) runs `--updates` updates of the preset on
ad-hoc episodes in procedural houses, envs in `--workers` processes; the first update (world loading,
numba compilation) is reported apart. Reported: env steps/s over whole updates (rollout + learning),
rollout-only steps/s, the learn (train-step) time, CPU ms per env step over the whole run
(`cpu_ms_per_step`, set-up included) and in steady state (`steady_cpu_ms_per_step`: this process and
its env workers from the second rollout's start to the last one's), and from the latter the CPU-bound
rate (steps/s with `workers` cores busy all the time, an upper bound). BC records `--bc-episodes` expert episodes, then
reports the recording rate and the time of one BC update (batch `bc.batch_chunks` chunks of <= context
steps). `--text hash` replaces the text encoder by fixed random vectors of the same size (384) so the
benchmark does not time loading MiniLM; the per-step cost is the same.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import platform
import shutil
import sys
import tempfile
import time
import zlib
from pathlib import Path

import numpy as np

# The ovon tree to measure: this checkout, or (compare mode) the baseline's, run by this same script.
TREE = Path(os.environ.get("OVON_BENCH_TREE") or Path(__file__).resolve().parents[1])
sys.path.insert(0, str(TREE))
from ovon.atomic import atomic_write_text  # noqa: E402
from ovon.config.base import parse_seed_list  # noqa: E402
from ovon.train.config import train_preset  # noqa: E402
from ovon.train.episodes import adhoc_specs  # noqa: E402
from ovon.train.logging import read_metrics  # noqa: E402
from ovon.train.text import needed_texts, write_text_table  # noqa: E402


def _stats(rows: list[dict], key: str) -> float | None:
    vals = [r[key] for r in rows if key in r]
    return float(np.median(vals)) if vals else None


VARIANTS = {
    "overlap": lambda cfg: dataclasses.replace(cfg, dagger=dataclasses.replace(cfg.dagger, overlap=True)),
    "bf16": lambda cfg: dataclasses.replace(cfg, learn_dtype="bfloat16"),
}


ALGOS = {"bc": (), "dagger": tuple(VARIANTS), "ppo": ()}  # algorithm -> the variant suffixes it takes


def split_variants(name: str) -> tuple[str, list[str]]:
    """ "dagger-bf16-overlap" -> ("dagger", ["bf16", "overlap"]); an unknown name or suffix is an error."""
    base, *variants = name.split("-")
    if base not in ALGOS:
        raise SystemExit(f"--algos: unknown algorithm {base!r} in {name!r}; valid: {', '.join(ALGOS)}")
    bad = [v for v in variants if v not in ALGOS[base]]
    if bad:
        takes = ", ".join("-" + v for v in ALGOS[base]) or "none"
        raise SystemExit(f"--algos: {base} takes no variant {'-' + bad[0]!r} (in {name!r}); its suffixes: {takes}")
    return base, variants


def base_config(args, root: Path):
    """The preset with this run's options and `--set` overrides (every algorithm starts from it)."""
    cfg = train_preset(
        args.preset,
        max_updates=args.updates,
        env_workers=args.workers,
        expert=args.expert,
        progress=False,
        checkpoint_every=10**9,
        text_cache=str(root / "text.pt"),
    )
    if args.envs:
        cfg = dataclasses.replace(cfg, num_envs=args.envs)
    if args.set:
        from ovon.config.base import merge, parse_overrides

        cfg = merge(cfg, parse_overrides(args.set))
    return cfg


def config_for(cfg, name: str):
    """The config an `--algos` entry trains: its algorithm, with its variants applied."""
    base, variants = split_variants(name)
    cfg = dataclasses.replace(cfg, algo=base)
    for v in variants:
        cfg = VARIANTS[v](cfg)
    return cfg


def check_algos(args) -> None:
    """Every `--algos` entry, with its variants and `--set`, is a valid training config: refused in one line
    before any algorithm (or the baseline tree) has spent minutes."""
    from ovon.config.base import ConfigError
    from ovon.train import check_config

    try:
        cfg = base_config(args, Path(tempfile.gettempdir()))
        for name in [a for a in args.algos.split(",") if a]:
            check_config(config_for(cfg, name))
    except (ConfigError, ValueError, KeyError) as e:
        raise SystemExit(f"train_throughput.py: {e}") from None


def bench_online(algo: str, cfg, specs, root: Path) -> dict:
    """`algo` is dagger or ppo, optionally with variant suffixes (`VARIANTS`)."""
    from ovon.train import train

    out = root / algo
    t0, c0 = time.perf_counter(), _tree_cpu()
    with _SteadyCPU() as marks:
        train(config_for(cfg, algo), specs, out)
    wall, cpu = time.perf_counter() - t0, _tree_cpu() - c0
    rows = read_metrics(out)
    steady = rows[1:] or rows
    steps = cfg.num_envs * cfg.rollout_steps
    rollout = _stats(steady, "time/rollout_s")
    return {
        # CPU (this process + env workers) from the start of the second rollout to the start of the last
        # one, per env step: set-up, world loading and numba compilation left out
        "steady_cpu_ms_per_step": marks.ms_per_step(steps),
        "learning": _learning(rows),
        "updates": len(rows),
        "steps_per_update": steps,
        "env_steps_per_s": _stats(steady, "steps_per_s"),
        "rollout_steps_per_s": steps / rollout if rollout else None,
        "rollout_s": rollout,
        "learn_s": _stats(steady, "time/learn_s"),
        "first_update_s": rows[0]["time"] if rows else None,
        "wall_s": wall,
        # CPU of this process and its env workers over the whole run (set-up included): on a shared
        # machine the figure that does not depend on what else runs
        "cpu_s": cpu,
        "cpu_ms_per_step": 1000.0 * cpu / max(1, len(rows) * steps),
    }


class _SteadyCPU:
    """Marks (CPU of this process, CPU of the env workers) at the start of every rollout, by wrapping
    `RolloutCollector.collect` while training runs."""

    def __init__(self) -> None:
        self.marks: list[float] = []

    def __enter__(self) -> _SteadyCPU:
        from ovon.env.bench import _cpu_seconds
        from ovon.train import collect

        self.cls, self.orig = collect.RolloutCollector, collect.RolloutCollector.collect
        orig, marks = self.orig, self.marks

        def collect_marked(collector, *args, **kwargs):
            pids = getattr(collector.envs.vec, "worker_pids", [])
            marks.append(time.process_time() + (_cpu_seconds(pids) if pids else 0.0))
            return orig(collector, *args, **kwargs)

        self.cls.collect = collect_marked
        return self

    def __exit__(self, *exc) -> None:
        self.cls.collect = self.orig

    def ms_per_step(self, steps_per_update: int) -> float | None:
        if len(self.marks) < 3:
            return None
        return 1000.0 * (self.marks[-1] - self.marks[1]) / ((len(self.marks) - 2) * steps_per_update)


def _tree_cpu() -> float:
    """User + system CPU seconds of this process and of its finished (joined) children."""
    import resource

    own, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


def _learning(rows: list[dict]) -> list[dict]:
    """Every logged number of every update except timings and rates: equal in two trees iff both
    trained the same (same losses, episodes, gradients), which a speed-up must not change."""
    return [{k: v for k, v in r.items() if not k.startswith("time") and k not in ("steps_per_s", "time")} for r in rows]


def bench_bc(cfg, specs, root: Path, episodes: int) -> dict:
    from ovon.train import train
    from ovon.train.bc import record_shards
    from ovon.train.text import text_table

    shards = root / "bc_shards"
    table = text_table(cfg.encoder, needed_texts(specs), cfg.text_cache, write=False)
    t0 = time.perf_counter()
    res = record_shards(cfg, specs, shards, table, episodes=episodes)
    rec = time.perf_counter() - t0
    steps = sum(r.get("steps", 0) for r in res)
    bc = dataclasses.replace(cfg, algo="bc", bc=dataclasses.replace(cfg.bc, shards=str(shards)))
    train(bc, None, root / "bc")
    rows = read_metrics(root / "bc")
    return {
        "record_episodes": episodes,
        "record_steps": steps,
        "record_steps_per_s": steps / rec,
        "record_success": float(np.mean([r["success"] for r in res if "success" in r])),
        "update_s": _stats(rows[1:] or rows, "time/update_s"),
        "batch_chunks": cfg.bc.batch_chunks,
        "context": cfg.policy.context,
    }


def compare(args) -> None:
    """Run this script alternately here and in a worktree of `args.baseline_rev`; write medians + ratios."""
    import resource
    import subprocess

    here = Path(__file__).resolve().parents[1]
    tmp = Path(tempfile.mkdtemp(prefix="ovon-bench-rev-"))
    base, own = baseline_tree(here, args.baseline_rev, tmp)
    algos = [a for a in args.algos.split(",") if a]
    base_algos = ",".join(dict.fromkeys(split_variants(a)[0] for a in algos))  # REV runs the plain algorithms
    passthrough = [
        "--preset",
        args.preset,
        "--updates",
        str(args.updates),
        "--workers",
        str(args.workers),
        "--houses",
        args.houses,
        "--expert",
        args.expert,
        "--text",
        args.text,
        "--bc-episodes",
        str(args.bc_episodes),
    ]
    if args.envs:
        passthrough += ["--envs", str(args.envs)]
    for item in args.set:
        passthrough += ["--set", item]
    runs: dict[str, list[dict]] = {"current": [], "baseline": []}
    load_before = os.getloadavg()
    try:
        if args.warmup:  # untimed: a fresh worktree compiles (and caches) every numba kernel in its first run
            i = passthrough.index("--updates")
            warm = [*passthrough[:i], "--updates", "1", *passthrough[i + 2 :]]
            for name, root in (("baseline", base), ("current", here)):
                algos_of = base_algos if name == "baseline" else args.algos
                subprocess.run(
                    [
                        sys.executable,
                        str(Path(__file__).resolve()),
                        *warm,
                        "--algos",
                        algos_of,
                        "--out",
                        str(tmp / f"warm-{name}.json"),
                    ],
                    cwd=root,
                    check=True,
                    capture_output=True,
                    env={**os.environ, "PYTHONPATH": str(root), "OVON_BENCH_TREE": str(root)},
                )
        for rep in range(args.repeats):
            for name, root in (("baseline", base), ("current", here)):
                out = tmp / f"{name}{rep}.json"
                before = resource.getrusage(resource.RUSAGE_CHILDREN)
                subprocess.run(
                    [
                        sys.executable,
                        str(Path(__file__).resolve()),
                        *passthrough,
                        "--algos",
                        base_algos if name == "baseline" else args.algos,
                        "--out",
                        str(out),
                    ],
                    cwd=root,
                    check=True,
                    env={**os.environ, "PYTHONPATH": str(root), "OVON_BENCH_TREE": str(root)},
                )
                after = resource.getrusage(resource.RUSAGE_CHILDREN)
                r = json.loads(out.read_text())
                r["cpu_s"] = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
                runs[name].append(r)
                print(
                    name, rep, {a: round(v.get("env_steps_per_s") or 0, 1) for a, v in r["algos"].items()}, flush=True
                )
    finally:
        if own:
            subprocess.run(["git", "-C", str(here), "worktree", "remove", "--force", str(base)], capture_output=True)
        shutil.rmtree(tmp, ignore_errors=True)
    rev = tree_commit(base) if Path(args.baseline_rev).is_dir() else args.baseline_rev
    summary: dict = {
        "baseline_rev": rev,
        "set": args.set,
        "repeats": args.repeats,
        "preset": args.preset,
        "houses": args.houses,
        "updates": args.updates,
        "load_average": os.getloadavg(),
        "warmup": args.warmup,
        "load_average_before": load_before,
        "machine": {"cpus": os.cpu_count(), "platform": platform.platform()},
        "algos": {},
        "runs": runs,
    }
    for algo in [a for a in algos if a != "bc"]:
        key = {"current": algo, "baseline": split_variants(algo)[0]}  # a variant vs REV's plain algo
        med = {n: float(np.median([r["algos"][key[n]]["env_steps_per_s"] for r in rs])) for n, rs in runs.items()}
        rollout = {
            n: float(np.median([r["algos"][key[n]]["rollout_steps_per_s"] for r in rs])) for n, rs in runs.items()
        }
        cpu = {
            n: float(np.median([r["algos"][key[n]].get("cpu_ms_per_step", np.nan) for r in rs]))
            for n, rs in runs.items()
        }
        steady = {
            n: float(np.median([r["algos"][key[n]].get("steady_cpu_ms_per_step") or np.nan for r in rs]))
            for n, rs in runs.items()
        }
        cores = min(args.workers, os.cpu_count() or 1) if args.workers > 0 else 1
        summary["algos"][algo] = {
            "env_steps_per_s": med,
            "rollout_steps_per_s": rollout,
            "ratio": med["current"] / med["baseline"],
            "rollout_ratio": rollout["current"] / rollout["baseline"],
            "cpu_ms_per_step": cpu,
            "cpu_ratio": cpu["baseline"] / cpu["current"],
            "steady_cpu_ms_per_step": steady,
            "steady_cpu_ratio": steady["baseline"] / steady["current"],
            # the rate with `cores` idle cores kept busy all the time (an upper bound:
            # acting and learning leave the env workers' cores idle)
            "cpu_bound_steps_per_s": {n: 1000.0 * max(cores, 1) / v for n, v in steady.items()},
        }
        entry = summary["algos"][algo]
        if algo == key["baseline"]:  # a variant (dagger-overlap, dagger-bf16) learns differently by design
            learned = [r["algos"][algo].get("learning") for rs in runs.values() for r in rs]
            entry["same_learning_as_baseline"] = all(x is not None and x == learned[0] for x in learned)
        print(
            f"{algo}: {med['baseline']:.0f} -> {med['current']:.0f} env steps/s including learning "
            f"(x{entry['ratio']:.2f}); rollout only x{entry['rollout_ratio']:.2f}; CPU per step (set-up included) "
            f"{cpu['baseline']:.2f} -> {cpu['current']:.2f} ms (x{entry['cpu_ratio']:.2f}), steady "
            f"{steady['baseline']:.2f} -> {steady['current']:.2f} ms (x{entry['steady_cpu_ratio']:.2f}, CPU-bound "
            f"{entry['cpu_bound_steps_per_s']['current']:.0f} steps/s); same losses and episodes "
            f"as the baseline: {entry.get('same_learning_as_baseline', 'n/a')}"
        )
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(Path(args.out), json.dumps(summary, indent=1))
    print(f"wrote {args.out}")


def tree_commit(tree: Path) -> str:
    """The commit a source tree is at, with "+dirty" when its code (the package, the benchmarks, the
    project file; not results or docs) has uncommitted changes. Not its path: results are read elsewhere."""
    import subprocess

    def git(*a: str) -> str:
        return subprocess.run(["git", "-C", str(tree), *a], capture_output=True, text=True).stdout.strip()

    head = git("rev-parse", "--short=12", "HEAD") or "unknown"
    changed = git(
        "status",
        "--porcelain",
        "--untracked-files=no",
        "--",
        "ovon",
        "benchmarks",
        "pyproject.toml",
        ":!benchmarks/results",
    )
    return head + ("+dirty" if changed else "")


def baseline_tree(here: Path, rev: str, tmp: Path) -> tuple[Path, bool]:
    """The baseline source tree: `rev` itself when it is a directory (an existing worktree), else a
    temporary git worktree of revision `rev` under `tmp`; returns (tree, whether it was created here)."""
    import subprocess

    if Path(rev).is_dir():
        return Path(rev).resolve(), False
    base = tmp / "baseline"
    subprocess.run(
        ["git", "-C", str(here), "worktree", "add", "--detach", str(base), rev], check=True, capture_output=True
    )
    return base, True


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--preset", default="cpu-small")
    ap.add_argument("--algos", default="bc,dagger,ppo")
    ap.add_argument("--updates", type=int, default=4)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--envs", type=int, default=0, help="override num_envs (0 = preset)")
    ap.add_argument("--houses", default="0,1")
    ap.add_argument("--expert", default="frontier", choices=["frontier", "shortest-path"])
    ap.add_argument("--text", default="hash", choices=["hash", "real"])
    ap.add_argument("--bc-episodes", type=int, default=8)
    ap.add_argument("--out", default="benchmarks/results/train_throughput.json")
    ap.add_argument(
        "--baseline-rev",
        help="git revision, or the directory of a worktree of it, to compare against "
        "(alternating runs, fresh processes)",
    )
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="config override (as `ovon train --set`), repeatable",
    )
    ap.add_argument(
        "--warmup",
        type=int,
        default=1,
        help="with --baseline-rev: one untimed 1-update run per tree "
        "first (numba compiles into a fresh worktree's cache), 0 = none",
    )
    args = ap.parse_args()
    check_algos(args)
    if args.baseline_rev:
        compare(args)
        return

    os.environ.setdefault("OMP_NUM_THREADS", "1")
    root = Path(tempfile.mkdtemp(prefix="ovon-train-bench-"))
    specs = adhoc_specs(parse_seed_list(args.houses))
    cfg = base_config(args, root)
    if args.text == "hash":
        texts = needed_texts(specs)
        write_text_table(
            root / "text.pt",
            {t: np.random.default_rng(zlib.crc32(t.encode())).standard_normal(384) for t in texts},
            cfg.encoder,
        )
    import ovon

    result = {
        "code": tree_commit(Path(ovon.__file__).resolve().parents[1]),
        "preset": args.preset,
        "num_envs": cfg.num_envs,
        "env_workers": cfg.env_workers,
        "rollout_steps": cfg.rollout_steps,
        "camera": [cfg.sim.camera.width, cfg.sim.camera.height],
        "policy": dataclasses.asdict(cfg.policy),
        "encoder": cfg.encoder.image,
        "expert": args.expert,
        "houses": args.houses,
        "set": args.set,
        "machine": {"cpus": os.cpu_count(), "platform": platform.platform()},
        "algos": {},
    }
    try:
        for algo in [a for a in args.algos.split(",") if a]:
            t = time.perf_counter()
            if algo == "bc":
                result["algos"][algo] = bench_bc(cfg, specs, root, args.bc_episodes)
            else:
                result["algos"][algo] = bench_online(algo, cfg, specs, root)
            shown = {k: v for k, v in result["algos"][algo].items() if k != "learning"}
            print(algo, json.dumps(shown), f"({time.perf_counter() - t:.0f} s)", flush=True)
    finally:
        shutil.rmtree(root, ignore_errors=True)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(Path(args.out), json.dumps(result, indent=1))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
