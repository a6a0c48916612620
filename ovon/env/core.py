"""The Gymnasium environment: `gymnasium.make("ovon/ObjectNav-v0", scene=..., goal="couch")`.

Observations are what a real robot has (RGB, depth, odometry, goal text, a bump flag) and `info` holds
only the episode id (plus the episode's metrics once it has ended): nothing an agent could cheat with.
Ground truth (true pose, semantic frame, goal field, map) is reachable through ONE explicit channel,
`env.unwrapped.privileged()`, which the `PrivilegedObservation` wrapper (ovon.env.privileged) puts into
the observation of oracle agents, experts and oracle encoders.
"""

from __future__ import annotations

import math
import re
import reprlib
import string
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, TypeVar

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from ovon.config.base import ConfigError, from_dict, merge, parse_overrides, validate
from ovon.config.sim import SimConfig
from ovon.config.task import TaskConfig
from ovon.scenes.model import Scene
from ovon.sim.agent import ACTION_NAMES, STOP, Kinematics, Odometry
from ovon.sim.navmesh.pathfind import navmesh_surface
from ovon.sim.noise import ActuationNoise, OdometryNoise
from ovon.sim.types import AgentState, Frame
from ovon.sim.world import World, acquire_world
from ovon.task.episode import EpisodeSpec, GoalViewpoint
from ovon.task.setup import prepare_episode
from ovon.task.tracker import EpisodeTracker

GOAL_CHARSET = string.ascii_letters + string.digits + " -_'/&().,"
MAX_GOAL_LEN = 64
ODOMETRY_LIMIT_M = 1000.0  # bound of the odometry Box (any building fits; check_env wants finite bounds)
RESET_OPTIONS = ("episode",)  # the keys reset(options=...) reads

C = TypeVar("C")


def _shown(value: Any) -> str:
    """A value for a one-line message (long reprs, e.g. of arrays, shortened)."""
    return " ".join(reprlib.repr(value).split())


def _config(value: C | Mapping[str, Any] | None, cls: type[C], name: str) -> C:
    """`sim=` / `task=` as a validated config: None (the defaults), an instance of `cls`, or a mapping of
    its fields (partial: the rest default). Checked here because an out-of-domain value built in Python
    (a negative success distance, a 0 deg field of view) otherwise fails much later, or never."""
    if value is None:
        return cls()
    try:
        if isinstance(value, cls):
            return validate(value, name)
        if isinstance(value, Mapping):
            return from_dict(cls, value, name)
    except ConfigError as e:  # the fix in Python terms, not the command line's `--set KEY=VALUE`
        msg = re.sub(r"--set ([\w.]+)=VALUE with VALUE", r"set \1 to", str(e))
        msg = msg.replace("fix: --set the values", "fix: set the values")
        raise ConfigError(msg if "fix:" in msg else f"{msg}; fix: use only these keys") from None
    raise ConfigError(
        f"{name} = {_shown(value)}: expected a {cls.__name__} or a mapping of its fields; fix: pass "
        f"{name}={cls.__name__}(...) or {name}={{...}} with its keys"
    )


def _start_pose(start: Any) -> tuple[float, float, float, float] | None:
    """`start=` as (x, y, z, yaw_deg) floats, refused unless 4 finite numbers (whether it lies on the
    navigable map is checked at reset, once the scene is loaded: `ovon.task.setup.check_start`)."""
    if start is None:
        return None
    ok = (
        isinstance(start, Sequence | np.ndarray)
        and not isinstance(start, str)
        and len(start) == 4
        and all(isinstance(v, int | float | np.integer | np.floating) and not isinstance(v, bool) for v in start)
        and all(math.isfinite(float(v)) for v in start)
    )
    if not ok:
        raise ValueError(
            f"start = {_shown(start)}: expected 4 finite numbers (x, y, z in m, yaw in degrees); "
            "fix: pass e.g. start=(3.0, 0.0, 2.0, 90.0) with x, z on the scene's navigable floor, "
            "or leave it out for a random start"
        )
    return tuple(float(v) for v in start)  # type: ignore[return-value]


@dataclass
class Privileged:
    """Ground truth for experts, oracles, dataset tools and failure analysis (never for a real agent)."""

    state: AgentState  # true pose
    grid: object  # NavGrid of the episode's floor
    goal_field: object  # DistanceField to all goal viewpoints
    viewpoints: list[GoalViewpoint]
    goal_ids: frozenset[int]
    frame: Frame  # the rendered frame, with the semantic instance ids
    world: World  # scene (objects and categories), navigation, renderer
    distance_to_goal: float = math.nan  # geodesic distance of the true pose to the nearest viewpoint
    sim: SimConfig | None = None  # the embodiment and camera this episode runs with
    task: TaskConfig | None = None  # success radius, step limit


class ObjectNavEnv(gym.Env):
    """`sim` / `task`: a config, a mapping of its fields, or None (defaults); `overrides`: `key=value`
    strings under `sim.` / `task.` applied on top; `start`: (x, y, z, yaw_deg) of ad-hoc episodes.
    Every argument is checked here, before a scene is loaded (one-line ValueError / ConfigError)."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": 10}

    def __init__(
        self,
        scene: str | Scene | None = None,
        goal: str | None = None,
        episodes: list[EpisodeSpec] | None = None,
        sim: SimConfig | Mapping[str, Any] | None = None,
        task: TaskConfig | Mapping[str, Any] | None = None,
        overrides: list[str] | tuple[str, ...] = (),
        start: tuple[float, float, float, float] | None = None,
        render_mode: str | None = "rgb_array",
    ):
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(
                f"render_mode = {_shown(render_mode)}: expected None or one of "
                f"{self.metadata['render_modes']} (ObjectNavEnv.metadata['render_modes']); fix: pass "
                "render_mode='rgb_array' and display the frames env.render() returns"
            )
        sim = _config(sim, SimConfig, "sim")
        task = _config(task, TaskConfig, "task")
        if isinstance(overrides, str) or not isinstance(overrides, Sequence):
            raise ConfigError(
                f"overrides = {_shown(overrides)}: expected a list of 'key=value' strings; fix: pass "
                "e.g. overrides=['task.max_steps=300']"
            )
        if overrides:
            data = parse_overrides(list(overrides))
            unknown = sorted(set(data) - {"sim", "task"})
            if unknown:
                raise ConfigError(
                    f"overrides = {_shown(list(overrides))}: unknown group(s) {', '.join(unknown)}; "
                    "expected keys under sim. or task.; fix: e.g. overrides=['task.max_steps=300']"
                )
            sim = merge(sim, data["sim"], "sim") if "sim" in data else sim
            task = merge(task, data["task"], "task") if "task" in data else task
        start = _start_pose(start)
        if scene is None and not episodes:
            raise ValueError("ObjectNavEnv needs scene=PATH_OR_ID (+ goal=CATEGORY) or episodes=[EpisodeSpec]")
        self.sim_cfg, self.task_cfg = sim, task
        self.render_mode = render_mode
        # A `Scene` object is kept here and looked up by its id (EpisodeSpec.scene is a string).
        self._scene_obj = scene if isinstance(scene, Scene) else None
        self._scene_arg = scene.scene_id if isinstance(scene, Scene) else scene
        self._goal_arg, self._start_arg = goal, start
        self._episodes = list(episodes or [])
        self._episode_cursor = 0
        self._world: World | None = None
        self._actuation = ActuationNoise.from_name(sim.noise.actuation, sim.noise.actuation_multiplier)
        odo = OdometryNoise(sim.noise.odometry_position_m, sim.noise.odometry_heading_deg)
        self._odometry = Odometry(odo if sim.noise.odometry else None, sim.noise.odometry_mode)
        self.observation_space = spaces.Dict(observation_spaces(sim, task))
        self.action_space = spaces.Discrete(6)
        self.spec_episode: EpisodeSpec | None = None
        self._has_episode = False  # False before the first reset and after a failed one

    def set_task(self, task: TaskConfig) -> None:
        """The task rules of the episodes started from now on (the one in progress keeps its own). Why: a
        training schedule changes a rule mid-run (evaluation's STOP rule for the last part of training,
        `ovon.env.sampler`); the observation layout must stay, so only rules may change."""
        validate(task, "task")
        if task.kind != self.task_cfg.kind or task.max_steps != self.task_cfg.max_steps:
            raise ValueError(
                f"set_task: kind {task.kind!r} / max_steps {task.max_steps} differ from this env's "
                f"({self.task_cfg.kind!r} / {self.task_cfg.max_steps}); fix: build a new env for another task"
            )
        self.task_cfg = task

    # -- episode set-up -------------------------------------------------------------------------
    def _world_for(self, scene: str) -> World:
        if self._world is None or self._world.key != scene:
            if self._world is not None:
                self._world.close()
            obj = self._scene_obj
            self._world = acquire_world(obj if obj is not None and obj.scene_id == scene else scene, self.sim_cfg)
        return self._world

    def _next_spec(self, options: dict | None) -> EpisodeSpec:
        if options and "episode" in options:
            return options["episode"]
        if self._episodes:
            spec = self._episodes[self._episode_cursor % len(self._episodes)]
            self._episode_cursor += 1
            return spec
        if self._goal_arg is None:
            raise ValueError("no goal: pass goal=CATEGORY or an episode in reset(options={'episode': ...})")
        start = self._start_arg
        return EpisodeSpec(
            episode_id="adhoc",
            scene=str(self._scene_arg),
            goal_category=self._goal_arg,
            start_position=None if start is None else np.array(start[:3], dtype=np.float64),
            start_yaw=None if start is None else math.radians(start[3]),
        )

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        if options is not None:
            _check_options(options)  # before the seed: a refused call changes nothing
        super().reset(seed=seed)
        self._has_episode = False
        spec = self._next_spec(options)
        if len(spec.goal_category) > MAX_GOAL_LEN:
            raise ValueError(f"goal text longer than {MAX_GOAL_LEN} characters: {spec.goal_category!r}")
        world = self._world_for(spec.scene)
        setup = prepare_episode(world, spec, self.np_random, self.task_cfg, self.sim_cfg.camera.hfov_deg)
        self._state, self._grid, self._field = setup.state, setup.grid, setup.goal_field
        self._viewpoints, self._tracker = setup.viewpoints, setup.tracker
        self._point_goal = setup.point_goal
        self._kin = Kinematics(self._grid, self.sim_cfg.agent, self._actuation, surface=navmesh_surface(world.nav))
        self.spec_episode = spec
        self._frame = self._render()
        self._tracker.reset(self._state.position, self._frame.semantic, self._state.yaw)
        odo = self._odometry.reset(self._state)
        self._has_episode = True
        return self._obs(odo), {"episode_id": spec.episode_id}

    # -- stepping -------------------------------------------------------------------------------
    def _render(self) -> Frame:
        eye = self._state.position + np.array([0.0, self.sim_cfg.camera.camera_height, 0.0])
        return self._world.renderer.render(eye, self._state.yaw, self._state.pitch)

    def _obs(self, odometry: np.ndarray, collided: bool = False) -> dict:
        cam = self.sim_cfg.camera
        depth = self._frame.depth
        depth = np.where(depth > 0, np.clip(depth, cam.min_depth, cam.max_depth), cam.max_depth)
        obs = {
            "depth": depth.astype(np.float32, copy=False),
            "odometry": odometry.astype(np.float32),
            "goal": self.spec_episode.goal_category,
            "collided": int(collided),
        }
        if cam.rgb:
            obs["rgb"] = self._frame.rgb
        if self.task_cfg.kind == "pointnav":  # from the odometry estimate, as a robot computes it
            from ovon.task.pointgoal import point_goal_vector

            obs["pointgoal"] = point_goal_vector(odometry, self._point_goal)
        return obs

    def _action_id(self, action: Any) -> int:
        """The action as an int, refused unless an integer of the action space. Gymnasium's `Discrete`
        takes a Python int, a numpy integer or a 0-d integer array (what `sample()` and a policy's
        `argmax().item()` give); `int(action)` would turn 1.7 into MOVE_FORWARD and "1" into an action."""
        value = action[()] if isinstance(action, np.ndarray) and action.ndim == 0 else action
        space = self.action_space
        if isinstance(value, int | np.integer) and not isinstance(value, bool):
            if space.start <= int(value) < space.start + space.n:
                return int(value)
        last = int(space.start) + int(space.n) - 1
        names = ", ".join(f"{int(space.start) + i}={n}" for i, n in enumerate(ACTION_NAMES))
        raise ValueError(
            f"action = {_shown(action)} ({type(action).__name__}): expected an integer in "
            f"{space.start}..{last} of action_space {space} ({names}); fix: pass a Python int, a "
            "numpy integer or a 0-d integer array, e.g. action_space.sample() or logits.argmax().item()"
        )

    def step(self, action):
        action = self._action_id(action)
        self._require_reset("step")
        if self._tracker.done:
            raise RuntimeError("step() after the episode ended: call reset()")
        result = self._kin.step(self._state, action, self.np_random)
        self._state = result.state
        self._frame = self._render()
        self._tracker.update(
            self._state.position, action == STOP, result.collided, self._frame.semantic, self._state.yaw
        )
        odo = self._odometry.update(self._state, self.np_random)
        reward = float(self._tracker.reward())
        terminated = self._tracker.called_stop  # a STOP, unless task.failed_stop_ends is false and it missed
        truncated = not terminated and self._tracker.steps >= self.task_cfg.max_steps
        info = {"episode_id": self.spec_episode.episode_id}
        if terminated or truncated:
            info["metrics"] = self._tracker.metrics().to_dict()
        return self._obs(odo, result.collided), reward, terminated, truncated, info

    def _require_reset(self, method: str) -> None:
        """Gymnasium's order (`ResetNeeded`): no episode state exists before the first reset."""
        if not self._has_episode:
            raise gym.error.ResetNeeded(
                f"{method}() without an episode: reset() was not called, or the last one "
                "failed; fix: call reset() (with a valid episode) first"
            )

    def render(self):
        self._require_reset("render")
        return self._frame.rgb

    def privileged(self) -> Privileged:
        """The one channel to ground truth (experts, oracles, failure analysis, recording)."""
        self._require_reset("privileged")
        return Privileged(
            self._state.copy(),
            self._grid,
            self._field,
            self._viewpoints,
            self._tracker.goal_ids,
            self._frame,
            self._world,
            float(self._tracker.distance),
            self.sim_cfg,
            self.task_cfg,
        )

    @property
    def tracker(self) -> EpisodeTracker:
        return self._tracker

    def close(self):
        if self._world is not None:
            self._world.close()
            self._world = None


def _check_options(options: Any) -> None:
    """reset(options=...): None or a dict of known keys; a misspelt key would silently start an ad-hoc
    episode instead of the one given."""
    if not isinstance(options, Mapping):
        raise ValueError(
            f"options = {_shown(options)}: expected None or a dict with keys from "
            f"{list(RESET_OPTIONS)}; fix: pass options={{'episode': EpisodeSpec(...)}} or leave it out"
        )
    unknown = sorted(map(str, set(options) - set(RESET_OPTIONS)))
    if unknown:
        raise ValueError(
            f"options = {_shown(dict(options))}: unknown key(s) {', '.join(map(repr, unknown))}, expected "
            f"keys from {list(RESET_OPTIONS)}; fix: pass options={{'episode': EpisodeSpec(...)}}"
        )
    if "episode" in options and not isinstance(options["episode"], EpisodeSpec):
        raise ValueError(
            f"options['episode'] = {_shown(options['episode'])}: expected an EpisodeSpec; fix: pass "
            "options={'episode': EpisodeSpec(...)} (e.g. one of ovon.dataset.io's episodes)"
        )


def observation_spaces(sim: SimConfig, task: TaskConfig | None = None) -> dict[str, spaces.Space]:
    """The plain env's observation spaces (RGB only when the camera renders it; PointNav adds the goal
    vector (rho, cos theta, sin theta) relative to the odometry pose)."""
    cam = sim.camera
    obs: dict[str, spaces.Space] = {
        "depth": spaces.Box(0.0, cam.max_depth, (cam.height, cam.width), np.float32),
        "odometry": spaces.Box(
            np.array([-ODOMETRY_LIMIT_M, -ODOMETRY_LIMIT_M, -math.pi], np.float32),
            np.array([ODOMETRY_LIMIT_M, ODOMETRY_LIMIT_M, math.pi], np.float32),
            (3,),
            np.float32,
        ),
        "goal": spaces.Text(MAX_GOAL_LEN, min_length=1, charset=GOAL_CHARSET),
        # 1 when the step that led here was blocked (a bump sensor; docs/spec.md#observations)
        "collided": spaces.Discrete(2),
    }
    if task is not None and task.kind == "pointnav":
        obs["pointgoal"] = spaces.Box(
            np.array([0.0, -1.0, -1.0], np.float32),
            np.array([2 * ODOMETRY_LIMIT_M, 1.0, 1.0], np.float32),
            (3,),
            np.float32,
        )
    if cam.rgb:
        obs = {"rgb": spaces.Box(0, 255, (cam.height, cam.width, 3), np.uint8), **obs}
    return obs
