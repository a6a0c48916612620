"""`ovon dataset stats`: the paper's Table 1/2-style numbers for a generated or released dataset."""

from __future__ import annotations

import math
from collections import Counter
from pathlib import Path

import numpy as np

from ovon.dataset.io import HELD_OUT_SPLITS, EpisodeDataset
from ovon.dataset.records import DatasetError
from ovon.dataset.splits import load_category_split

HIST_EDGES = (0, 2, 4, 6, 8, 10, 15, 20, 30)


def split_stats(root: str | Path, split: str) -> dict:
    ds = EpisodeDataset(root, split)
    episodes = 0
    cats: Counter = Counter()
    instances: set[tuple[str, str]] = set()
    geo: list[float] = []
    scenes_with_eps = 0
    scene_cats: Counter = Counter()
    for scene, shard in ds.iter_scenes():
        n = len(shard.episodes)
        episodes += n
        scenes_with_eps += n > 0
        for i, ep in enumerate(shard.episodes):
            cats[ep.object_category] += 1
            g = (ep.info or {}).get("geodesic_distance")
            if g is not None:
                geo.append(_distance(g, f"{ds.shard_path(scene)}: episode {str(ep.episode_id)!r} (episodes[{i}])"))
        for goals in shard.goals_by_category.values():
            for g in goals:
                instances.add((scene, g.object_id))
        for c in {ep.object_category for ep in shard.episodes}:
            scene_cats[c] += 1
    hist, _edges = np.histogram(geo, bins=HIST_EDGES) if geo else (np.zeros(len(HIST_EDGES) - 1, int), None)
    return {
        "scenes": len(ds.scenes()),
        "scenes_with_episodes": scenes_with_eps,
        "episodes": episodes,
        "categories": len(cats),
        "goal_instances": len(instances),
        "episodes_per_category": dict(sorted(cats.items(), key=lambda kv: (-kv[1], kv[0]))),
        "geodesic_distance": {
            # None (JSON null, printed "–") for a split without episodes: never NaN in a table or file
            "mean": float(np.mean(geo)) if geo else None,
            "min": float(np.min(geo)) if geo else None,
            "max": float(np.max(geo)) if geo else None,
            "histogram_edges_m": list(HIST_EDGES),
            "histogram": [int(x) for x in hist],
        },
    }


def _distance(value: object, where: str) -> float:
    """A stored geodesic distance, or one line naming the episode (a string or NaN cannot be averaged)."""
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value) or value < 0:
        raise DatasetError(
            f"{where}: info.geodesic_distance = {value!r}: expected a finite number >= 0 (metres); "
            "fix: correct or remove the episode (`ovon dataset validate` lists every problem)"
        )
    return float(value)


def dataset_stats(root: str | Path) -> dict:
    root = Path(root)
    if not root.is_dir():
        raise FileNotFoundError(f"dataset folder {root} does not exist")
    from ovon.dataset.validate import dataset_splits
    from ovon.dataset.verify import shell_only

    splits = []
    for name in dataset_splits(root):
        ds = EpisodeDataset(root, name)
        if not ds.split_dir.is_dir():
            continue  # a known split name that is not there
        trap = shell_only(ds)
        if trap is not None:  # its episodes would count 0: refused, as `ovon dataset verify` names it
            raise DatasetError(f"{trap} (`ovon dataset verify {root}` lists every problem)")
        if ds.content_dir.is_dir():
            splits.append(name)
    if not splits:
        raise FileNotFoundError(f"{root} holds no split folders (<split>/content/*.json.gz)")
    out: dict = {"splits": {s: split_stats(root, s) for s in splits}}
    cat_file = root / "categories.json"
    if cat_file.exists():
        split = load_category_split(cat_file)
        for s in HELD_OUT_SPLITS:
            rng = split.similarity_range(s)
            if rng:
                out.setdefault("category_split", {})[s] = {
                    "categories": len(split.categories(s)),
                    "similarity_min": rng[0],
                    "similarity_max": rng[1],
                }
        out.setdefault("category_split", {})["train"] = {"categories": len(split.train)}
    return out


def format_stats(stats: dict) -> str:
    lines = [
        "| split | scenes | episodes | categories | goal instances | mean geodesic (m) | geodesic histogram |",
        "|---|---|---|---|---|---|---|",
    ]
    for s, st in stats["splits"].items():
        g = st["geodesic_distance"]
        edges = g["histogram_edges_m"]
        hist = " ".join(f"{a}-{b}:{n}" for a, b, n in zip(edges, edges[1:], g["histogram"]))
        mean = "–" if g["mean"] is None else f"{g['mean']:.2f}"
        lines.append(
            f"| {s} | {st['scenes']} | {st['episodes']} | {st['categories']} | {st['goal_instances']} "
            f"| {mean} | {hist} |"
        )
    if "category_split" in stats:
        lines += ["", "| category split | categories | similarity range |", "|---|---|---|"]
        for s, v in stats["category_split"].items():
            rng = f"[{v['similarity_min']:.2f}, {v['similarity_max']:.2f}]" if "similarity_min" in v else "–"
            lines.append(f"| {s} | {v['categories']} | {rng} |")
    return "\n".join(lines)
