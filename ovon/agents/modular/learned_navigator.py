"""`navigator.kind=learned`: a PointNav policy trained by `ovon train --task pointnav` as the bee-lining
module of the modular agents (VLFM's PointNav policy; docs/spec.md#modular-baseline).

Inputs are what the policy trained on: the depth frame and bump flag through the checkpoint's own encoder,
and the goal vector (rho, cos theta, sin theta) of the request (`NavRequest.rho` / `.theta`, from odometry).
The caller decides when to stop: STOP within `stop_distance_m` of a goal point (as the geometric
navigator); the policy's own STOP is masked, because the caller's radius, not the training radius, ends
a modular episode, and a frontier is left by the caller. The policy's memory restarts when the target
moves more than `retarget_m` or changes kind. Actions are sampled (seeded per episode) unless
`deterministic`.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import torch

from ovon.agents.modular.config import NavigatorConfig
from ovon.agents.modular.maps import AgentMaps
from ovon.agents.modular.navigation import NavRequest
from ovon.agents.modular.sensors import Sensors
from ovon.sim.agent import STOP
from ovon.task.pointgoal import goal_vector


def load_pointnav_policy(checkpoint: str):
    """The PointNav `ActorCritic` of a policy.pt (or run folder); ValueError naming the file otherwise."""
    from ovon.models.policy import ActorCritic

    path = Path(checkpoint)
    path = path / "policy.pt" if path.is_dir() else path
    policy = ActorCritic.load(path).eval()
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

        del maps  # the policy has its own memory; it needs no map
        self.cfg = cfg
        self.policy, extra = load_pointnav_policy(cfg.checkpoint)
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

    def reset(self) -> None:
        self.gen = torch.Generator().manual_seed(0)  # the same draws in every episode, whatever the worker
        self.state = self.policy.init_state(1, "cpu")
        self.prev = torch.full((1,), -1, dtype=torch.long)
        self.first = True
        self.target: tuple[float, float] | None = None
        self.kind = ""

    @torch.no_grad()
    def act(self, observation: dict, request: NavRequest) -> int | None:
        if request.kind == "goal" and request.rho < self.cfg.stop_distance_m:
            return STOP
        t = request.target
        if self.target is None or request.kind != self.kind or math.dist(t, self.target) > self.cfg.retarget_m:
            self.state = self.policy.init_state(1, "cpu")
            self.prev = torch.full((1,), -1, dtype=torch.long)
            self.first = True
        self.target, self.kind = (float(t[0]), float(t[1])), request.kind
        batch = {
            "depth": np.asarray(observation["depth"], np.float32)[None],
            "collided": np.array([int(observation.get("collided", 0))]),
        }
        image = self.encoder.encode(batch).float()
        goal = torch.from_numpy(goal_vector(request.rho, request.theta))[None]
        obs = self.policy.make_obs(image, goal)
        logits, _, self.state = self.policy.act_step(obs, self.prev, self.state, torch.tensor([self.first]))
        logits = logits[0].clone()
        logits[STOP] = -math.inf
        if self.cfg.deterministic:
            action = int(logits.argmax().item())
        else:
            action = int(torch.multinomial(torch.softmax(logits.float(), -1), 1, generator=self.gen).item())
        self.prev = torch.tensor([action])
        self.first = False
        return action
