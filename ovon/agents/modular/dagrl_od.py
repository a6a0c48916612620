"""`--agent dagrl-od --checkpoint POLICY`: DAgRL+OD (docs/spec.md#dagrl-od): the end-to-end policy explores until
the detector fires on the goal text; from then on the bee-lining module (the one VLFM uses) drives to the
nearest lifted goal point and STOPs, for the rest of the episode.

The agent builds its own maps from the first step (bee-lining needs them when the detector fires) and
tracks the camera pitch from the policy's LOOK actions for the back-projection. It is privileged when the
policy uses oracle perception (oracle-vl) or the detector is the oracle; its row name says which.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ovon.agents.modular.config import DAgRLODConfig, modular_config
from ovon.agents.modular.core import ModularCore
from ovon.agents.modular.debug import draw_beliefs


def describe_dagrl_od(cfg: DAgRLODConfig, policy_perception: str | None = None) -> str:
    from ovon.models.detectors import describe_detector

    parts = ["DAgRL+OD"]
    if policy_perception:
        parts.append(f"policy: {policy_perception}")
    parts.append(describe_detector(cfg.detector))
    if cfg.navigator.kind != "geometric":
        parts.append(f"{cfg.navigator.kind} navigator")
    return ", ".join(parts)


class DAgRLODAgent:
    def __init__(self, checkpoint: str = "", preset: str = "cpu", **overrides: Any) -> None:
        if checkpoint:
            overrides["checkpoint"] = checkpoint
        self.cfg = modular_config(DAgRLODConfig, preset, overrides)
        if not self.cfg.checkpoint:
            raise ValueError("dagrl-od needs a policy: pass --checkpoint POLICY (a policy.pt written by ovon train)")
        from ovon.agents.policy_agent import PolicyAgent

        self.policy = PolicyAgent(
            self.cfg.checkpoint,
            deterministic=self.cfg.deterministic,
            threads=self.cfg.threads,
            temperature=self.cfg.temperature,
        )
        self.core = ModularCore(self.cfg, self.policy.text)
        self.privileged = bool(self.policy.privileged) or self.core.privileged
        perception = "oracle perception" if self.policy.privileged else self.policy.encoder_cfg.image
        self.name = describe_dagrl_od(self.cfg, perception)
        self.beelining = False
        self.switch_step: int | None = None
        self.step = 0

    @staticmethod
    def resolved_config(**kwargs: Any) -> DAgRLODConfig:
        """The config the constructor builds from these arguments, the checkpoint aside (the experiment
        runner records it, so a preset changed in code makes a finished evaluation stale)."""
        kwargs.pop("checkpoint", None)
        preset = kwargs.pop("preset", "cpu")
        return modular_config(DAgRLODConfig, preset, kwargs)

    @staticmethod
    def describe(**kwargs: Any) -> str:
        return describe_dagrl_od(DAgRLODAgent.resolved_config(**kwargs))

    def reset(self, episode_info: dict) -> None:
        self.policy.reset(episode_info)
        self.core.reset(episode_info)
        self.beelining = False
        self.switch_step = None
        self.step = 0

    def act(self, observation: dict) -> int:
        core = self.core
        if core.maps is None:
            self.reset({})
        on_map = core.observe(observation)
        self.step += 1
        if not self.beelining and core.detected and on_map:
            self.beelining = True
            self.switch_step = self.step
        if self.beelining and on_map:
            action = core.beeline(observation)
            if action is not None:
                return core.record(action)
        # before the detector fired, or the goal cannot be reached on the agent's map: the policy acts
        return core.record(int(self.policy.act(observation)))

    def debug_frame(self, size: int = 240) -> np.ndarray | None:
        """What the agent believes now (`ovon video`): its maps, goal points and plan (no value map)."""
        if self.core.maps is None:
            return None
        who = "bee-lining" if self.beelining else "policy"
        return draw_beliefs(self.core, size, title=f"DAgRL+OD: {who}")
