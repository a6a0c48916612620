"""`ovon dataset generate`: goal objects, viewpoints and starts for every scene of a scene dataset,
written as HM3D-OVON splits (train, val_seen, val_seen_synonyms, val_unseen).

Pipeline (one job per scene, in worker processes or Ray tasks):
1. categories present in the scenes (semantic.txt labels through the cleaning table) -> category split
   (`categories.json`, SentenceBERT similarity; reused when it already exists in the output);
2. per scene: navigability, then every candidate object's viewpoints rendered with the generation rig;
   the goals are cached (`.cache/goals/<scene>.json.gz`) so val allocation can see all val scenes;
3. per scene and split: episodes allocated (train: uniform over the scene's categories; val: each
   split's budget spread over (scene, category) pairs, i.e. over categories in proportion to how many
   scenes contain them), starts sampled, the shard written atomically.
A re-run skips every file already written; the same seed gives byte-identical shards.
A scene that yields no episode (no navigable floor, no goal object, no start) is named with its reason:
a warning counted in `generation_report.json` when other scenes yield, an error when none does.
"""

from __future__ import annotations

import gzip
import json
import shutil
import time
import warnings
import zlib
from collections import Counter
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from ovon.atomic import atomic_write_text, write_json_gz
from ovon.config.base import from_dict, to_dict
from ovon.config.dataset import GenerationConfig
from ovon.config.sim import AgentConfig, CameraConfig, NavConfig
from ovon.dataset.generation_folder import EmptyGenerationError, generation_run_folder
from ovon.dataset.io import SPLITS, shard_exists, write_scene_shard, write_split_shell
from ovon.dataset.records import Episode, ObjectGoal, ViewPoint, goal_key
from ovon.geometry import quat_to_yaw, yaw_to_quat


@dataclass
class SceneRef:
    folder: str  # scene folder on disk
    stem: str  # file stem = shard name, e.g. "TEEsavR23oF"
    scene_id: str  # episode scene_id: <dataset>/<split>/<NNNNN-id>/<stem>.glb
    kind: str  # "train" | "val" (scene split)


def discover_scenes(scenes_dir: str | Path) -> list[SceneRef]:
    from ovon.scenes.hm3dsem import find_scene_files, list_scenes

    root = Path(scenes_dir)
    refs = []
    for kind in ("train", "val"):
        if not (root / kind).is_dir():
            continue
        for folder in list_scenes(root, kind):
            files = find_scene_files(folder)
            rel = f"{root.name}/{kind}/{folder.name}/{files['visual'].name}"
            refs.append(SceneRef(str(folder), files["stem"], rel, kind))
    if not refs:
        raise FileNotFoundError(
            f"no scenes under {root}: expected {root}/train/<NNNNN-id>/ and {root}/val/<NNNNN-id>/ "
            "(make some with `ovon scenes generate`)"
        )
    return refs


def preflight_scenes(refs: list[SceneRef]) -> None:
    """Cheap checks of every scene's files before any generation work (`preflight_scene`: containers and
    lengths, node transforms, semantic.txt, extent), so a truncated or broken scene fails the command at
    once with one line naming its file, not after hours spent on the scenes listed before it."""
    from ovon.scenes.hm3dsem.load import preflight_scene

    for ref in refs:
        preflight_scene(ref.folder)


def scene_categories(ref: SceneRef) -> set[str]:
    """Canonical categories annotated in a scene, from its semantic.txt (cheap: no mesh loading)."""
    from ovon.scenes.hm3dsem import find_scene_files, parse_semantic_txt
    from ovon.scenes.vocabulary import load_vocabulary

    vocab = load_vocabulary()
    txt = find_scene_files(ref.folder)["semantic_txt"]
    if txt is None:
        raise FileNotFoundError(
            f"scene {ref.folder} has no semantic annotations ({ref.stem}.semantic.txt + {ref.stem}.semantic.glb): "
            "ObjectNav episodes need them; add them or move the scene out of the scenes folder"
        )
    from ovon.scenes.hm3dsem.errors import SceneFileError
    from ovon.scenes.hm3dsem.semantic_txt import SEMANTIC_HEADER, SEMANTIC_LINE_FORMAT

    entries = parse_semantic_txt(txt)
    if not entries:
        raise SceneFileError(
            txt,
            "holds no annotated instance (ObjectNav episodes need the scene's objects)",
            f"fix: expected a first line '{SEMANTIC_HEADER}', then {SEMANTIC_LINE_FORMAT} per "
            "instance; restore the file or move the scene out of the scenes folder",
        )
    return {c for e in entries if (c := vocab.clean(e.raw_label))}


def _rng(seed: int, *parts: str) -> np.random.Generator:
    return np.random.default_rng([seed, zlib.crc32("|".join(parts).encode())])


def _r(v, nd: int) -> list[float]:
    return [round(float(x), nd) for x in v]


# -- phase 1: goals of one scene ----------------------------------------------------------------
def compute_goals(ref: SceneRef, cfg: GenerationConfig, categories: list[str], nav_cache: Path | None = None) -> dict:
    """{category: [goal dict]} for the scene plus the reasons objects were not goals (`nav_cache`: the
    folder of the on-disk navigation-grid cache, shared with phase 2)."""
    from ovon.dataset.viewpoints import object_viewpoints
    from ovon.sim.navgrid import build_navigation
    from ovon.sim.render import make_renderer
    from ovon.sim.world import load_scene_any

    scene = load_scene_any(ref.folder)
    nav = build_navigation(scene, AgentConfig(), NavConfig(), cache_dir=nav_cache)
    vc = cfg.viewpoints
    cam = CameraConfig(
        width=vc.render_size,
        height=vc.render_size,
        hfov_deg=vc.hfov_deg,
        camera_height=vc.camera_height,
        backend=vc.backend,
    )  # type: ignore[arg-type]
    renderer = make_renderer(scene, cam)
    wanted = set(categories)
    reasons: Counter = Counter()
    goals: dict[str, list[dict]] = {}
    nd = cfg.decimals
    try:
        for obj in sorted(scene.objects, key=lambda o: o.id):
            if obj.category is None or obj.category not in wanted:
                continue
            grid = nav.grid_for(obj.aabb_min)
            vps, why = object_viewpoints(obj, grid, renderer, vc)
            if why is None:
                # Reachable = on an island where starts can be sampled (big enough, not a furniture top).
                ok = set(grid.start_islands(cfg.starts.min_island_radius).tolist())
                vps = [v for v in vps if grid.island_of(v.position) in ok]
                if not vps:
                    why = "unreachable"
            if why is not None:
                reasons[why] += 1
                continue
            goals.setdefault(obj.category, []).append(
                {
                    "object_category": obj.category,
                    "object_id": obj.name,
                    "position": _r(obj.center, nd),
                    "floor": int(grid.floor),
                    "view_points": [
                        {"position": _r(v.position, nd), "rotation": _r(v.rotation(), nd), "iou": round(v.score, nd)}
                        for v in vps
                    ],
                }
            )
    finally:
        renderer.close()
    return {
        "goals": goals,
        "not_goal_reasons": dict(sorted(reasons.items())),
        "floor_m2": round(start_area(nav, cfg.starts.min_island_radius), 2),
    }


def start_area(nav, min_island_radius: float) -> float:  # noqa: ANN001 - a SceneNav
    """Navigable area (m^2) where starts may lie: islands of radius >= `min_island_radius`, off furniture."""
    area = 0.0
    for g in nav.floors:
        ok = np.flatnonzero((g.island_radius >= min_island_radius) & ~g.elevated())
        area += float((np.isin(g.islands, ok) & g.navigable).sum()) * g.cell_size**2
    return area


def _goal_cache_path(out: Path, ref: SceneRef) -> Path:
    return out / ".cache" / "goals" / f"{ref.kind}-{ref.stem}.json.gz"


def goals_job(job: dict) -> dict:
    ref = SceneRef(**job["ref"])
    out = Path(job["out"])
    path = _goal_cache_path(out, ref)
    if path.exists():
        return {"stem": ref.stem, "cached": True}
    t0 = time.perf_counter()
    res = compute_goals(ref, from_dict(GenerationConfig, job["cfg"]), job["categories"], _nav_cache(out))
    write_json_gz(path, res)  # no timing in it: the cache is part of what the runner fingerprints
    return {"stem": ref.stem, "cached": False, "seconds": round(time.perf_counter() - t0, 3)}


def load_goal_cache(out: Path, ref: SceneRef) -> dict:
    with gzip.open(_goal_cache_path(out, ref), "rt", encoding="utf-8") as f:
        return json.load(f)


def _nav_cache(out: Path) -> Path:
    """Where both phases keep the scenes' navigation grids (computed once per scene, kept for a resume)."""
    return out / ".cache" / "nav"


# -- phase 2: episodes of one scene and split ----------------------------------------------------
def episodes_job(job: dict) -> dict:
    """Sample the allocated episodes of one (scene, split) and write its shard."""
    from ovon.dataset.starts import sample_start
    from ovon.sim.geodesic import distance_field, distance_to_goals
    from ovon.sim.navgrid import build_navigation
    from ovon.sim.world import load_scene_any

    ref = SceneRef(**job["ref"])
    out, split = Path(job["out"]), job["split"]
    if shard_exists(out, split, ref.stem):
        return {"stem": ref.stem, "split": split, "cached": True}
    cfg = from_dict(GenerationConfig, job["cfg"])
    goals: dict[str, list[dict]] = load_goal_cache(out, ref)["goals"]
    alloc: dict[str, int] = job["allocation"]
    children: dict[str, list[str]] = job["children"]
    rng = _rng(cfg.seed, "starts", split, ref.stem)
    reasons: Counter = Counter()
    t0 = time.perf_counter()
    episodes: list[Episode] = []
    used: set[str] = set()
    nav = None
    if any(alloc.values()):
        nav = build_navigation(load_scene_any(ref.folder), AgentConfig(), NavConfig(), cache_dir=_nav_cache(out))
    # Round-robin over categories so a truncated list still covers all of them.
    queue = {c: n for c, n in sorted(alloc.items()) if n > 0}
    per_cat: dict[str, tuple] = {}
    for cat in queue:
        cats = [cat, *[c for c in children.get(cat, []) if c in goals]]
        main_floor = Counter(g["floor"] for g in goals[cat]).most_common(1)[0][0]
        on_floor = [vp for c in cats for g in goals[c] if g["floor"] == main_floor for vp in g["view_points"]]
        vps = np.array([vp["position"] for vp in on_floor], dtype=np.float64)
        grid = nav.floors[main_floor]
        fld = distance_field(grid, vps)
        dist = distance_to_goals(nav, fld, vps)
        oracle_vps = [(np.asarray(vp["position"], dtype=np.float64), quat_to_yaw(vp["rotation"])) for vp in on_floor]
        per_cat[cat] = (
            cats,
            grid,
            fld,
            vps,
            _oracle_accept(grid, dist, oracle_vps, cfg) if cfg.starts.oracle_check else None,
            dist,
        )
    dropped = set()
    strata: dict[str, list[int]] = job.get("strata") or {}
    n_bins = max(0, len(cfg.starts.val_strata_m) - 1)
    while queue:
        for cat in list(queue):
            cats, grid, fld, vps, accept, dist = per_cat[cat]
            if strata.get(cat):
                start = None
                target = strata[cat][alloc[cat] - queue[cat]]
                for j, bounds in stratum_bounds(cfg.starts, target, n_bins):
                    start = sample_start(grid, fld, vps, bounds, rng, reasons, accept, dist)
                    if start is not None:
                        if j != target:
                            reasons["stratum_moved"] += 1
                        break
            else:
                start = sample_start(grid, fld, vps, cfg.starts, rng, reasons, accept, dist)
            if start is None:
                reasons["category_without_start"] += 1
                dropped.add(cat)
                del queue[cat]
                continue
            nd = cfg.decimals
            episodes.append(
                Episode(
                    episode_id=str(len(episodes)),
                    scene_id=ref.scene_id,
                    start_position=_r(start.position, nd),
                    start_rotation=_r(yaw_to_quat(start.yaw), nd),
                    object_category=cat,
                    info={
                        "geodesic_distance": round(start.geodesic, nd),
                        "euclidean_distance": round(start.euclidean, nd),
                    },
                    children_object_categories=cats[1:],
                )
            )
            used.update(cats)
            queue[cat] -= 1
            if queue[cat] == 0:
                del queue[cat]
    base = Path(ref.scene_id).name
    gbc = {
        goal_key(base, c): [
            ObjectGoal(
                g["object_category"],
                g["object_id"],
                g["position"],
                [ViewPoint(vp["position"], vp["rotation"], vp["iou"]) for vp in g["view_points"]],
            )
            for g in goals[c]
        ]
        for c in sorted(used)
    }
    write_scene_shard(out, split, ref.stem, episodes, gbc)
    return {
        "stem": ref.stem,
        "split": split,
        "cached": False,
        "episodes": len(episodes),
        "seconds": round(time.perf_counter() - t0, 3),
        "rejections": dict(reasons),
        "dropped_categories": sorted(dropped),
    }


def _oracle_accept(grid, dist, oracle_vps: list, cfg: GenerationConfig):  # noqa: ANN001, ANN202
    """The start check of `StartConfig.oracle_check`: the shortest-path oracle, run from the start as the
    episode file will hold it (rounded position and rotation), must finish."""
    from ovon.config.task import TaskConfig
    from ovon.dataset.starts import oracle_finishes

    task = TaskConfig()
    nd = cfg.decimals

    def accept(p: np.ndarray, yaw: float) -> bool:
        pos = np.asarray(_r(p, nd), dtype=np.float64)
        return oracle_finishes(
            grid,
            pos,
            quat_to_yaw(_r(yaw_to_quat(yaw), nd)),
            oracle_vps,
            dist,
            task.max_steps,
            task.success_distance,
            AgentConfig(),
        )

    return accept


# -- allocation ------------------------------------------------------------------------------------
def deal_strata(counts: dict, pairs: list, n_bins: int) -> dict[str, dict[str, list[int]]]:
    """Each val episode's start-distance bin: the split's episodes, in (scene, category) order, are dealt over
    the `n_bins` bins in turn, so every split holds the same number per bin (+-1) whatever its categories.
    {scene: {category: [bin of its 1st, 2nd, ... episode]}}; {} without strata."""
    if n_bins < 1:
        return {}
    out: dict[str, dict[str, list[int]]] = {}
    k = 0
    for scene, cat in pairs:
        n = counts[(scene, cat)]
        out.setdefault(scene, {})[cat] = [(k + i) % n_bins for i in range(n)]
        k += n
    return out


def stratum_bounds(starts, b: int, n_bins: int) -> list[tuple[int, Any]]:
    """The start configs of bin `b` and, as fallbacks, of the other bins nearest first: a bin this goal cannot
    fill (a small house has no 7 m path) moves its episode to the closest bin that it can (counted)."""
    edges = starts.val_strata_m
    order = sorted(range(n_bins), key=lambda j: (abs(j - b), j))
    out = []
    for j in order:
        lo, hi = max(starts.min_geodesic, edges[j]), min(starts.max_geodesic, edges[j + 1])
        if lo < hi:
            out.append((j, replace(starts, min_geodesic=lo, max_geodesic=hi)))
    return out


def largest_remainder(total: int, keys: list, weights: list[float] | None = None) -> dict:
    """Split `total` over keys in proportion to weights, integers summing exactly to total."""
    if not keys:
        return {}
    w = np.ones(len(keys)) if weights is None else np.asarray(weights, dtype=np.float64)
    quota = total * w / w.sum()
    base = np.floor(quota).astype(int)
    rest = total - int(base.sum())
    order = sorted(range(len(keys)), key=lambda i: (-(quota[i] - base[i]), i))
    for i in order[:rest]:
        base[i] += 1
    return {k: int(n) for k, n in zip(keys, base)}


@dataclass
class GenerationReport:
    seconds: float = 0.0
    scenes: int = 0
    episodes: dict = field(default_factory=dict)
    not_goal_reasons: Counter = field(default_factory=Counter)
    rejections: Counter = field(default_factory=Counter)
    dropped: list = field(default_factory=list)
    goal_seconds: list = field(default_factory=list)
    without_episodes: dict = field(default_factory=dict)  # "<kind>/<scene folder>" -> why it yields none


def _no_goal_reason(g: dict) -> str:
    """Why a scene's goal cache holds no goal (`compute_goals`)."""
    if g.get("floor_m2") == 0:
        a = AgentConfig()
        return (
            f"no navigable floor for the agent (radius {a.radius} m, height {a.height} m; furniture tops and "
            "tiny islands aside): check the scene's up axis, scale and face winding with `ovon scenes inspect`"
        )
    reasons = g.get("not_goal_reasons") or {}
    if not reasons:
        return "none of its objects is of a category of the requested splits"
    return "no object can be a goal (" + ", ".join(f"{n} {k}" for k, n in sorted(reasons.items())) + ")"


def _without_episodes(
    report: GenerationReport, active: list[SceneRef], scenes_dir: Path, out: Path, existed: set[str], final: bool
) -> None:
    """Name the scenes that yield no episode: an error when no scene of a kind the splits need (train or
    val) yields, the generation then leaving none of the files it created; else, once `final`, one warning
    (they are counted in the report)."""
    bad = report.without_episodes
    if not bad:
        return

    def named(scenes: list[str]) -> str:
        by_reason: dict[str, list[str]] = {}
        for scene in sorted(scenes):
            by_reason.setdefault(bad[scene], []).append(scene)
        return "; ".join(
            f"{', '.join(sc[:3])}{f' and {len(sc) - 3} more' if len(sc) > 3 else ''}: {why}"
            for why, sc in by_reason.items()
        )

    for kind in sorted({r.kind for r in active}):
        scenes = [f"{r.kind}/{Path(r.folder).name}" for r in active if r.kind == kind]
        if all(sc in bad for sc in scenes):
            for p in out.iterdir():
                if p.name not in existed:
                    shutil.rmtree(p) if p.is_dir() else p.unlink()
            raise EmptyGenerationError(
                f"no {kind} scene of {scenes_dir} yields an episode: {named(scenes)}; fix: repair those scenes or "
                "pass a scenes folder whose scenes have a navigable floor and annotated objects"
            )
    if final:
        warnings.warn(
            f"{len(bad)} of {len(active)} scenes of {scenes_dir} yield no episode (counted in "
            f"generation_report.json): {named(list(bad))}",
            stacklevel=3,
        )


@generation_run_folder  # identity, resume check and lock of the output folder (ovon.runfolder)
def generate(
    scenes_dir: str | Path,
    out: str | Path,
    cfg: GenerationConfig,
    splits: tuple[str, ...] = SPLITS,
    workers: int = 1,
    executor: str = "process",
    progress: bool = True,
    category_split_path: str | Path | None = None,
) -> GenerationReport:
    from ovon.dataset.splits import SplitConfig, children_map, load_category_split, split_categories
    from ovon.models.text_minilm import default_text_encoder
    from ovon.parallel import progress_bar, run_jobs
    from ovon.scenes.vocabulary import load_vocabulary

    bad = [s for s in splits if s not in SPLITS]
    if bad:
        raise ValueError(f"unknown split(s) {bad}; choose from {list(SPLITS)}")
    t0 = time.perf_counter()
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    existed = {p.name for p in out.iterdir()}
    refs = discover_scenes(scenes_dir)
    kinds = {"train"} if splits == ("train",) else ({"val"} if "train" not in splits else {"train", "val"})
    for kind in sorted(kinds):
        if not any(r.kind == kind for r in refs):
            need = [s for s in splits if (s == "train") == (kind == "train")]
            raise EmptyGenerationError(
                f"{scenes_dir} has no {kind} scenes (expected {Path(scenes_dir) / kind}/"
                f"<NNNNN-id>/) for the split(s) {need}; fix: add scene folders there or "
                "leave those splits out (--split)"
            )
    active = [r for r in refs if r.kind in kinds]
    preflight_scenes(active)
    cats_by_scene = {r.stem: scene_categories(r) for r in refs}
    cat_path = Path(category_split_path) if category_split_path else out / "categories.json"
    if cat_path.exists():
        csplit = load_category_split(cat_path, splits=splits)
    else:
        all_cats = sorted(set().union(*cats_by_scene.values()))
        if not all_cats:
            raise EmptyGenerationError(
                f"no scene of {scenes_dir} has an annotated object of a known category (their "
                "semantic.txt labels are all dropped by the cleaning table, e.g. wall, floor); "
                "fix: pass scenes annotated with object labels"
            )
        sc = cfg.splits
        csplit = split_categories(
            all_cats,
            SplitConfig(
                seed=sc.seed, holdout_fraction=sc.holdout_fraction, similarity_threshold=sc.similarity_threshold
            ),
        )
        csplit.save(cat_path)
    if cat_path != out / "categories.json":
        csplit.save(out / "categories.json")
    split_cats = {s: csplit.categories(s) for s in SPLITS}
    vocab, enc = load_vocabulary(), default_text_encoder()
    children = {
        s: (children_map(split_cats[s], vocab, enc, cfg.splits.children_threshold) if cfg.splits.children else {})
        for s in splits
    }
    atomic_write_text(out / "generation_config.json", json.dumps(to_dict(cfg), indent=2, sort_keys=True))
    report = GenerationReport(scenes=len(refs))
    cfg_d = to_dict(cfg)
    wanted = sorted(set().union(*(split_cats[s] for s in splits)))

    # phase 1: goals
    jobs = [{"ref": r.__dict__, "out": str(out), "cfg": cfg_d, "categories": wanted} for r in active]
    with progress_bar("goals + viewpoints (scenes)", len(jobs), progress) as bar:
        for res in run_jobs(goals_job, jobs, workers, executor):
            if not res["cached"]:
                report.goal_seconds.append(res["seconds"])
            bar.advance()
    goals = {r.stem: load_goal_cache(out, r) for r in active}
    for g in goals.values():
        report.not_goal_reasons.update(g["not_goal_reasons"])
    name = {r.stem: f"{r.kind}/{Path(r.folder).name}" for r in active}
    report.without_episodes = {
        name[r.stem]: _no_goal_reason(goals[r.stem]) for r in active if not goals[r.stem]["goals"]
    }
    _without_episodes(report, active, Path(scenes_dir), out, existed, final=False)

    # phase 2: allocation + starts
    ep_jobs = []
    for split in splits:
        kind = "train" if split == "train" else "val"
        scene_refs = [r for r in active if r.kind == kind]
        eligible = {r.stem: sorted(c for c in split_cats[split] if c in goals[r.stem]["goals"]) for r in scene_refs}
        if split == "train":
            allocs = {s: largest_remainder(cfg.episodes_per_train_scene, cs) for s, cs in eligible.items()}
        else:
            pairs = [(s, c) for s, cs in sorted(eligible.items()) for c in cs]
            flat = largest_remainder(cfg.episodes_per_val_split, pairs)
            allocs = {s: {c: flat[(s, c)] for c in cs} for s, cs in eligible.items()}
            strata = deal_strata(flat, pairs, len(cfg.starts.val_strata_m) - 1)
        for r in scene_refs:
            ep_jobs.append(
                {
                    "ref": r.__dict__,
                    "out": str(out),
                    "cfg": cfg_d,
                    "split": split,
                    "allocation": allocs[r.stem],
                    "children": children[split],
                    # val splits with start-distance strata: each episode's bin, per category, in order
                    "strata": {} if split == "train" else strata.get(r.stem, {}),
                }
            )
        write_split_shell(out, split)
    allocated = {(j["ref"]["stem"], j["split"]): j["allocation"] for j in ep_jobs}
    yielded: dict[str, bool] = {}  # stem -> an episode (or a shard from an earlier session), False: none
    failed: dict[str, Counter] = {}
    with progress_bar("episodes (scene x split)", len(ep_jobs), progress) as bar:
        for res in run_jobs(episodes_job, ep_jobs, workers, executor):  # in completion order
            if not res["cached"]:
                report.episodes[res["split"]] = report.episodes.get(res["split"], 0) + res["episodes"]
                report.rejections.update(res["rejections"])
                report.dropped += [(res["stem"], res["split"], c) for c in res["dropped_categories"]]
            stem = res["stem"]
            if res["cached"] or res["episodes"]:
                yielded[stem] = True
            elif any(allocated[(stem, res["split"])].values()):
                yielded.setdefault(stem, False)
                failed.setdefault(stem, Counter()).update(res["rejections"])
            bar.advance()
    for stem, ok in sorted(yielded.items()):
        if not ok:
            why = ", ".join(f"{n} {k}" for k, n in sorted(failed[stem].items())) or "none"
            report.without_episodes[name[stem]] = f"no start could be sampled for its goals (rejections: {why})"
    _without_episodes(report, active, Path(scenes_dir), out, existed, final=True)
    report.seconds = time.perf_counter() - t0
    summary = {
        "seconds": round(report.seconds, 2),
        "scenes": report.scenes,
        "new_episodes": report.episodes,
        "objects_not_goals": dict(report.not_goal_reasons),
        "start_rejections": dict(report.rejections),
        "dropped_categories": report.dropped,
        "goal_seconds_per_scene": report.goal_seconds,
        "scenes_without_episodes": dict(sorted(report.without_episodes.items())),
    }
    atomic_write_text(out / "generation_report.json", json.dumps(summary, indent=2, sort_keys=True))
    return report
