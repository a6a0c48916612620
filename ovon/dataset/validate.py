"""Episode validation, shared by `ovon dataset validate` and every reader (evaluation, training).

Why one module: the checks a reader needs before it runs an episode (unique ids, finite numbers, unit
pure-yaw start rotations, goals with viewpoints, a non-empty category, a start on the navigable map)
are the ones `validate` reports. Readers skip a bad episode with a counted warning; `validate` lists it
and fails. Independent of the generator's code, `validate` also checks the constraints of docs/spec.md#generation:
viewpoint ordering and scores, and that every start is on the goals' floor, within the geodesic limits
of a goal viewpoint, along a single-floor path.
"""

from __future__ import annotations

import math
import warnings
from collections import Counter
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ovon.config.dataset import GenerationConfig
from ovon.config.sim import AgentConfig, NavConfig
from ovon.dataset.io import SPLITS, EpisodeDataset, SceneEpisodes
from ovon.dataset.records import DatasetError, Episode, ObjectGoal, goal_key, resolve_scene_path

ROT_TOL = 1e-4  # released rotations are float32 rounded to 6 decimals


class DatasetWarning(UserWarning):
    """Episodes a reader skipped (the message counts them by problem and points to `ovon dataset validate`)."""


# ----------------------------------------------------------------------------------------------------
# checks without the scene


def rotation_problem(q: Iterable[float], yaw_only: bool = True) -> str | None:
    """Why `q` ([x, y, z, w]) is not a unit (pure-yaw) quaternion, or None."""
    q = np.asarray(list(q), dtype=np.float64)
    n = float(np.linalg.norm(q))
    if abs(n - 1.0) > ROT_TOL:
        return f"{q.tolist()} is not a unit quaternion (norm {n:.4g})"
    if yaw_only and (abs(q[0]) > ROT_TOL or abs(q[2]) > ROT_TOL):
        return f"{q.tolist()} is not a rotation about +y only (x, z must be 0)"
    return None


def goal_problems(g: ObjectGoal) -> list[tuple[str, str]]:
    """(kind, detail) for one goal instance."""
    out: list[tuple[str, str]] = []
    try:
        _ = g.instance_id
    except ValueError as e:
        out.append(("object_id", str(e)))
    if not g.object_category.strip():
        out.append(("empty_category", "empty object_category"))
    if not g.view_points:
        out.append(("no_viewpoints", f"goal {g.object_id!r} has no view_points"))
    for i, vp in enumerate(g.view_points):
        why = rotation_problem(vp.rotation, yaw_only=False)
        if why:
            out.append(("viewpoint_rotation", f"view_points[{i}].agent_state.rotation {why}"))
            break
    return out


def episode_problems(ep: Episode, goals_by_category: Mapping[str, list[ObjectGoal]]) -> list[tuple[str, str]]:
    """(kind, detail) for everything that stops an episode from running as the dataset means it."""
    out: list[tuple[str, str]] = []
    if not str(ep.object_category).strip():
        out.append(("empty_category", "object_category is empty"))
    why = rotation_problem(ep.start_rotation)
    if why:
        out.append(("rotation", f"start_rotation {why}"))
    for k in ("geodesic_distance", "euclidean_distance"):
        v = (ep.info or {}).get(k)
        if v is not None and (isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v) or v < 0):
            out.append(("info_number", f"info.{k} = {v!r} is not a finite number >= 0"))
    key = goal_key(ep.scene_id, ep.object_category)
    if key not in goals_by_category:
        out.append(("missing_goal_key", f"goals_by_category has no {key!r}"))
        return out
    goals = list(goals_by_category[key])
    for child in ep.children_object_categories:
        goals += goals_by_category.get(goal_key(ep.scene_id, child), [])
    if not goals:
        out.append(("no_goals", f"no goal instances for {[ep.object_category, *ep.children_object_categories]}"))
    elif not any(g.view_points for g in goals):
        out.append(("no_viewpoints", "none of its goals has a viewpoint"))
    if any(g.view_points for g in goals):
        try:
            for g in goals:
                _ = g.instance_id
        except ValueError as e:
            out.append(("object_id", str(e)))
    return out


@dataclass
class ShardCheck:
    """The problems of one shard: per episode index, and of its goals."""

    episodes: dict[int, list[tuple[str, str]]] = field(default_factory=dict)
    goals: list[tuple[str, str, str]] = field(default_factory=list)  # (kind, where, detail)

    def bad(self, i: int) -> bool:
        return i in self.episodes


def check_shard(shard: SceneEpisodes) -> ShardCheck:
    """Duplicated episode ids (later copies), per-episode problems, and problems of the goal lists."""
    res = ShardCheck()
    seen: dict[str, int] = {}
    for i, ep in enumerate(shard.episodes):
        probs = episode_problems(ep, shard.goals_by_category)
        eid = str(ep.episode_id)
        if eid in seen:
            probs.insert(0, ("duplicate_id", f"episode_id {eid!r} already used by episodes[{seen[eid]}]"))
        else:
            seen[eid] = i
        if probs:
            res.episodes[i] = probs
    for key, goals in shard.goals_by_category.items():
        if not goals:
            res.goals.append(("empty_goal_list", f"goals_by_category[{key!r}]", "empty list of goals"))
        for gi, g in enumerate(goals):
            for kind, detail in goal_problems(g):
                res.goals.append((kind, f"goals_by_category[{key!r}][{gi}]", detail))
    return res


def usable_episodes(shard: SceneEpisodes) -> tuple[list[Episode], Counter]:
    """The episodes a reader may run, and a count of the skipped ones by their first problem."""
    chk = check_shard(shard)
    skipped = Counter(chk.episodes[i][0][0] for i in chk.episodes)
    return [ep for i, ep in enumerate(shard.episodes) if not chk.bad(i)], skipped


def warn_skipped(where: str, skipped: Counter, total: int) -> None:
    """One counted warning for the episodes a reader skipped."""
    n = sum(skipped.values())
    if n:
        kinds = ", ".join(f"{c} {k}" for k, c in sorted(skipped.items()))
        warnings.warn(
            f"{where}: skipped {n} of {total} episodes that fail validation ({kinds}); "
            "`ovon dataset validate` lists them",
            DatasetWarning,
            stacklevel=3,
        )


def split_problem(ds: EpisodeDataset) -> str | None:
    """Why a split folder holds no episodes at all (no content/ folder, no shards), or None. A split's
    `<split>.json.gz` is read even when its shards hold every episode: a torn one means a broken copy of the
    dataset, which is named (DatasetError) instead of being passed over."""
    ds.shell()
    if not ds.content_dir.is_dir():
        if ds.shell().get("episodes"):
            return None
        return f"{ds.split_dir} has no content/ folder (expected content/<scene>.json.gz shards)"
    if not ds.scenes() and not ds.shell().get("episodes"):
        return f"{ds.content_dir} holds no <scene>.json.gz shards"
    return None


# ----------------------------------------------------------------------------------------------------
# checks with the scene


def start_problem(nav, position: Iterable[float]) -> str | None:
    """Why an episode may not start at `position` in the scene (`SceneNav.start_problem`), or None."""
    return nav.start_problem(np.asarray(list(position), dtype=np.float64))


_NAV_MEMO: dict[tuple, object] = {}


def scene_navigation(scene_path: str, agent: AgentConfig, nav: NavConfig):
    """Navigation of a scene file, memoised per (file, size, mtime, params) so repeated checks are free."""
    from ovon.sim.navgrid import build_navigation
    from ovon.sim.world import load_scene_any

    try:
        st = Path(scene_path).stat()
        key = (scene_path, st.st_size, st.st_mtime_ns, agent, nav)
    except OSError:
        key = (scene_path, agent, nav)
    if key not in _NAV_MEMO:
        if len(_NAV_MEMO) >= 8:
            _NAV_MEMO.pop(next(iter(_NAV_MEMO)))
        _NAV_MEMO[key] = build_navigation(load_scene_any(scene_path), agent, nav)
    return _NAV_MEMO[key]


def off_map_starts_job(job: dict) -> dict:
    """Worker job: [index, why] of the `job["starts"]` no episode may start at (`start_problem`)."""
    from ovon.config.base import from_dict

    nav = scene_navigation(job["scene"], from_dict(AgentConfig, job["agent"]), from_dict(NavConfig, job["nav"]))
    why = [start_problem(nav, p) for p in job["starts"]]
    return {"scene": job["scene"], "bad": [[i, w] for i, w in enumerate(why) if w]}


# ----------------------------------------------------------------------------------------------------
# ovon dataset validate


@dataclass
class ValidationReport:
    episodes: int = 0
    shards: int = 0
    errors: list[str] = field(default_factory=list)
    counts: Counter = field(default_factory=Counter)

    @property
    def ok(self) -> bool:
        return not self.errors and not self.counts

    def error(self, kind: str, msg: str) -> None:
        self.counts[kind] += 1
        if len(self.errors) < 200:
            self.errors.append(msg)


def _check_geometry(ep, goals, nav, cfg: GenerationConfig, where: str, rep: ValidationReport, tol: float) -> None:
    from ovon.sim.geodesic import distance_field, distance_to_goals

    why = start_problem(nav, ep.start_position)
    if why:
        rep.error("start_not_navigable", f"{where}: {why}")
        return
    start = np.asarray(ep.start_position, dtype=np.float64)
    grid = nav.grid_for(start)
    vps = np.array([vp.position for g in goals for vp in g.view_points], dtype=np.float64)
    same_floor = np.array([nav.floor_index(v) == grid.floor for v in vps])
    if not same_floor.any():
        rep.error("other_floor", f"{where}: no goal viewpoint on the start's floor {grid.floor}")
        return
    fld = distance_field(grid, vps[same_floor])
    d = distance_to_goals(nav, fld, vps[same_floor])(start)  # on a navmesh scene, habitat's own geodesic
    sc = cfg.starts
    if not math.isfinite(d):
        rep.error("unreachable", f"{where}: no goal viewpoint reachable from the start")
        return
    if d < sc.min_geodesic - tol or d > sc.max_geodesic + tol:
        rep.error("geodesic_range", f"{where}: geodesic {d:.3f} m outside [{sc.min_geodesic}, {sc.max_geodesic}]")
    stored = (ep.info or {}).get("geodesic_distance")
    if stored is not None and abs(float(stored) - d) > max(tol, 0.02 * d):
        rep.error("geodesic_mismatch", f"{where}: info.geodesic_distance {stored} but recomputed {d:.3f}")
    path = fld.path(start)
    if len(path) and float(np.ptp(path[:, 1])) > sc.max_height_span + 1e-6:
        rep.error("multi_floor", f"{where}: path height span {np.ptp(path[:, 1]):.2f} m")


def dataset_splits(root: str | Path) -> list[str]:
    """Split folders under a dataset root: the known split names present, plus any folder with content/."""
    root = Path(root)
    if not root.is_dir():
        raise FileNotFoundError(f"dataset {root} does not exist; fix: pass the folder that holds val_seen/ ...")
    return [
        d.name
        for d in sorted(root.iterdir())
        if d.is_dir()
        and not d.name.startswith(".")
        and (
            d.name in SPLITS
            or d.name in ("val_unseen_easy", "val_unseen_hard")
            or (d / "content").is_dir()
            or (d / f"{d.name}.json.gz").is_file()
        )
    ]


def validate_dataset(
    root: str | Path,
    scenes: str | Path,
    splits: list[str] | None = None,
    cfg: GenerationConfig | None = None,
    max_episodes_per_scene: int | None = None,
    tol: float = 0.05,
) -> ValidationReport:
    cfg = cfg or GenerationConfig()
    root = Path(root)
    splits = dataset_splits(root) if splits is None else list(splits)
    rep = ValidationReport()
    if not splits:
        rep.error("no_splits", f"{root}: no split folders (expected e.g. val_seen/content/*.json.gz)")
    for split in splits:
        ds = EpisodeDataset(root, split)
        why = split_problem(ds)
        if why:
            rep.error("empty_split", f"{split}: {why}")
            continue
        split_episodes = 0
        for scene, shard in ds.iter_scenes():
            rep.shards += 1
            chk = check_shard(shard)
            for kind, w, detail in chk.goals:
                rep.error(kind, f"{split}/{scene}: {w}: {detail}")
            for key, goals in shard.goals_by_category.items():
                w = f"{split}/{scene}: goals_by_category[{key!r}]"
                for gi, g in enumerate(goals):
                    ious = [vp.iou for vp in g.view_points]
                    if any(a < b for a, b in zip(ious, ious[1:])):
                        rep.error("viewpoint_order", f"{w}[{gi}]: view_points not sorted by iou")
                    if ious and min(ious) <= cfg.viewpoints.min_score:
                        rep.error("viewpoint_score", f"{w}[{gi}]: a viewpoint scores <= {cfg.viewpoints.min_score}")
            split_episodes += len(shard.episodes)
            eps = shard.episodes[:max_episodes_per_scene] if max_episodes_per_scene else shard.episodes
            for i, ep in enumerate(eps):
                rep.episodes += 1
                where = f"{split}/{scene}: episodes[{i}] (id {ep.episode_id})"
                try:
                    path = str(resolve_scene_path(ep.scene_id, scenes))
                except (DatasetError, FileNotFoundError) as e:
                    rep.error("scene", f"{where}: {e}")
                    continue
                if chk.bad(i):
                    for kind, detail in chk.episodes[i]:
                        rep.error(kind, f"{where}: {detail}")
                    continue
                nav = scene_navigation(path, AgentConfig(), NavConfig())
                goals = shard.goals_for(ep)
                _check_geometry(ep, goals, nav, cfg, where, rep, tol)
        if split_episodes == 0:
            rep.error("empty_split", f"{split}: no episodes in {ds.content_dir}")
    return rep
