"""`--agent vlfm`: the VLFM-style modular baseline (docs/spec.md#modular-baseline and #vlfm).

Episode: 12 TURN_LEFT (a full turn) -> explore the frontier with the highest language value, driven to
by the point-goal navigator -> once the detector fires, bee-line to the nearest lifted goal point and STOP
within the stop distance; STOP when no frontier is left or the agent leaves its map. Never LOOK_UP/DOWN.

Privileged data: only the oracle detector (semantic frame + instance categories) and the oracle-vl scorer
(oracle perception) read `observation["privileged"]`; with `detector.kind=owlv2` and `value.scorer.kind=
siglip` (the `paper` preset) the agent uses RGB, depth and odometry only. Its row name says which:
"VLFM, oracle detection, oracle-vl value".
"""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np

from ovon.agents.modular.config import VLFMConfig, modular_config
from ovon.agents.modular.core import ModularCore, info_seed
from ovon.agents.modular.debug import draw_beliefs
from ovon.agents.modular.frontier_choice import FrontierChooser
from ovon.agents.modular.value_map import ValueMap
from ovon.models.scorers import describe_scorer, make_scorer
from ovon.sim.agent import STOP, TURN_LEFT


def describe_vlfm(cfg: VLFMConfig) -> str:
    from ovon.models.detectors import describe_detector

    name = f"VLFM, {describe_detector(cfg.detector)}, {describe_scorer(cfg.value.scorer)}"
    if cfg.navigator.kind != "geometric":
        name += f", {cfg.navigator.kind} navigator"
    return name


class VLFMAgent:
    """`VLFMAgent(preset="cpu", **overrides)`; overrides are dotted config keys, e.g.
    `VLFMAgent(**{"detector": "noisy", "value.scorer.kind": "constant"})` (see `VLFMConfig`)."""

    def __init__(self, preset: str = "cpu", **overrides: Any) -> None:
        self.cfg = modular_config(VLFMConfig, preset, overrides)
        self.core = ModularCore(self.cfg)
        self.scorer = make_scorer(self.cfg.value.scorer)
        self.privileged = self.core.privileged or bool(self.scorer.privileged)
        self.name = describe_vlfm(self.cfg)
        self.value_map: ValueMap | None = None
        self.chooser: FrontierChooser | None = None
        self.mode = "idle"
        self.step = 0
        self.timing: dict[str, float] = {}  # ms of the last step per phase (benchmarks/vlfm_step.py)

    @staticmethod
    def resolved_config(**kwargs: Any) -> VLFMConfig:
        """The config the constructor builds from these arguments (the experiment runner records it, so a
        preset changed in code makes a finished evaluation stale)."""
        preset = kwargs.pop("preset", "cpu")
        return modular_config(VLFMConfig, preset, kwargs)

    @staticmethod
    def describe(**kwargs: Any) -> str:
        """Row name for reports, from the constructor arguments."""
        return describe_vlfm(VLFMAgent.resolved_config(**kwargs))

    def reset(self, episode_info: dict) -> None:
        core = self.core
        maps_before = core.maps
        core.reset(episode_info)
        assert core.maps is not None
        if core.maps is not maps_before or self.value_map is None:
            self.value_map = ValueMap(self.cfg.value, core.maps)
            self.chooser = FrontierChooser(self.cfg.value, core.maps.cell_size)
        assert self.value_map is not None and self.chooser is not None
        self.value_map.reset()
        self.chooser.reset()
        self.scorer.reset(info_seed(episode_info))
        self.step = 0
        self.mode = "spin"
        self._progress_target = -1
        self._progress_best = math.inf
        self._progress_age = 0

    def act(self, observation: dict) -> int:
        t0 = time.perf_counter()
        action = self._act(observation)
        t3 = time.perf_counter()
        self.timing["total"] = (t3 - t0) * 1e3
        self.timing["decide"] = self.timing["total"] - sum(self.timing.get(k, 0.0) for k in ("maps", "detect", "value"))
        return action

    def _act(self, observation: dict) -> int:
        core = self.core
        if core.maps is None:
            self.reset({})
        self.timing = {}
        if not core.observe(observation):
            self.mode = "off_map"
            return core.record(STOP)
        self.timing.update(core.timing)
        assert self.value_map is not None
        t = time.perf_counter()
        score = self.scorer.score(observation, str(observation["goal"]))
        self.value_map.update(score, core.pose)
        self.timing["value"] = (time.perf_counter() - t) * 1e3
        self.step += 1
        if self.step <= self.cfg.spin_steps:
            self.mode = "spin"
            return core.record(TURN_LEFT)
        if core.goal_point() is not None:
            action = core.beeline(observation)
            if action is not None:
                self.mode = "navigate"
                return core.record(action)
        return core.record(self._explore(observation))

    def debug_frame(self, size: int = 240) -> np.ndarray | None:
        """What the agent believes now (`ovon video`): its maps, frontiers, goal points, plan and value map."""
        if self.core.maps is None or self.value_map is None:
            return None
        target = self.chooser.target if self.chooser is not None and self.mode == "explore" else None
        return draw_beliefs(self.core, size, self.value_map, target, f"VLFM: {self.mode}")

    # -- exploration ----------------------------------------------------------------------------
    def _stuck(self, target: int, dist: float) -> bool:
        """No progress toward the same frontier (0.1 m better than the best so far) for stuck_steps."""
        if target != self._progress_target:
            self._progress_target, self._progress_best, self._progress_age = target, dist, 0
            return False
        if dist < self._progress_best - 0.1:
            self._progress_best, self._progress_age = dist, 0
            return False
        self._progress_age += 1
        return self._progress_age > self.cfg.stuck_steps

    def _explore(self, observation: dict) -> int:
        core = self.core
        maps, vm, chooser = core.maps, self.value_map, self.chooser
        assert maps is not None and vm is not None and chooser is not None
        pose = core.pose
        agent = maps.cell(pose.x, pose.z)
        for _ in range(self.cfg.max_choices_per_step):
            fr = maps.frontiers()
            if len(fr) == 0:
                self.mode = "no_frontier"
                return STOP
            values = vm.frontier_values(fr.rows, fr.cols)
            i = chooser.choose(fr.rows, fr.cols, values, agent)
            if i is None:
                self.mode = "no_frontier"
                return STOP
            target_cell = (int(fr.rows[i]), int(fr.cols[i]))
            target = maps.cell_centre(*target_cell)
            dist = math.hypot(target[0] - pose.x, target[1] - pose.z)
            if dist < self.cfg.frontier_reached_m or self._stuck(chooser.choices, dist):
                chooser.drop_target(blacklist=True)  # reached but still a frontier, or no progress
                continue
            action = core.navigate_to(observation, target)
            if action is None:
                chooser.drop_target(blacklist=True)  # unreachable on the agent's map
                continue
            self.mode = "explore"
            return action
        self.mode = "look_around"
        return TURN_LEFT
