"""Episode set-up: from a loaded world and an `EpisodeSpec` to the true start state, the goal set and a
fresh `EpisodeTracker`.

Why a task function and not env code: the simulator knows scenes, grids and cameras but nothing of
goals; the Gymnasium env (ovon.env) only sequences reset/step. Dataset tools and tests can set up the
same episode without an env.
"""

from __future__ import annotations

import math
import weakref
from dataclasses import dataclass

import numpy as np

from ovon.config.task import TaskConfig
from ovon.lru import LRU
from ovon.scenes.model import footprint_distance
from ovon.sim.geodesic import CACHE_SIZE, DistanceField, distance_field, distance_to_goals
from ovon.sim.navgrid import START_HEIGHT_TOLERANCE_M
from ovon.sim.types import AgentState
from ovon.sim.world import World
from ovon.task.episode import EpisodeSpec, GoalViewpoint
from ovon.task.goals import distractors, goal_instances, points_near_objects
from ovon.task.tracker import EpisodeTracker

_ADHOC = LRU(CACHE_SIZE)  # (grid uids, goal object ids) -> (grid, points, viewpoints), as many as distance fields
# world -> {goal categories: the scene's distractors}, shared read-only: a training env resets to the same few
# goal sets thousands of times and rebuilding the list cost ~0.05 ms per PPO step. Keyed by the world itself
# (weakly), not by its grids: worlds of the same geometry share grids but may hold other objects.
_DISTRACTORS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


@dataclass
class EpisodeSetup:
    """Everything ground truth about one episode at its start."""

    state: AgentState  # true start pose
    grid: object  # NavGrid of the start floor
    goal_field: DistanceField  # geodesic distance to the nearest goal viewpoint
    viewpoints: list[GoalViewpoint]
    goal_ids: frozenset[int]
    tracker: EpisodeTracker  # reset by the env once the first frame is rendered
    point_goal: np.ndarray | None = None  # pointnav: the goal (forward, left) in the start frame


def prepare_episode(
    world: World, spec: EpisodeSpec, rng: np.random.Generator, task: TaskConfig, fov_deg: float = 42.0
) -> EpisodeSetup:
    """Goal instances, viewpoints (the episode's own, or navigable points within 1 m of the goals for
    ad-hoc episodes), the goal distance field, and the start (the episode's, or a seeded random one
    connected to the goals). `fov_deg` is the camera's (for the exploration reward). Raises ValueError when
    the episode cannot be set up in this world. With `task.kind == "pointnav"` see `_prepare_point`."""
    if task.kind == "pointnav":
        return _prepare_point(world, spec, rng, task)
    objs = goal_instances(world.scene, spec)
    start_pos = check_start(world, spec)
    if start_pos is not None:
        grids = [world.nav.grid_for(start_pos)]
    else:
        # Random start: on the floor of a random viewpoint / goal object (a seeded choice).
        anchors = [v.position for v in spec.viewpoints] or [o.aabb_min for o in objs]
        grids = []
        for i in rng.permutation(len(anchors)):
            g = world.nav.grid_for(anchors[int(i)])
            if all(g is not h for h in grids):
                grids.append(g)
    if spec.viewpoints:
        grid = grids[0]
        # The start floor's goals only (navigation is per floor, as the dataset validator measures d0): a
        # viewpoint upstairs over a navigable cell downstairs would otherwise be a goal there.
        viewpoints = [v for v in spec.viewpoints if world.nav.floor_index(v.position) == grid.floor]
        if not viewpoints:
            raise ValueError(
                f"episode {spec.episode_id!r} in scene {spec.scene!r}: no goal viewpoint on the start's "
                f"floor {grid.floor} ({len(spec.viewpoints)} on other floors); expected the goal on the "
                "start's floor (ovon navigates one floor at a time); fix: `ovon dataset validate` "
                "lists such episodes (other_floor): leave them out"
            )
        points = np.stack([v.position for v in viewpoints])
    else:
        grid, points, viewpoints = _adhoc_viewpoints(world, grids, objs, spec.goal_category)
    field = distance_field(grid, points)
    distance_fn = distance_to_goals(world.nav, field, points)
    if start_pos is None:
        start_pos = _random_reachable_start(grid, distance_fn, rng, task.success_distance)
    elif not math.isfinite(distance_fn(start_pos)):  # else the episode would run to its step limit first
        raise ValueError(
            f"episode {spec.episode_id!r} in scene {spec.scene!r}: no goal viewpoint is reachable from "
            f"the start {np.round(start_pos, 3).tolist()} on floor {grid.floor}; fix: `ovon dataset "
            "validate` lists such episodes (unreachable): leave them out"
        )
    yaw = spec.start_yaw if spec.start_yaw is not None else float(rng.uniform(-math.pi, math.pi))
    goal_ids = frozenset(o.id for o in objs)
    on_floor = [o for o in objs if world.nav.grid_for(o.aabb_min) is grid] or objs
    coverage = None
    if task.reward.kind == "dense" and task.reward.dense_coverage != 0.0:
        from ovon.task.coverage import Coverage

        coverage = Coverage(grid, task.reward.coverage_fov_deg or fov_deg, task.reward.coverage_range_m)
    tracker = EpisodeTracker(
        distance_fn=distance_fn,
        goal_ids=goal_ids,
        cfg=task,
        distractors=_world_distractors(world, spec.goal_categories),
        coverage=coverage,
        object_distance_fn=lambda p: object_floor_distance(on_floor, p),
    )
    state = AgentState(np.array(start_pos, dtype=np.float64), float(yaw), 0.0)
    return EpisodeSetup(state, grid, field, list(viewpoints), goal_ids, tracker)


def check_start(world: World, spec: EpisodeSpec) -> np.ndarray | None:
    """The spec's given start position as floats (None: a random start), refused (one-line ValueError
    naming the episode and the value) unless it and the start yaw are finite and the position lies on
    the navigable map of its floor (`SceneNav.start_problem`, the dataset validator's rule too):
    off the map the agent renders from outside the building and the goal distance is inf, which no
    metric reports."""
    where = f"episode {spec.episode_id!r} in scene {spec.scene!r}"
    yaw = spec.start_yaw
    if yaw is not None and not (isinstance(yaw, int | float | np.integer | np.floating) and math.isfinite(yaw)):
        raise ValueError(
            f"{where}: start yaw = {yaw!r}: expected a finite angle; fix: give a finite start yaw "
            "(ObjectNavEnv start=(x, y, z, yaw_deg)), or none for a random one"
        )
    if spec.start_position is None:
        return None
    try:
        pos = np.asarray(spec.start_position, dtype=np.float64)
    except (TypeError, ValueError):
        pos = np.full(0, np.nan)
    if pos.shape != (3,) or not np.isfinite(pos).all():
        raise ValueError(
            f"{where}: start (x, y, z) = {spec.start_position!r}: expected 3 finite numbers; fix: give "
            "a start on the scene's navigable floor, or none for a random one"
        )
    why = world.nav.start_problem(pos)
    if why is None:
        return pos
    if not world.nav.floors:
        raise ValueError(f"{where}: {why}; fix: check the scene's mesh and the agent's size (sim.agent)")
    near = world.nav.snap(pos)  # nan when this floor has no navigable cell
    hint = f"e.g. the nearest navigable point {near.round(3).tolist()}" if np.isfinite(near).all() else "elsewhere"
    raise ValueError(
        f"{where}: {why}; expected a navigable x, z (agent radius {world.nav.agent.radius} m) with y "
        f"within {START_HEIGHT_TOLERANCE_M} m of that floor's surface; fix: start there, {hint}, or give "
        "no start for a random one"
    )
    return pos


def _world_distractors(world: World, goal_categories: list[str]) -> list:
    per_world = _DISTRACTORS.setdefault(world, {})
    key = tuple(sorted(set(goal_categories)))
    if key not in per_world:
        per_world[key] = distractors(world.scene, goal_categories)
    return per_world[key]


def _adhoc_viewpoints(world: World, grids: list, objs: list, goal: str) -> tuple:
    """(grid, points, viewpoints) of an ad-hoc episode: the navigable points within 1 m of the goal objects
    on the first of `grids` that has any. Cached per (grids, objects): a training env resets to the same
    few goal sets thousands of times, and building the ~1000 viewpoints cost more than the episode's
    first frame. The cached viewpoints are shared, read-only."""

    def make() -> tuple:
        grid, points = grids[0], np.zeros((0, 3))
        for grid in grids:
            points = points_near_objects(grid, [o for o in objs if world.nav.grid_for(o.aabb_min) is grid])
            if len(points):
                break
        if len(points) == 0:
            raise ValueError(f"no navigable point within 1 m of any {goal!r} on its floor")
        points.flags.writeable = False
        return grid, points, tuple(GoalViewpoint(p, 0.0) for p in points)

    return _ADHOC.get((tuple(g.uid for g in grids), tuple(o.id for o in objs)), make)


def object_floor_distance(objects: list, position: np.ndarray) -> float:
    """Floor-plane distance from a position to the nearest of the objects' oriented box footprints."""
    xz = np.asarray(position, dtype=np.float64)[[0, 2]][None]
    return min(float(footprint_distance(o, xz)[0]) for o in objects)


def _random_reachable_start(grid, distance_fn, rng: np.random.Generator, min_distance: float) -> np.ndarray:  # noqa: ANN001
    for _ in range(1000):
        p = grid.random_point(rng)
        d = distance_fn(p)
        if math.isfinite(d) and d > min_distance:
            return p
    raise ValueError("could not find a navigable start connected to the goal in 1000 tries")


def _prepare_point(world: World, spec: EpisodeSpec, rng: np.random.Generator, task: TaskConfig) -> EpisodeSetup:
    """A PointNav episode: the spec's start and single viewpoint (the goal point) when it has both, else a
    pair sampled with `rng` (`ovon.task.pointgoal.sample_point_goal`); the goal field has one source. A start
    without a goal point is refused (it used to be replaced by a sampled one without a word)."""
    from ovon.task.pointgoal import goal_in_start_frame, sample_point_goal

    start = check_start(world, spec)
    if start is not None and not spec.viewpoints:
        raise ValueError(
            f"episode {spec.episode_id!r}: a PointNav episode with a given start needs its goal point "
            "too (viewpoints[0]); fix: give both, or neither for a sampled pair"
        )
    if start is not None:
        grid = world.nav.grid_for(start)
        goal = np.asarray(spec.viewpoints[0].position, dtype=np.float64)
        field = distance_field(grid, goal[None])
    else:
        grid, start, goal, field = sample_point_goal(world.nav.floors, rng, task)
    yaw = spec.start_yaw if spec.start_yaw is not None else float(rng.uniform(-math.pi, math.pi))
    distance_fn = distance_to_goals(world.nav, field, np.asarray(goal, dtype=np.float64)[None])
    tracker = EpisodeTracker(distance_fn=distance_fn, goal_ids=frozenset(), cfg=task, goal_known=True)
    state = AgentState(np.array(start, dtype=np.float64), float(yaw), 0.0)
    return EpisodeSetup(
        state,
        grid,
        field,
        [GoalViewpoint(np.asarray(goal, dtype=np.float64), 0.0)],
        frozenset(),
        tracker,
        goal_in_start_frame(start, yaw, goal),
    )
