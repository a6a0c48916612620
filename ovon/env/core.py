"""The Gymnasium environment: `gymnasium.make("ovon/ObjectNav-v0", scene=..., goal="couch")`.

Observations are what a real robot has (RGB, depth, odometry, goal text, a bump flag) and `info` holds
only the episode id (plus the episode's metrics once it has ended): nothing an agent could cheat with.
Ground truth (true pose, semantic frame, goal field, map) is reachable through ONE explicit channel,
`env.unwrapped.privileged()`, which the `PrivilegedObservation` wrapper (ovon.env.privileged) puts into
the observation of oracle agents, experts and oracle encoders.
"""

from __future__ import annotations

import math
import string
from dataclasses import dataclass

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from ovon.config.base import merge, parse_overrides
from ovon.config.sim import SimConfig
from ovon.config.task import TaskConfig
from ovon.scenes.model import Scene
from ovon.sim.agent import STOP, Kinematics, Odometry
from ovon.sim.noise import ActuationNoise, OdometryNoise
from ovon.sim.types import AgentState, Frame
from ovon.sim.world import World, acquire_world
from ovon.task.episode import EpisodeSpec, GoalViewpoint
from ovon.task.setup import prepare_episode
from ovon.task.tracker import EpisodeTracker

GOAL_CHARSET = string.ascii_letters + string.digits + " -_'/&().,"
MAX_GOAL_LEN = 64
ODOMETRY_LIMIT_M = 1000.0  # bound of the odometry Box (any building fits; check_env wants finite bounds)


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
    metadata = {"render_modes": ["rgb_array"], "render_fps": 10}

    def __init__(
        self,
        scene: str | Scene | None = None,
        goal: str | None = None,
        episodes: list[EpisodeSpec] | None = None,
        sim: SimConfig | None = None,
        task: TaskConfig | None = None,
        overrides: list[str] | tuple[str, ...] = (),
        start: tuple[float, float, float, float] | None = None,
        render_mode: str | None = "rgb_array",
    ):
        sim = sim or SimConfig()
        task = task or TaskConfig()
        if overrides:
            data = parse_overrides(list(overrides))
            sim = merge(sim, data.get("sim", {}), "sim") if "sim" in data else sim
            task = merge(task, data.get("task", {}), "task") if "task" in data else task
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
        super().reset(seed=seed)
        spec = self._next_spec(options)
        if len(spec.goal_category) > MAX_GOAL_LEN:
            raise ValueError(f"goal text longer than {MAX_GOAL_LEN} characters: {spec.goal_category!r}")
        world = self._world_for(spec.scene)
        setup = prepare_episode(world, spec, self.np_random, self.task_cfg, self.sim_cfg.camera.hfov_deg)
        self._state, self._grid, self._field = setup.state, setup.grid, setup.goal_field
        self._viewpoints, self._tracker = setup.viewpoints, setup.tracker
        self._point_goal = setup.point_goal
        self._kin = Kinematics(self._grid, self.sim_cfg.agent, self._actuation)
        self.spec_episode = spec
        self._frame = self._render()
        self._tracker.reset(self._state.position, self._frame.semantic, self._state.yaw)
        odo = self._odometry.reset(self._state)
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

    def step(self, action):
        action = int(action)
        if not self.action_space.contains(action):
            raise ValueError(f"action {action!r} is not in 0..5")
        if self._tracker.done:
            raise RuntimeError("step() after the episode ended: call reset()")
        result = self._kin.step(self._state, action, self.np_random)
        self._state = result.state
        self._frame = self._render()
        self._tracker.update(self._state.position, action == STOP, result.collided, self._frame.semantic,
                             self._state.yaw)
        odo = self._odometry.update(self._state, self.np_random)
        reward = float(self._tracker.reward())
        terminated = self._tracker.called_stop  # a STOP, unless task.failed_stop_ends is false and it missed
        truncated = not terminated and self._tracker.steps >= self.task_cfg.max_steps
        info = {"episode_id": self.spec_episode.episode_id}
        if terminated or truncated:
            info["metrics"] = self._tracker.metrics().to_dict()
        return self._obs(odo, result.collided), reward, terminated, truncated, info

    def render(self):
        return self._frame.rgb

    def privileged(self) -> Privileged:
        """The one channel to ground truth (experts, oracles, failure analysis, recording)."""
        return Privileged(
            self._state.copy(), self._grid, self._field, self._viewpoints,
            self._tracker.goal_ids, self._frame, self._world, float(self._tracker.distance),
            self.sim_cfg, self.task_cfg,
        )

    @property
    def tracker(self) -> EpisodeTracker:
        return self._tracker

    def close(self):
        if self._world is not None:
            self._world.close()
            self._world = None


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
        obs["pointgoal"] = spaces.Box(np.array([0.0, -1.0, -1.0], np.float32),
                                      np.array([2 * ODOMETRY_LIMIT_M, 1.0, 1.0], np.float32), (3,), np.float32)
    if cam.rgb:
        obs = {"rgb": spaces.Box(0, 255, (cam.height, cam.width, 3), np.uint8), **obs}
    return obs
