"""The Gymnasium environment: `gymnasium.make("ovon/ObjectNav-v0", scene=..., goal="couch")`.

Observations are what a real robot has (RGB, depth, odometry, goal text); the semantic frame is only
added with `privileged=True`. Experts and oracles reach ground truth through `env.unwrapped.privileged()`,
an explicit call that a non-oracle agent has no reason to make.
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
from ovon.sim.world import World, build_world
from ovon.task.episode import EpisodeSpec, GoalViewpoint
from ovon.task.goals import distractors, goal_instances, points_near_objects
from ovon.task.tracker import EpisodeTracker

GOAL_CHARSET = string.ascii_letters + string.digits + " -_'/&().,"
MAX_GOAL_LEN = 64
ODOMETRY_LIMIT_M = 1000.0  # bound of the odometry Box (any building fits; check_env wants finite bounds)


@dataclass
class Privileged:
    """Ground truth for experts, oracles, dataset tools and failure analysis."""

    state: AgentState
    grid: object  # NavGrid of the episode's floor
    goal_field: object  # DistanceField to all goal viewpoints
    viewpoints: list[GoalViewpoint]
    goal_ids: frozenset[int]
    frame: Frame
    world: World


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
        privileged: bool = False,
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
        self.privileged_obs = privileged
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
        self._odometry = Odometry(odo if sim.noise.odometry else None)
        cam = sim.camera
        obs = {
            "rgb": spaces.Box(0, 255, (cam.height, cam.width, 3), np.uint8),
            "depth": spaces.Box(0.0, cam.max_depth, (cam.height, cam.width), np.float32),
            "odometry": spaces.Box(
                np.array([-ODOMETRY_LIMIT_M, -ODOMETRY_LIMIT_M, -math.pi], np.float32),
                np.array([ODOMETRY_LIMIT_M, ODOMETRY_LIMIT_M, math.pi], np.float32),
                (3,),
                np.float32,
            ),
            "goal": spaces.Text(MAX_GOAL_LEN, min_length=1, charset=GOAL_CHARSET),
            # 1 when the step that led here was blocked (a bump sensor; task.md reports it each step)
            "collided": spaces.Discrete(2),
        }
        if privileged:
            obs["semantic"] = spaces.Box(0, np.iinfo(np.int32).max, (cam.height, cam.width), np.int32)
        self.observation_space = spaces.Dict(obs)
        self.action_space = spaces.Discrete(6)
        self.spec_episode: EpisodeSpec | None = None

    # -- episode set-up -------------------------------------------------------------------------
    def _world_for(self, scene: str) -> World:
        if self._world is None or self._world.key != scene:
            if self._world is not None:
                self._world.close()
            obj = self._scene_obj
            self._world = build_world(obj if obj is not None and obj.scene_id == scene else scene, self.sim_cfg)
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
        start = None if self._start_arg is None else self._start_arg
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
        objs = goal_instances(world.scene, spec)
        rng = self.np_random
        if spec.start_position is not None:
            start_pos = np.asarray(spec.start_position, dtype=np.float64)
            grids = [world.nav.grid_for(start_pos)]
        else:
            # Random start: on the floor of a random viewpoint / goal object (a seeded choice).
            start_pos = None
            anchors = [v.position for v in spec.viewpoints] or [o.aabb_min for o in objs]
            order = rng.permutation(len(anchors))
            grids = []
            for i in order:
                g = world.nav.grid_for(anchors[int(i)])
                if all(g is not h for h in grids):
                    grids.append(g)
        grid, points = grids[0], np.zeros((0, 3))
        if spec.viewpoints:
            viewpoints = spec.viewpoints
            points = np.stack([v.position for v in viewpoints])
        else:
            for grid in grids:
                points = points_near_objects(grid, [o for o in objs if world.nav.grid_for(o.aabb_min) is grid])
                if len(points):
                    break
            if len(points) == 0:
                raise ValueError(f"no navigable point within 1 m of any {spec.goal_category!r} on its floor")
            viewpoints = [GoalViewpoint(p, 0.0) for p in points]
        from ovon.sim.geodesic import distance_field

        field = distance_field(grid, points)
        if start_pos is None:
            start_pos = self._random_reachable_start(grid, field, rng)
        yaw = spec.start_yaw if spec.start_yaw is not None else float(rng.uniform(-math.pi, math.pi))
        self._state = AgentState(np.array(start_pos, dtype=np.float64), float(yaw), 0.0)
        self._grid, self._field, self._viewpoints = grid, field, viewpoints
        self._kin = Kinematics(grid, self.sim_cfg.agent, self._actuation)
        goal_ids = frozenset(o.id for o in objs)
        self._tracker = EpisodeTracker(
            distance_fn=field.distance,
            goal_ids=goal_ids,
            cfg=self.task_cfg,
            distractors=distractors(world.scene, spec.goal_categories),
        )
        self.spec_episode = spec
        self._frame = self._render()
        self._tracker.reset(self._state.position, self._frame.semantic)
        odo = self._odometry.reset(self._state)
        return self._obs(odo), self._info()

    def _random_reachable_start(self, grid, field, rng) -> np.ndarray:
        for _ in range(1000):
            p = grid.random_point(rng)
            d = field.distance(p)
            if math.isfinite(d) and d > self.task_cfg.success_distance:
                return p
        raise ValueError("could not find a navigable start connected to the goal in 1000 tries")

    # -- stepping -------------------------------------------------------------------------------
    def _render(self) -> Frame:
        eye = self._state.position + np.array([0.0, self.sim_cfg.camera.camera_height, 0.0])
        return self._world.renderer.render(eye, self._state.yaw, self._state.pitch)

    def _obs(self, odometry: np.ndarray, collided: bool = False) -> dict:
        cam = self.sim_cfg.camera
        depth = self._frame.depth
        depth = np.where(depth > 0, np.clip(depth, cam.min_depth, cam.max_depth), cam.max_depth)
        obs = {
            "rgb": self._frame.rgb,
            "depth": depth.astype(np.float32, copy=False),
            "odometry": odometry.astype(np.float32),
            "goal": self.spec_episode.goal_category,
            "collided": int(collided),
        }
        if self.privileged_obs:
            obs["semantic"] = self._frame.semantic
        return obs

    def _info(self) -> dict:
        t = self._tracker
        return {
            "position": self._state.position.copy(),
            "yaw": self._state.yaw,
            "pitch": self._state.pitch,
            "distance_to_goal": t.distance,
            "collided": False,
            "episode_id": self.spec_episode.episode_id,
        }

    def step(self, action):
        action = int(action)
        if not self.action_space.contains(action):
            raise ValueError(f"action {action!r} is not in 0..5")
        if self._tracker.done:
            raise RuntimeError("step() after the episode ended: call reset()")
        result = self._kin.step(self._state, action, self.np_random)
        self._state = result.state
        self._frame = self._render()
        self._tracker.update(self._state.position, action == STOP, result.collided, self._frame.semantic)
        odo = self._odometry.update(self._state, self.np_random)
        reward = float(self._tracker.reward())
        terminated = action == STOP
        truncated = not terminated and self._tracker.steps >= self.task_cfg.max_steps
        info = self._info()
        info["collided"] = result.collided
        if terminated or truncated:
            info["metrics"] = self._tracker.metrics().to_dict()
        return self._obs(odo, result.collided), reward, terminated, truncated, info

    def render(self):
        return self._frame.rgb

    def privileged(self) -> Privileged:
        return Privileged(
            self._state.copy(), self._grid, self._field, self._viewpoints,
            self._tracker.goal_ids, self._frame, self._world,
        )

    @property
    def tracker(self) -> EpisodeTracker:
        return self._tracker

    def close(self):
        if self._world is not None:
            self._world.close()
            self._world = None
