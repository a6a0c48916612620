"""`navigator.kind=learned`: a PointNav policy trained by `ovon train --task pointnav` as the bee-lining
module of the modular agents (VLFM's PointNav policy; docs/spec.md#modular-baseline).

Inputs are what the policy trained on: the depth frame and bump flag through the checkpoint's own encoder,
and the goal vector (rho, cos theta, sin theta) of a point from odometry. That point is the target itself
when the route to it on the agent's map (the geometric navigator's A*) is at most `subgoal_m` long, else
the point `subgoal_m` along that route: the policy trained on point goals 1-6 m away (geodesic) and a goal
vector does not say where the walls are, so a frontier 8-10 m away behind a wall had it bump into the wall
until the step limit. For a goal point the route ends at the nearest free cell within the stop distance
(the goal point usually lies on the object). No route: None (the caller picks another target), as the
geometric navigator.

The caller decides when to stop: within `stop_distance_m + handover_m` of a goal point the geometric
navigator takes the final approach (STOP within `stop_distance_m`, its settle rule); the policy's own STOP
is masked, because the caller's radius, not the training radius, ends a modular episode, and a frontier is
left by the caller. When the policy is stuck (under one forward step of motion over `stuck_steps` steps,
with a bump) the geometric navigator drives the next `stuck_steps` steps. The policy's memory restarts
when its point moves more than `retarget_m` or the target changes kind. Actions are sampled (seeded by the
episode's seed, so a run repeats and evaluation seeds vary the draws) unless `deterministic`.
"""

from __future__ import annotations

import math
from collections import deque
from pathlib import Path

import numpy as np
import torch

from ovon.agents.modular.config import NavigatorConfig
from ovon.agents.modular.maps import AgentMaps
from ovon.agents.modular.navigation import GeometricNavigator, NavRequest
from ovon.agents.modular.sensors import Sensors
from ovon.sim.agent import MOVE_FORWARD, STOP
from ovon.task.pointgoal import goal_vector


def load_pointnav_policy(checkpoint: str):
    """The PointNav `ActorCritic` of a policy.pt (or run folder); ValueError naming the file otherwise."""
    from ovon.models.policy import ActorCritic

    path = Path(checkpoint)
    path = path / "policy.pt" if path.is_dir() else path
    policy = ActorCritic.load(path, flag="navigator.checkpoint").eval()
    extra = getattr(policy, "checkpoint_extra", {}) or {}
    if (extra.get("task") or {}).get("kind") != "pointnav":
        raise ValueError(
            f"navigator.checkpoint = {checkpoint!r} is not a PointNav policy; fix: pass the policy.pt "
            "of `ovon train --task pointnav`"
        )
    return policy, extra


class LearnedNavigator:
    name = "learned"

    def __init__(self, cfg: NavigatorConfig, maps: AgentMaps, sensors: Sensors) -> None:
        from ovon.models.encoders import make_image_encoder

        self.cfg = cfg
        self.maps = maps
        self.planner = GeometricNavigator(cfg, maps, sensors)  # the route to far targets; the final approach
        self.policy, extra = load_pointnav_policy(cfg.checkpoint)
        task = extra.get("task") or {}
        self.subgoal_m = cfg.subgoal_m or float(task.get("point_max_distance_m") or 6.0)
        self.encoder = make_image_encoder(self.policy.encoder_cfg)
        cam = extra.get("camera") or {}
        hfov, w, h = cam.get("hfov_deg"), cam.get("width"), cam.get("height")
        have = sensors.camera
        if hfov is not None and (
            abs(float(hfov) - have.hfov_deg) > 1e-3 or abs(w / h - have.width / have.height) > 0.02 * (w / h)
        ):
            raise ValueError(
                f"navigator.checkpoint {cfg.checkpoint!r} was trained with a {w}x{h} camera of "
                f"{hfov} deg HFOV; this episode's camera is {have.width}x{have.height}, "
                f"{have.hfov_deg} deg; fix: evaluate with the same HFOV and aspect ratio "
                "(e.g. --set sim.camera.width=W --set sim.camera.height=H)"
            )
        self.reset()

    def reset(self, seed: int = 0) -> None:
        self.planner.reset(seed)
        self.gen = torch.Generator().manual_seed(seed)  # the episode's draws, whatever the worker
        self.state = self.policy.init_state(1, "cpu")
        self.prev = torch.full((1,), -1, dtype=torch.long)
        self.first = True
        self.target: tuple[float, float] | None = None  # the point the policy heads for
        self.aim: tuple[float, float] | None = None  # the request's target when `target` was chosen
        self.kind = ""
        self.recent: deque[tuple[float, float, bool]] = deque(maxlen=max(1, self.cfg.stuck_steps))  # (x, z, bumped)
        self.rescue = 0  # steps the geometric navigator still drives after the policy got stuck

    def stuck(self, request: NavRequest, bumped: bool) -> bool:
        """Less than one forward step of motion over the last `stuck_steps` policy steps, with a bump."""
        n = self.cfg.stuck_steps
        if n == 0:
            return False
        self.recent.append((request.pose.x, request.pose.z, bumped))
        if len(self.recent) < n or not any(b for _, _, b in self.recent):
            return False
        x0, z0, _ = self.recent[0]
        return all(math.hypot(x - x0, z - z0) < self.planner.steering.step for x, z, _ in self.recent)

    def subgoal(self, request: NavRequest) -> tuple[float, float] | None:
        """The point the policy heads for: the target, or the point `subgoal_m` along the route to it."""
        path = self.planner.route(request)
        if path is None:
            return None
        pr, pc = path
        steps = np.hypot(np.diff(pr), np.diff(pc)) * self.maps.cell_size
        along = np.concatenate([[0.0], np.cumsum(steps)])
        if along[-1] <= self.subgoal_m and request.kind == "frontier":
            return request.target
        k = int(np.searchsorted(along, self.subgoal_m, side="right")) - 1
        return self.maps.cell_centre(int(pr[k]), int(pc[k]))

    def _geometric(self, observation: dict, request: NavRequest, then: int) -> int | None:
        """The geometric navigator takes this step and the `then` steps after it; the policy restarts with a
        fresh memory afterwards."""
        self.rescue, self.target = then, None
        self.recent.clear()
        return self.planner.act(observation, request)

    @torch.no_grad()
    def act(self, observation: dict, request: NavRequest) -> int | None:
        if request.kind == "goal" and request.rho < self.cfg.stop_distance_m + self.cfg.handover_m:
            if self.cfg.handover_m > 0:  # the policy starts afresh should the agent leave the final approach
                return self._geometric(observation, request, then=0)
            if request.rho < self.cfg.stop_distance_m:
                return STOP
        bumped = bool(observation.get("collided", 0))
        if self.rescue == 0 and self.stuck(request, bumped):
            return self._geometric(observation, request, then=self.cfg.stuck_steps - 1)
        if self.rescue > 0:
            return self._geometric(observation, request, then=self.rescue - 1)
        t = self.subgoal(request)
        if t is None:
            return None
        keep = self.cfg.waypoint_keep_m
        if (
            keep > 0
            and self.target is not None
            and request.kind == self.kind
            and self.aim is not None
            and math.dist(request.target, self.aim) <= self.cfg.retarget_m
            and math.hypot(self.target[0] - request.pose.x, self.target[1] - request.pose.z) > keep
        ):
            t = self.target
        else:
            self.aim = (float(request.target[0]), float(request.target[1]))
        if self.target is None or request.kind != self.kind or math.dist(t, self.target) > self.cfg.retarget_m:
            self.state = self.policy.init_state(1, "cpu")
            self.prev = torch.full((1,), -1, dtype=torch.long)
            self.first = True
        self.target, self.kind = (float(t[0]), float(t[1])), request.kind
        point = NavRequest(request.pose, self.target, request.kind, request.maps)
        batch = {
            "depth": np.asarray(observation["depth"], np.float32)[None],
            "collided": np.array([int(bumped)]),
        }
        image = self.encoder.encode(batch).float()
        goal = torch.from_numpy(goal_vector(point.rho, point.theta))[None]
        obs = self.policy.embed(image, goal)
        logits, _, self.state = self.policy.act_step(obs, self.prev, self.state, torch.tensor([self.first]))
        logits = logits[0].clone()
        logits[STOP] = -math.inf
        if self.cfg.deterministic:
            action = int(logits.argmax().item())
        else:
            action = int(torch.multinomial(torch.softmax(logits.float(), -1), 1, generator=self.gen).item())
        self.prev = torch.tensor([action])
        self.first = False
        if (
            action == MOVE_FORWARD
            and self.cfg.map_checked_forward
            and self.planner.on_map(request.pose)
            and not self.planner.steering.free(request.pose.position, request.pose.yaw)
        ):
            # as when stuck: the geometric navigator drives `stuck_steps` steps (its detour, then the route)
            return self._geometric(observation, request, then=max(0, self.cfg.stuck_steps - 1))
        return action
