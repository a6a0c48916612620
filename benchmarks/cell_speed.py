"""Learned perception against the oracle where it is used: the experiment runner's own cpu-scale cells.

    .venv/bin/python benchmarks/cell_speed.py [--root DIR] [--updates 6] [--episodes 30] [--repeats 1]
        [--train-cells rl-warmup,dagger] [--out /tmp/cell_speed.json]

What runs: the `main` experiment resolved at scale `cpu` (`ovon.experiments.plan.resolve`, the plan
`ovon experiment run main --scale cpu` executes), on a small dataset of that scale's generator (4 train houses x
40 episodes, 2 val houses x 20 episodes per split: `--set data.*` overrides of the scale, generated once under
`--root`). Each command is the cell's own (`Cell.commands`, run as the runner runs it: `python -m
ovon.cli.main ...` in a child process with the runner's environment), changed only where named:

* training (`--train-cells`): the cell's command with `encoder.image` = `world-vl` (the cpu scale's) and
  = `oracle-vl`, `max_updates` = `--updates`, its own `--out`. Reported: env steps/s over the updates after the
  first (worker start and world loading left out), from the run's own `metrics.jsonl` (`steps_per_s`, which
  includes learning) and rollout-only steps/s (`time/rollout_s`).
* evaluation: the `dagger` evaluation cell on the DAgger policy this benchmark just trained with each encoder,
  and VLFM with learned perception (`vlfm`: world-owl + world-vl) against `vlfm-oracle` (oracle detection and
  value); `--episodes` episodes of val_seen, one seed. Reported: episodes/s and env steps/s of the whole command,
  and env steps per CPU second (the command and its workers, `getrusage`), which a machine busy with other work
  inflates least: read that ratio when the wall-clock ones disagree between repeats.
  Start-up is in both (about 7 s: importing torch, loading MiniLM for the goal texts, which the oracle's value
  scorer needs too), so few episodes push the ratio toward 1 or, with the learned detector's shorter episodes,
  below the steady value; the default 30 keeps it under a fifth of the time.

The two encoders alternate within each repeat, so a busy machine slows both; read the ratios
(world-vl / oracle, target >= 0.6). Writes JSON to `--out` (default: the temp folder, so a casual run leaves
the checkout as it was).
"""

from __future__ import annotations

import argparse
import json
import platform
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from ovon.atomic import atomic_write_text  # noqa: E402

TARGET = 0.6
SMALL_DATA = (
    "data.train_scenes=4",
    "data.val_scenes=2",
    "data.set.episodes_per_train_scene=40",
    "data.set.episodes_per_val_split=20",
)
ENCODERS = ("oracle-vl", "world-vl")


def with_option(argv: list[str], flag: str, value: str) -> list[str]:
    """`argv` with `flag`'s value replaced (or the flag appended)."""
    out = list(argv)
    if flag in out:
        out[out.index(flag) + 1] = value
    else:
        out += [flag, value]
    return out


def with_set(argv: list[str], key: str, value: str) -> list[str]:
    """`argv` with `--set key=...` replaced (or appended)."""
    out = list(argv)
    for i, tok in enumerate(out):
        if tok.startswith(f"{key}=") and i > 0 and out[i - 1] == "--set":
            out[i] = f"{key}={value}"
            return out
    return out + ["--set", f"{key}={value}"]


def _children_cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def run(argv: list[str], log: Path) -> tuple[float, float]:
    """One `ovon` command as the runner runs it; returns its (wall, CPU) seconds, the CPU of its worker
    processes included (refuses a failed command). CPU seconds are what a busy machine inflates least."""
    from ovon.experiments.runner import child_env

    log.parent.mkdir(parents=True, exist_ok=True)
    t0, c0 = time.perf_counter(), _children_cpu()
    with open(log, "ab") as f:
        code = subprocess.call(
            [sys.executable, "-m", "ovon.cli.main", *argv], stdout=f, stderr=subprocess.STDOUT, env=child_env()
        )
    if code != 0:
        raise SystemExit(f"`ovon {' '.join(argv)}` failed (exit {code}); its output: {log}")
    return time.perf_counter() - t0, _children_cpu() - c0


def _share(row: dict) -> float:
    return (row["time/rollout_s"] + row["time/learn_s"]) / row["time/rollout_s"]


def train_rates(folder: Path, cpu: float) -> dict:
    rows = [json.loads(line) for line in (folder / "metrics.jsonl").read_text().splitlines() if line.strip()]
    steady = rows[1:] or rows
    steps = int(rows[-1].get("step", 0)) if rows else 0
    return {
        "cpu_s": cpu,
        "steps": steps,
        "steps_per_cpu_s": steps / cpu if cpu > 0 else None,
        "steps_per_s": float(np.median([r["steps_per_s"] for r in steady])),
        # steps_per_s counts rollout + learning; the rollout alone: the same steps over its share of the time
        "rollout_steps_per_s": float(np.median([r["steps_per_s"] * _share(r) for r in steady])),
        "updates": len(rows),
    }


def eval_rates(folder: Path, wall: float, cpu: float) -> dict:
    eps = [json.loads(line) for line in (folder / "episodes.jsonl").read_text().splitlines() if line.strip()]
    steps = sum(int(e["steps"]) for e in eps)
    return {
        "episodes": len(eps),
        "steps": steps,
        "wall_s": wall,
        "cpu_s": cpu,
        "steps_per_cpu_s": steps / cpu if cpu > 0 else None,
        "episodes_per_s": len(eps) / wall,
        "steps_per_s": steps / wall,
        "sr": float(np.mean([e["success"] for e in eps])) if eps else None,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--root", default=str(Path(tempfile.gettempdir()) / "ovon_cell_speed"))
    ap.add_argument("--updates", type=int, default=6)
    ap.add_argument("--episodes", type=int, default=30)
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--train-cells", default="rl-warmup,dagger")
    ap.add_argument("--no-eval", action="store_true")
    ap.add_argument("--out", default=str(Path(tempfile.gettempdir()) / "cell_speed.json"))
    args = ap.parse_args()
    if args.updates < 2 or args.episodes < 1 or args.repeats < 1:
        raise SystemExit("--updates >= 2 (the first is left out), --episodes >= 1 and --repeats >= 1")

    from ovon.experiments.definitions import load_experiment
    from ovon.experiments.plan import resolve

    root = Path(args.root)
    plan = resolve([load_experiment("main")], "cpu", root, SMALL_DATA)
    logs = root / "bench-logs"
    data = plan.cells["data:data"]
    if not (plan.episodes_dir / "train").is_dir():
        print(f"generating the small cpu-scale dataset under {root} (once)", flush=True)
        for argv in data.commands:
            run(argv, logs / "data.log")

    train_names = [n for n in args.train_cells.split(",") if n]
    results: dict = {"train": {}, "eval": {}}
    bench = root / "bench"
    for rep in range(args.repeats):
        for enc in ENCODERS:
            for name in train_names:
                cell = plan.cells[f"train:{name}"]
                out = bench / f"r{rep}" / enc / name
                argv = with_set(cell.commands[-1], "encoder.image", enc)
                argv = with_set(argv, "max_updates", str(args.updates))
                argv = with_set(argv, "progress", "false")
                argv = with_option(argv, "--out", str(out))
                if out.exists():
                    shutil.rmtree(out)
                _, cpu = run(argv, logs / f"{name}-{enc}.log")
                results["train"].setdefault(name, {}).setdefault(enc, []).append(train_rates(out, cpu))
                print(f"train {name:10s} {enc:9s} {results['train'][name][enc][-1]}", flush=True)
            if args.no_eval:
                continue
            evals = {"policy (dagger)": "dagger", "vlfm": "vlfm" if enc == "world-vl" else "vlfm-oracle"}
            for label, cell_name in evals.items():
                cell = plan.cells[f"eval:{cell_name}"]
                out = bench / f"r{rep}" / enc / f"eval-{cell_name}"
                argv = cell.commands[-1]
                if label.startswith("policy"):
                    if "dagger" not in train_names:
                        continue
                    argv = with_option(argv, "--checkpoint", str(bench / f"r{rep}" / enc / "dagger" / "policy.pt"))
                for flag, value in (("--episodes", str(args.episodes)), ("--seeds", "0"), ("--splits", "val_seen")):
                    argv = with_option(argv, flag, value)
                argv = with_option(argv, "--out", str(out))
                if out.exists():  # an evaluation folder resumes: start it over
                    shutil.rmtree(out)
                wall, cpu = run(argv, logs / f"eval-{cell_name}-{enc}.log")
                results["eval"].setdefault(label, {}).setdefault(enc, []).append(eval_rates(out, wall, cpu))
                print(f"eval  {label:15s} {enc:9s} {results['eval'][label][enc][-1]}", flush=True)

    ratios: dict = {}
    keys = {"train": ("steps_per_s", "steps_per_cpu_s"), "eval": ("episodes_per_s", "steps_per_s", "steps_per_cpu_s")}
    for part, names in keys.items():
        for name, by_enc in results[part].items():
            if not set(ENCODERS) <= set(by_enc):
                continue
            for key in names:
                med = {e: float(np.median([r[key] for r in by_enc[e]])) for e in ENCODERS}
                ratios[f"{part}:{name}:{key}"] = med["world-vl"] / med["oracle-vl"]
    print("\nworld-vl / oracle ratios (target >= 0.6):")
    for k, v in ratios.items():
        print(f"  {k:40s} {v:.2f} {'ok' if v >= TARGET else 'BELOW TARGET'}")
    payload = {
        "benchmark": "cell_speed",
        "args": vars(args),
        "data_overrides": list(SMALL_DATA),
        "machine": {"python": platform.python_version(), "cpus": __import__("os").cpu_count()},
        "results": results,
        "ratios": ratios,
        "target": TARGET,
    }
    atomic_write_text(args.out, json.dumps(payload, indent=2))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
