"""`ovon perception evaluate`: the world-owl detector and the world-vl embeddings on the val splits' held-out
houses, beside ORACLE DETECTION on the same (frame, goal) pairs.

Why frame level: an agent's success hides where perception fails; here every frame of a val house is asked
"is <goal> in view?" for each goal category of the split in that house, and the answer is checked against
the semantic frame: a pair is positive when the goal covers at least `visible_share` of the frame (the
share the threshold was calibrated at), strictly (the name's own instances) or synonym-tolerant (any name
with the same look, `ovon.scenes.procedural.looks.look_key`).

Per split: precision and recall at the calibrated threshold, AP, the most frequent confusions, and
image-text retrieval (the global embedding's top-1 among the split's goal names in the house). Beside it,
the oracle detector (`ovon.models.detectors.oracle.OracleDetector`, the real class, presets "perfect" and
"noisy") on the same pairs. Its semantic frame is rebuilt from the cached frames' instance rows: each
visible instance gets its exact pixel count (placed in a block, not its real shape). The oracle's decision
reads only pixel counts, so decisions and scores are those of the real detector; only its boxes differ,
and they are not used here.

Frames are rendered once per house and seed (`ovon.perception.frames`, cached under `<out>/frames/`, so an
interrupted run resumes); the same inputs and seed give the same report.
"""

from __future__ import annotations

import hashlib
import math
import re
import warnings
import zlib
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import torch

from ovon.atomic import atomic_write_text, atomic_write_with, write_json
from ovon.parallel import progress_bar
from ovon.perception.calibrate import average_precision, pr_at, pr_curve
from ovon.perception.frames import HouseFrames, render_house

ORACLE_PRESETS = {"oracle": "perfect", "oracle-noisy": "noisy"}
MAX_CONFUSIONS = 10


@dataclass
class SplitHouses:
    """The held-out houses of one val split and the goal categories its episodes ask for in each."""

    split: str
    scenes: dict[str, str] = field(default_factory=dict)  # scene id -> resolved scene path
    goals: dict[str, list[str]] = field(default_factory=dict)  # scene id -> sorted goal categories


def read_splits(data: str, scenes: str, houses: int | None = None) -> list[SplitHouses]:
    """Each val split's scenes (the first `houses` by scene id) and goals, read as `ovon evaluate` reads a
    split (`ovon.dataset.episodes.load_split`: invalid episodes skipped with a counted warning). A missing
    split folder is skipped with a warning; no split at all is an error."""
    from ovon.dataset.episodes import load_split
    from ovon.dataset.io import VAL_SPLITS, resolve_split_dir
    from ovon.dataset.validate import warn_skipped

    out: list[SplitHouses] = []
    missing: list[str] = []
    for split in VAL_SPLITS:
        try:
            resolve_split_dir(data, split)
        except FileNotFoundError:
            missing.append(split)
            continue
        sel = load_split(data, scenes, split, None)
        warn_skipped(f"{Path(data) / split}", sel.skipped, sel.picked)
        sh = SplitHouses(split)
        goals: dict[str, set[str]] = {}
        for spec in sel.specs:
            sh.scenes.setdefault(spec.scene_key, spec.scene)
            goals.setdefault(spec.scene_key, set()).add(spec.goal_category)
        keep = sorted(sh.scenes)[:houses] if houses else sorted(sh.scenes)
        sh.scenes = {k: sh.scenes[k] for k in keep}
        sh.goals = {k: sorted(goals[k]) for k in keep}
        out.append(sh)
    if not out:
        root = Path(data)
        present = sorted(p.name for p in root.iterdir() if p.is_dir() and not p.name.startswith("."))
        raise FileNotFoundError(
            f"--data {data}: no val split folder ({', '.join(f'{s}/' for s in VAL_SPLITS)}); folders there: "
            f"{present}; fix: point --data at the episode dataset root (written by `ovon dataset generate`, or "
            "the released HM3D-OVON files)"
        )
    if missing:
        warnings.warn(f"--data {data}: no {', '.join(missing)} folder; evaluating the others", stacklevel=2)
    return out


def names_for(splits: list[SplitHouses]) -> list[str]:
    """The label space of the frames: the vocabulary, plus any goal name outside it (HM3D raw names)."""
    from ovon.scenes.vocabulary import load_vocabulary

    names = list(load_vocabulary().names)
    known = set(names)
    extra = sorted({g for s in splits for gs in s.goals.values() for g in gs} - known)
    return names + extra


def cache_path(out: Path, scene_key: str, seed: int, n: int, names: list[str]) -> Path:
    """One file per house, seed, frame count and label space (category indices refer to `names`)."""
    safe = re.sub(r"[^A-Za-z0-9_.-]+", "_", scene_key).strip("_.") or "scene"
    tag = hashlib.sha256("\n".join(names).encode()).hexdigest()[:8]
    return out / "frames" / f"{safe}-s{seed}-n{n}-{tag}.npz"


def render_all(
    scenes: dict[str, str], out: Path, n: int, seed: int, names: list[str], progress: bool = True
) -> dict[str, Path]:
    """Render (or reuse) every house's frames."""
    paths = {k: cache_path(out, k, seed, n, names) for k in sorted(scenes)}
    todo = [k for k, p in paths.items() if not p.exists()]
    (out / "frames").mkdir(parents=True, exist_ok=True)
    with progress_bar("rendering val frames", len(todo), progress and bool(todo)) as bar:
        for k in todo:
            render_house(scenes[k], n, seed, names).save(paths[k])
            bar.advance()
    return paths


# ----------------------------------------------------------------------------------------------------
# per house: scores, labels, oracle decisions


def labels_for(frames: HouseFrames, names: list[str], goals: list[str], share: float) -> tuple[np.ndarray, np.ndarray]:
    """(N, K) strict and synonym-tolerant labels: the goal (or a name of its look) covers >= share."""
    from ovon.scenes.procedural.looks import look_key

    n = len(frames.rgb)
    strict = np.zeros((n, len(goals)), dtype=bool)
    syn = np.zeros((n, len(goals)), dtype=bool)
    goal_col = {g: j for j, g in enumerate(goals)}
    goal_look = np.array([look_key(g) for g in goals], dtype=object)
    for f, c, s in frames.inst[:, :3]:
        if s < share:
            continue
        name = names[int(c)]
        j = goal_col.get(name)
        if j is not None:
            strict[int(f), j] = True
        syn[int(f)] |= goal_look == look_key(name)
    return strict, syn


@torch.inference_mode()
def world_scores(model, frames: HouseFrames, text: torch.Tensor, batch: int = 64) -> tuple[np.ndarray, np.ndarray]:
    """(N, K) world-owl frame scores (the calibrated pooling of cell probabilities, what
    `WorldOWLDetector.detect` compares to its threshold) and world-vl global probabilities."""
    det, glob = [], []
    for i in range(0, len(frames.rgb), batch):
        top, _, g = model.features(frames.rgb[i : i + batch])
        det.append(model.frame_score(model.probs(top, text)).numpy())
        glob.append(model.global_probs(g, text).numpy())
    return np.concatenate(det).astype(np.float64), np.concatenate(glob).astype(np.float64)


def _semantic_frames(frames: HouseFrames) -> list[np.ndarray]:
    """Per frame an (H, W) instance-id image with each visible instance's exact pixel count (see the
    module docstring: the oracle reads counts only)."""
    n, H, W = frames.rgb.shape[:3]
    sems = [np.zeros(H * W, dtype=np.int64) for _ in range(n)]
    fill = [0] * n
    for row in frames.inst[np.lexsort((frames.inst[:, 7], frames.inst[:, 0]))]:
        f, iid = int(row[0]), int(row[7])
        cnt = int(round(float(row[2]) * H * W))
        sems[f][fill[f] : fill[f] + cnt] = iid
        fill[f] += cnt
    return [s.reshape(H, W) for s in sems]


def oracle_scores(
    frames: HouseFrames, names: list[str], goals: list[str], preset: str, text_encoder, seed: int
) -> tuple[np.ndarray, np.ndarray]:
    """(N, K) decisions and scores (best detection score, 0 without one) of the real oracle detector.
    Its generator is re-seeded per (house, goal) as it is per episode, so a pair's draw does not depend on
    which split asks or in which order."""
    from ovon.models.config import detector_preset
    from ovon.models.detectors.oracle import OracleDetector

    det = OracleDetector(detector_preset(preset), text_encoder=text_encoder)
    objects = {int(r[7]): names[int(r[1])] for r in frames.inst}
    world = SimpleNamespace(
        key=f"perception:{frames.scene_id}",
        scene=SimpleNamespace(objects=[SimpleNamespace(id=i, category=c) for i, c in sorted(objects.items())]),
    )
    sems = _semantic_frames(frames)
    dec = np.zeros((len(sems), len(goals)), dtype=bool)
    score = np.zeros((len(sems), len(goals)), dtype=np.float64)
    for j, goal in enumerate(goals):
        det.reset(zlib.crc32(f"{seed}|{frames.scene_id}|{goal}".encode()))
        goal_ids = {i for i, c in objects.items() if c == goal}
        for f, sem in enumerate(sems):
            p = SimpleNamespace(world=world, frame=SimpleNamespace(semantic=sem), goal_ids=goal_ids)
            found = det.detect({"privileged": p}, goal)
            if found:
                dec[f, j] = True
                score[f, j] = max(d.score for d in found)
    return dec, score


def _in_view(inst: np.ndarray, names: list[str], frame: int, goal: str, share: float) -> str:
    """What was in view when the goal was wrongly detected: the goal itself under the visible share, else
    the largest visible category, else nothing."""
    rows = inst[inst[:, 0] == frame]
    cats = [names[int(c)] for c in rows[np.argsort(-rows[:, 2], kind="stable"), 1]]
    if goal in cats:
        return f"{goal} (< {share:.0%} of the frame)"
    return cats[0] if cats else "(no object)"


# ----------------------------------------------------------------------------------------------------
# the evaluation


def _num(x: float) -> float | None:
    return None if x is None or (isinstance(x, float) and math.isnan(x)) else round(float(x), 4)


def _detector_row(pred: np.ndarray, score: np.ndarray, strict: np.ndarray, syn: np.ndarray) -> dict:
    row = {}
    for kind, lab in (("strict", strict), ("synonym", syn)):
        p, r = pr_at(pred.astype(np.float64), lab, 0.5)
        row[kind] = {"precision": _num(p), "recall": _num(r), "ap": _num(average_precision(score, lab)),
                     "positives": int(lab.sum())}  # fmt: skip
    row["detections"] = int(pred.sum())
    return row


def evaluate(
    data: str,
    scenes: str,
    out: str | Path,
    checkpoint: str | None = None,
    frames_per_house: int = 200,
    houses: int | None = None,
    seed: int = 0,
    progress: bool = True,
) -> dict:
    """Evaluate; write `perception.json`, `perception.md` and `pr.png` under `out`; return the report."""
    from ovon.models.encoders.text import MiniLMText
    from ovon.models.world import load_world_vl
    from ovon.perception.config import PretrainConfig
    from ovon.scenes.procedural.looks import look_key

    model = load_world_vl(checkpoint)  # first: a wrong path is refused before any rendering
    cal = model.meta.get("calibration", {})
    share = float(cal.get("visible_share", PretrainConfig().visible_share))
    splits = read_splits(data, scenes, houses)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    names = names_for(splits)
    known = set(names)
    all_scenes = {k: v for s in splits for k, v in s.scenes.items()}
    paths = render_all(all_scenes, out, frames_per_house, seed, names, progress)
    text_encoder = MiniLMText()

    # per house: the union of its goals over the splits, scored once
    per_house: dict[str, dict] = {}
    with progress_bar("scoring val frames", len(paths), progress) as bar:
        for key in sorted(paths):
            frames = HouseFrames.load(paths[key])
            goals = sorted({g for s in splits for g in s.goals.get(key, [])})
            text = torch.nn.functional.normalize(text_encoder.encode(goals).float(), dim=-1)
            det, glob = world_scores(model, frames, text)
            strict, syn = labels_for(frames, names, goals, share)
            h = {"inst": frames.inst, "n": len(frames.rgb), "goals": goals, "world": det, "global": glob}
            h["strict"], h["syn"] = strict, syn
            for name, preset in ORACLE_PRESETS.items():
                h[name] = oracle_scores(frames, names, goals, preset, text_encoder, seed)
            per_house[key] = h  # without the images: a few MB per house
            bar.advance()

    report = {
        "checkpoint": model.source,
        "pooling": model.pooling,
        "threshold": model.threshold,
        "visible_share": share,
        "seed": seed,
        "frames_per_house": frames_per_house,
        "houses_per_split": houses,
        "oracle_presets": dict(ORACLE_PRESETS),
        "splits": {},
    }
    curves = {}
    for sh in splits:
        cols = {k: [] for k in ("world", "strict", "syn", *ORACLE_PRESETS)}
        oracle_s = {k: [] for k in ORACLE_PRESETS}
        confusions: Counter = Counter()
        small_goal = 0
        ret = {"strict": [0, 0], "synonym": [0, 0], "chance": []}
        for key in sorted(sh.scenes):
            h = per_house[key]
            idx = [h["goals"].index(g) for g in sh.goals[key]]
            world, strict, syn = h["world"][:, idx], h["strict"][:, idx], h["syn"][:, idx]
            cols["world"].append(world.ravel())
            cols["strict"].append(strict.ravel())
            cols["syn"].append(syn.ravel())
            for name in ORACLE_PRESETS:
                cols[name].append(h[name][0][:, idx].ravel())
                oracle_s[name].append(h[name][1][:, idx].ravel())
            for f, j in zip(*np.nonzero((world >= model.threshold) & ~strict)):
                goal = sh.goals[key][j]
                seen = _in_view(h["inst"], names, int(f), goal, share)
                small_goal += seen.startswith(f"{goal} (")
                confusions[(goal, seen)] += 1
            if len(idx) >= 2:  # retrieval among one name is not a choice
                glob = h["global"][:, idx]
                top = np.argmax(glob, axis=1)
                for kind, lab in (("strict", strict), ("synonym", syn)):
                    has = lab.any(axis=1)
                    ret[kind][0] += int(lab[np.arange(len(top)), top][has].sum())
                    ret[kind][1] += int(has.sum())
                has = strict.any(axis=1)
                ret["chance"] += (strict[has].sum(axis=1) / len(idx)).tolist()
        cat = {k: np.concatenate(v) if v else np.zeros(0) for k, v in cols.items()}
        strict, syn = cat["strict"].astype(bool), cat["syn"].astype(bool)
        world_pred = cat["world"] >= model.threshold
        dets = {"world-owl": _detector_row(world_pred, cat["world"], strict, syn)}
        for name in ORACLE_PRESETS:
            o_score = np.concatenate(oracle_s[name]) if oracle_s[name] else np.zeros(0)
            dets[name] = _detector_row(cat[name].astype(bool), o_score, strict, syn)
            curves.setdefault(sh.split, {})[name] = pr_at(cat[name].astype(np.float64), strict, 0.5)
        curves.setdefault(sh.split, {})["world-owl"] = (
            pr_curve(cat["world"], strict),
            pr_curve(cat["world"], syn),
            pr_at(cat["world"], strict, model.threshold),
        )
        fp = int((world_pred & ~strict).sum())
        rows = sorted(confusions.items(), key=lambda kv: (-kv[1], kv[0]))[:MAX_CONFUSIONS]
        report["splits"][sh.split] = {
            "houses": sorted(sh.scenes),
            "goals": {k: sh.goals[k] for k in sorted(sh.scenes)},
            "frames": int(sum(per_house[k]["n"] for k in sh.scenes)),
            "pairs": int(strict.size),
            "detectors": dets,
            "retrieval": {
                "frames": ret["strict"][1],
                "top1_strict": _num(ret["strict"][0] / ret["strict"][1]) if ret["strict"][1] else None,
                "top1_synonym": _num(ret["synonym"][0] / ret["synonym"][1]) if ret["synonym"][1] else None,
                "chance": _num(float(np.mean(ret["chance"]))) if ret["chance"] else None,
            },
            "false_positives": fp,
            "false_positives_goal_under_share": small_goal,
            "confusions": [
                {"goal": g, "in_view": v, "count": n, "same_look": look_key(g) == look_key(v) if v in known else None}
                for (g, v), n in rows
            ],
        }
    write_json(out / "perception.json", report)
    atomic_write_text(out / "perception.md", markdown(report))
    plot_pr(curves, out / "pr.png")
    return report


# ----------------------------------------------------------------------------------------------------
# reports


def _fmt(x) -> str:
    return "-" if x is None else f"{x:.3f}"


def markdown(report: dict) -> str:
    share = report["visible_share"]
    lines = [
        "# Perception on the val splits (frame level)",
        "",
        f"world-owl: weights `{report['checkpoint']}`, pooling {report['pooling']}, calibrated threshold "
        f"{report['threshold']:.4g}. A (frame, goal) pair is positive when the goal covers >= {share:.0%} of "
        "the frame; strict: the goal's own instances; synonym: any name with the same look.",
        "",
        "**Rows named `oracle` are ORACLE DETECTION** (privileged: they read the semantic frame; presets "
        + ", ".join(f"`{k}` = {v}" for k, v in report["oracle_presets"].items())
        + f"). The oracle fires from its own minimum share (1-2%), so goals seen under {share:.0%} count "
        "as its false positives here.",
        "",
        "| split | detector | pairs | positives | P strict | R strict | AP strict | P synonym | R synonym | "
        "AP synonym |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for split, s in report["splits"].items():
        for name, d in s["detectors"].items():
            a, b = d["strict"], d["synonym"]
            lines.append(
                f"| {split} | {name} | {s['pairs']} | {a['positives']} | {_fmt(a['precision'])} | "
                f"{_fmt(a['recall'])} | {_fmt(a['ap'])} | {_fmt(b['precision'])} | {_fmt(b['recall'])} | "
                f"{_fmt(b['ap'])} |"
            )
    lines += [
        "",
        "## Image-text retrieval (world-vl global embedding vs MiniLM text)",
        "",
        "Top-1 among the split's goal names in the house, over frames where one of them is visible (houses "
        "with at least two goal names).",
        "",
        "| split | frames | top-1 strict | top-1 synonym | chance |",
        "|---|---:|---:|---:|---:|",
    ]
    for split, s in report["splits"].items():
        r = s["retrieval"]
        lines.append(
            f"| {split} | {r['frames']} | {_fmt(r['top1_strict'])} | {_fmt(r['top1_synonym'])} | {_fmt(r['chance'])} |"
        )
    lines += ["", f"## world-owl's most frequent confusions (strict false positives, top {MAX_CONFUSIONS})", ""]
    for split, s in report["splits"].items():
        lines += [
            f"### {split}: {s['false_positives']} false positives ({s['false_positives_goal_under_share']} with the "
            f"goal in view under {share:.0%})",
            "",
            "| goal | in view (largest) | frames | same look |",
            "|---|---|---:|---|",
        ]
        lines += [f"| {c['goal']} | {c['in_view']} | {c['count']} | {'yes' if c['same_look'] else ''} |"
                  for c in s["confusions"]] or ["| - | - | 0 | |"]  # fmt: skip
        lines.append("")
    return "\n".join(lines)


def plot_pr(curves: dict, path: Path) -> None:
    """Precision-recall per split: world-owl strict and synonym, its calibrated operating point, the oracles."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = max(1, len(curves))
    fig, axes = plt.subplots(1, n, figsize=(4 * n, 3.8), squeeze=False)
    for ax, (split, c) in zip(axes[0], curves.items()):
        (ps, rs), (py, ry), (p0, r0) = c["world-owl"]
        ax.plot(rs, ps, label="world-owl strict")
        ax.plot(ry, py, "--", label="world-owl synonym")
        if not (math.isnan(p0) or math.isnan(r0)):
            ax.plot([r0], [p0], "o", label="world-owl threshold")
        for name, marker in zip(ORACLE_PRESETS, ("s", "^")):
            p, r = c[name]
            if not (math.isnan(p) or math.isnan(r)):
                ax.plot([r], [p], marker, label=f"{name} (ORACLE DETECTION)")
        ax.set(title=split, xlabel="recall", ylabel="precision", xlim=(0, 1.02), ylim=(0, 1.02))
        ax.legend(fontsize=7)
    fig.tight_layout()
    atomic_write_with(path, lambda fh: fig.savefig(fh, format="png", dpi=100))
    plt.close(fig)


__all__ = ["evaluate", "labels_for", "markdown", "oracle_scores", "read_splits", "world_scores"]
