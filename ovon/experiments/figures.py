"""Report figures: SR per table entry beside the paper's, the failure bars in the paper's grouping, and
the training curve of each training cell from its `metrics.jsonl`. Drawn on `matplotlib.figure.Figure`
objects and saved with `savefig`: no pyplot state, the global backend is never switched."""

from __future__ import annotations

from pathlib import Path

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
    """One panel per column (split) of the table: for each row (agent) SR of ours (solid, with its std
    over seeds as the error bar) beside the paper's (hatched). Panels two to a line, so that a table of
    many rows and splits stays a page-shaped figure with a legend one can read."""
    rows, cols = table["rows"], table["columns"]
    n = max(1, len(cols))
    ncols = min(2, n)
    nrows = -(-n // ncols)
    panel_w = max(3.6, 0.75 * len(rows) + 1.4)
    fig = Figure(figsize=(panel_w * ncols, 3.4 * nrows + 0.6))
    axes = fig.subplots(nrows, ncols, squeeze=False)
    ours_color, paper_color = "#1f77b4", "#ff7f0e"
    width = 0.38
    xs = list(range(len(rows)))
    for k, ax in enumerate(axes.flat):
        if k >= len(cols):
            ax.set_visible(False)
            continue
        col = cols[k]
        ours = [r["cells"][col]["ours"] for r in rows]
        paper = [r["cells"][col]["paper"] for r in rows]
        ax.bar(
            [x - width / 2 for x in xs],
            [o["sr"][0] if o else 0 for o in ours],
            width,
            yerr=[o["sr"][1] if o else 0 for o in ours],
            capsize=3,
            color=ours_color,
            label="ours (mean ± std over seeds)",
        )
        ax.bar(
            [x + width / 2 for x in xs],
            [p["sr"] if p else 0 for p in paper],
            width,
            color="white",
            hatch="//",
            edgecolor=paper_color,
            label="paper",
        )
        for x, o, p in zip(xs, ours, paper):
            if o is None:
                ax.text(x - width / 2, 1, "not run", rotation=90, ha="center", va="bottom", fontsize=8)
            if p is None:
                ax.text(x + width / 2, 1, "n/a", rotation=90, ha="center", va="bottom", fontsize=8)
        ax.set_xticks(
            xs,
            [r["name"] for r in rows],
            rotation=30 if len(rows) > 3 else 0,
            ha="right" if len(rows) > 3 else "center",
        )
        ax.set_title(str(col), fontsize=11)
        ax.set_ylabel("SR (%)", fontsize=10)
        ax.tick_params(labelsize=9)
        ax.grid(axis="y", alpha=0.3)
        ax.set_axisbelow(True)
    handles, labels = axes.flat[0].get_legend_handles_labels()
    fig.suptitle(title, fontsize=12)
    fig.legend(handles, labels, loc="lower center", ncol=2, fontsize=10, bbox_to_anchor=(0.5, 0.0), frameon=False)
    fig.tight_layout(rect=(0, 0.07 if nrows == 1 else 0.04, 1, 0.95))
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
    ncols = min(3, len(keys))
    nrows = -(-len(keys) // ncols)
    fig = Figure(figsize=(3.8 * ncols, 3.2 * nrows))
    axes = fig.subplots(nrows, ncols, squeeze=False)
    for ax in list(axes.flat)[len(keys) :]:
        ax.set_visible(False)
    for ax, key in zip(axes.flat, keys):
        xs = [r["step"] for r in rows if key in r]
        ys = [r[key] for r in rows if key in r]
        ax.plot(xs, ys, lw=0.6, alpha=0.4, color="C0")
        k = max(1, len(ys) // 20)
        smooth = [sum(ys[max(0, i - k + 1) : i + 1]) / len(ys[max(0, i - k + 1) : i + 1]) for i in range(len(ys))]
        ax.plot(xs, smooth, lw=1.4, color="C0")
        ax.set_title(key, fontsize=11)
        ax.set_xlabel("env steps", fontsize=10)
        # 300k-step runs in 3.8-inch panels: plain tick labels (100000150000...) run into each other
        ax.xaxis.set_major_locator(MaxNLocator(4))
        ax.xaxis.set_major_formatter(EngFormatter(sep=""))
        ax.tick_params(labelsize=10)
    fig.suptitle(f"training: {name}", fontsize=12, y=1.02)
    fig.tight_layout()
    return _save(fig, out)
