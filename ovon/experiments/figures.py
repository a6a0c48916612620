"""Report figures: SR per table entry beside the paper's, the failure bars in the paper's grouping, and
the training curve of each training cell from its `metrics.jsonl`. Drawn on `matplotlib.figure.Figure`
objects and saved with `savefig`: no pyplot state, the global backend is never switched."""

from __future__ import annotations

from pathlib import Path

import matplotlib
from matplotlib.figure import Figure
from matplotlib.ticker import EngFormatter, MaxNLocator

# Curves worth a panel: imitation (BC, DAgger) and PPO runs log different scalars.
IL_KEYS = ("episode/success", "episode/spl", "loss", "accuracy", "beta")
RL_KEYS = ("episode/success", "episode/spl", "reward/mean", "value_loss", "entropy", "lr/actor")


def _save(fig, out: Path) -> Path:
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=100, bbox_inches="tight")
    return out


def table_figure(title: str, table: dict, out: Path) -> Path:
    """Grouped bars: per row, SR of each column (ours solid with the std, the paper's hatched)."""
    rows, cols = table["rows"], table["columns"]
    n = len(cols)
    width = 0.8 / (2 * n)
    fig = Figure(figsize=(max(5.0, 1.4 * len(rows) * n / 2 + 2), 3.6))
    ax = fig.subplots()
    colors = matplotlib.rcParams["axes.prop_cycle"].by_key()["color"]
    for j, col in enumerate(cols):
        xs_ours = [i + (2 * j - n + 0.5) * width for i in range(len(rows))]
        ours = [r["cells"][col]["ours"] for r in rows]
        paper = [r["cells"][col]["paper"] for r in rows]
        ax.bar(
            xs_ours,
            [o["sr"][0] if o else 0 for o in ours],
            width,
            yerr=[o["sr"][1] if o else 0 for o in ours],
            color=colors[j % len(colors)],
            label=f"{col} (ours)",
        )
        for x, o in zip(xs_ours, ours):
            if o is None:
                ax.text(x, 0.5, "not run", rotation=90, ha="center", va="bottom", fontsize=7)
        ax.bar(
            [x + width for x in xs_ours],
            [p["sr"] if p else 0 for p in paper],
            width,
            fill=False,
            hatch="//",
            edgecolor=colors[j % len(colors)],
            label=f"{col} (paper)",
        )
    ax.set_xticks(range(len(rows)), [r["name"] for r in rows])
    ax.set_ylabel("SR (%)")
    ax.set_title(title, fontsize=10)
    ax.legend(fontsize=7, ncol=max(1, n), loc="upper left")
    return _save(fig, out)


def failure_figure(fig_data: dict, out: Path) -> Path:
    """Bars per failure group and split (ours), the paper's values as black diamonds, its ranges as
    grey bands."""
    groups, splits = fig_data["groups"], fig_data["splits"]
    n = len(splits)
    width = 0.8 / n
    fig = Figure(figsize=(2 + 1.3 * len(groups), 3.8))
    ax = fig.subplots()
    for j, split in enumerate(splits):
        xs = [i + (j - (n - 1) / 2) * width for i in range(len(groups))]
        vals = [g["ours"].get(split, 0.0) if g["ours"] else 0.0 for g in groups]
        ax.bar(
            xs,
            vals,
            width,
            color=[g["color"] for g in groups],
            alpha=0.45 + 0.55 * (j + 1) / n,
            edgecolor="black",
            linewidth=0.5,
        )
        for x, g in zip(xs, groups):
            if g["paper"]:
                ax.plot([x], [g["paper"][split]], marker="D", color="black", markersize=4)
    for i, g in enumerate(groups):
        if g["paper_range"]:
            ax.fill_between([i - 0.4, i + 0.4], *g["paper_range"], color="grey", alpha=0.2, linewidth=0)
    from matplotlib.patches import Patch

    handles = [
        Patch(facecolor="grey", alpha=0.45 + 0.55 * (j + 1) / n, edgecolor="black", label=s)
        for j, s in enumerate(splits)
    ]
    ax.set_xticks(range(len(groups)), [g["name"] for g in groups], rotation=20, fontsize=8)
    ax.set_ylabel("% of episodes")
    status = "" if fig_data["groups"] and fig_data["groups"][0]["ours"] else " (not run)"
    ax.set_title(
        f"{fig_data['caption']}{status}\nbars: ours per split (light to dark); diamonds / grey band: paper", fontsize=9
    )
    ax.legend(handles=handles, fontsize=7)
    return _save(fig, out)


def training_curve(name: str, folder: Path, out: Path) -> Path | None:
    """Panels of the run's logged scalars against environment steps (raw and a moving average); None
    without a log."""
    from ovon.train.logging import read_metrics

    rows = read_metrics(folder)
    if not rows:
        return None
    wanted = RL_KEYS if any("value_loss" in r for r in rows) else IL_KEYS
    keys = [k for k in wanted if any(k in r for r in rows)]
    if not keys:
        return None
    fig = Figure(figsize=(3.0 * len(keys), 2.8))
    axes = fig.subplots(1, len(keys), squeeze=False)
    for ax, key in zip(axes[0], keys):
        xs = [r["step"] for r in rows if key in r]
        ys = [r[key] for r in rows if key in r]
        ax.plot(xs, ys, lw=0.6, alpha=0.4, color="C0")
        k = max(1, len(ys) // 20)
        smooth = [sum(ys[max(0, i - k + 1) : i + 1]) / len(ys[max(0, i - k + 1) : i + 1]) for i in range(len(ys))]
        ax.plot(xs, smooth, lw=1.4, color="C0")
        ax.set_title(key, fontsize=9)
        ax.set_xlabel("env steps", fontsize=8)
        # 300k-step runs in 3-inch panels: plain tick labels (100000150000...) run into each other
        ax.xaxis.set_major_locator(MaxNLocator(4))
        ax.xaxis.set_major_formatter(EngFormatter(sep=""))
        ax.tick_params(labelsize=7)
    fig.suptitle(f"training: {name}", fontsize=10, y=1.02)
    fig.tight_layout()
    return _save(fig, out)
