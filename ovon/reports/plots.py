"""Figures: failure breakdown per split (the paper's figure), SR vs geodesic distance, SR per category, and
training curves (SR vs env steps from `metrics.jsonl`).

Drawn on `matplotlib.figure.Figure` objects and saved with `savefig`: no pyplot state, and the global
backend is never switched (importing this in a notebook leaves its backend as it was)."""

from __future__ import annotations

from pathlib import Path

from matplotlib.figure import Figure

from ovon.dataset.io import VAL_SPLITS
from ovon.reports.compare import DISTANCE_BINS, distance_bin, failure_breakdown, sr_by
from ovon.task.tracker import FAILURE_LABELS

# The paper's colours: timeouts orange family (ignored goal pink, missed goal brown), wrong object yellow,
# entered-and-left purple.
FAILURE_COLORS = {
    "timeout_missed_goal": "#8c564b",
    "timeout_ignored_goal": "#e377c2",
    "timeout_left_goal": "#ff7f0e",
    "stop_wrong_object": "#f2c80f",
    "stop_too_far": "#7f7f7f",
    "stop_left_goal": "#9467bd",
    "stop_never_saw_goal": "#c49c94",
}


def _ordered(splits):
    return [s for s in VAL_SPLITS if s in splits] + sorted(set(splits) - set(VAL_SPLITS))


def plot_failures(name: str, records: list[dict], out: Path) -> Path:
    fb = failure_breakdown(records)
    splits = _ordered(fb)
    fig = Figure(figsize=(3.6 + 1.6 * len(splits), 4.2))
    ax = fig.subplots()
    bottoms = [0.0] * len(splits)
    for label in FAILURE_LABELS:
        vals = [100 * fb[s][label] for s in splits]
        ax.bar(splits, vals, bottom=bottoms, color=FAILURE_COLORS[label], label=label.replace("_", " "))
        bottoms = [b + v for b, v in zip(bottoms, vals)]
    for i, s in enumerate(splits):
        timeout = 100 * sum(fb[s][lbl] for lbl in FAILURE_LABELS if lbl.startswith("timeout"))
        ax.text(i, bottoms[i] + 1, f"timeout {timeout:.1f}%", ha="center", fontsize=8, color="#ff7f0e")
    ax.set_ylabel("% of episodes (failures)")
    ax.set_title(f"Failure modes: {name}")
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.0, 1.0))
    fig.savefig(out, dpi=120, bbox_inches="tight")
    return out


def distinct_colors(n: int) -> list:
    """n colours no two alike: the tab10 / tab20 palettes while they last, then evenly spaced hues (the
    default colour cycle repeats after 10, and a legend of 12 lines would name two lines by one colour)."""
    import matplotlib

    if n <= 10:
        return list(matplotlib.colormaps["tab10"].colors[:n])
    if n <= 20:
        return list(matplotlib.colormaps["tab20"].colors[:n])
    cmap = matplotlib.colormaps["turbo"]
    return [cmap(i / (n - 1)) for i in range(n)]


MARKERS = ("o", "s", "^", "D", "v", "P", "X", "*")


def plot_sr_vs_distance(runs: list[tuple[str, list[dict]]], out: Path) -> Path:
    labels = [distance_bin(lo) for lo in DISTANCE_BINS[:-1]]
    lines = []
    for name, recs in runs:
        table = sr_by(recs, lambda r: distance_bin(float(r["geodesic_distance"])))
        for k, split in enumerate(_ordered(table)):
            ys = [100 * table[split][lbl][0] if lbl in table[split] else float("nan") for lbl in labels]
            lines.append((f"{name} / {split}", ys, MARKERS[k % len(MARKERS)]))
    fig = Figure(figsize=(7, 4))
    ax = fig.subplots()
    for (label, ys, marker), color in zip(lines, distinct_colors(len(lines))):
        ax.plot(labels, ys, marker=marker, color=color, label=label)
    ax.set_xlabel("geodesic distance start -> goal")
    ax.set_ylabel("SR (%)")
    ax.set_ylim(-2, 102)
    ax.tick_params(axis="x", labelrotation=30)
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0)
    fig.savefig(out, dpi=120, bbox_inches="tight")
    return out


def plot_sr_per_category(name: str, records: list[dict], out: Path, top: int = 40) -> Path:
    table = sr_by(records, lambda r: r["category"])
    splits = _ordered(table)
    fig = Figure(figsize=(10, 2.8 * len(splits)))
    axes = fig.subplots(len(splits), 1, squeeze=False)
    for ax, split in zip(axes[:, 0], splits):
        items = sorted(table[split].items(), key=lambda kv: (-kv[1][1], kv[0]))[:top]
        ax.bar([k for k, _ in items], [100 * v[0] for _, v in items], color="#1f77b4")
        ax.set_title(f"{name} / {split}: SR per category (most frequent {len(items)})", fontsize=9)
        ax.set_ylim(0, 100)
        ax.tick_params(axis="x", labelrotation=70, labelsize=7)
    fig.savefig(out, dpi=110, bbox_inches="tight")
    return out


def learning_curve(rows: list[dict], metric: str = "episode/success", window: int = 10) -> tuple[list, list]:
    """(env steps, metric) from `metrics.jsonl` rows: each point the episode-weighted mean of `metric` over
    the last `window` logged updates (an update ends ~10 episodes, so one update's SR is noise)."""
    steps, values = [], []
    for i, r in enumerate(rows):
        part = [x for x in rows[max(0, i - window + 1) : i + 1] if x.get(metric) is not None]
        weight = [float(x.get("episode/count", 1.0)) if metric.startswith("episode/") else 1.0 for x in part]
        if sum(weight) > 0:
            steps.append(r["step"])
            values.append(sum(w * float(x[metric]) for w, x in zip(weight, part)) / sum(weight))
    return steps, values


def plot_learning_curves(
    runs: list[str | Path], out: str | Path, metric: str = "episode/success", window: int = 10
) -> Path:
    """`metric` vs env steps for training run folders (their `metrics.jsonl`), one line per run. `out`
    (a PNG) is checked before the runs are read."""
    from ovon.atomic import atomic_write_with, check_output_path
    from ovon.train.logging import read_metrics

    check_output_path(out, "--out", expected="the path of a .png file", example="curve.png", suffixes=(".png",))

    fig = Figure(figsize=(6.4, 3.6))
    ax = fig.add_subplot()
    for run in runs:
        rows = read_metrics(run)
        if not rows:
            raise FileNotFoundError(f"{run}: no metrics.jsonl; fix: pass a run folder written by `ovon train`")
        # an episode metric may be absent only because no episode has ended yet (an empty line)
        if not metric.startswith("episode/") and not any(r.get(metric) is not None for r in rows):
            keys = sorted({k for r in rows for k in r} - {"update", "step", "time"})
            raise ValueError(f"--metric {metric!r} is not logged in {run}/metrics.jsonl; fix: one of {keys}")
        steps, values = learning_curve(rows, metric, window)
        scale = 100.0 if metric in ("episode/success", "episode/spl", "episode/soft_spl") else 1.0  # as %
        ax.plot(steps, [scale * v for v in values], label=Path(run).name)
    ax.set_xlabel("environment steps")
    pct = metric in ("episode/success", "episode/spl", "episode/soft_spl")
    ax.set_ylabel(f"{metric.split('/')[-1]}{' (%)' if pct else ''}")
    ax.set_title(f"training episodes, mean of the last {window} updates", fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_with(out, lambda f: fig.savefig(f, format="png", dpi=120))
    return out
