"""A trained policy as an evaluation agent (`ovon evaluate --agent policy --checkpoint PATH`).

Loads an `ActorCritic` checkpoint (`policy.pt` written by `ovon train`, or a run folder holding one),
rebuilds its perception encoders from the stored encoder config and acts with `act_step` (KV cache /
LSTM state, reset at each episode). The goal-text table saved with the policy is reused, so the goal
embeddings match training; unseen texts go to the real text encoder. A PointNav policy (trained with
`--task pointnav`) takes the env's goal vector `observation["pointgoal"]` instead.

With the oracle-vl encoder the agent is privileged: it reads the semantic frame and the scene's
instance -> category map through `observation["privileged"]` (ORACLE PERCEPTION).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from ovon.config.base import Pattern, constrained, non_negative, positive, validate, values_from_option
from ovon.models.encoders import encode_observation


@dataclass(frozen=True)
class PolicyAgentArgs:
    """The settings of `PolicyAgent` (`--agent-arg KEY=VALUE`) with their domains, checked before the
    checkpoint is read. Why: `temperature <= 0` let nan through (softmax of nan: every action sampled from
    garbage, or a JSON error naming no key), and any non-empty string counted as `deterministic`."""

    deterministic: bool = True
    device: str = constrained("cpu", Pattern(r"cpu|cuda(:[0-9]+)?|mps", "cpu, cuda, cuda:N or mps"))
    threads: int = non_negative(1)  # 0: leave torch's default
    # None: the temperature the checkpoint says the policy acted at in training (1 for checkpoints without it)
    temperature: float | None = positive(None)


class PolicyAgent:
    def __init__(
        self,
        checkpoint: str,
        deterministic: bool = True,
        device: str | torch.device = "cpu",
        threads: int = 1,
        temperature: float | None = None,
    ) -> None:
        """`deterministic`: argmax actions; else sample from softmax(logits / temperature) with a generator
        seeded per episode (reproducible). Argmax can lock an imitation policy into a turn-left /
        turn-right cycle; sampling breaks it, and a temperature < 1 keeps rare actions (STOP) rare.
        `temperature` None: the one the checkpoint records as its training's (`acting_temperature`), so a
        PPO policy is scored at the temperature it was optimised at."""
        from ovon.models.config import EncoderConfig
        from ovon.models.encoders import TableTextEncoder
        from ovon.models.policy import ActorCritic

        if isinstance(device, torch.device):  # what torch code passes; the option's domain is its str
            device = str(device)
        with values_from_option("--agent-arg"):  # a real bool, a finite temperature > 0, ...: one line each
            validate(PolicyAgentArgs(deterministic, device, threads, temperature))
        if threads > 0:
            torch.set_num_threads(threads)
        path = Path(checkpoint)
        if path.is_dir():
            path = path / "policy.pt"
        self.policy = ActorCritic.load(path, map_location=device, flag="checkpoint").eval()
        self.device = torch.device(device)
        self.deterministic = deterministic
        self.encoder_cfg = self.policy.encoder_cfg or EncoderConfig()
        extra = getattr(self.policy, "checkpoint_extra", {}) or {}
        self.temperature = float(extra.get("acting_temperature", 1.0) if temperature is None else temperature)
        self.text = TableTextEncoder(extra.get("text_table", {}), self.encoder_cfg)
        self.image_encoder = None
        if self.encoder_cfg.image != "cnn":
            from ovon.models.encoders import make_image_encoder

            self.image_encoder = make_image_encoder(self.encoder_cfg, self.text)
        self.privileged = self.encoder_cfg.image == "oracle-vl"
        self.pointnav = (extra.get("task") or {}).get("kind") == "pointnav"
        self._gen = torch.Generator().manual_seed(0)
        self._scene_set = False
        self._state = None
        self._prev = torch.full((1,), -1, dtype=torch.long)
        self._first = True

    def reset(self, episode_info: dict) -> None:
        self._state = self.policy.init_state(1, self.device)
        self._prev = torch.full((1,), -1, dtype=torch.long, device=self.device)
        self._first = True
        self._scene_set = False
        self._gen.manual_seed(int(episode_info.get("seed", 0)))
        if self.image_encoder is not None and hasattr(self.image_encoder, "reseed"):
            self.image_encoder.reseed(int(episode_info.get("seed", 0)))

    def _image(self, observation: dict) -> torch.Tensor | dict[str, torch.Tensor]:
        """The image input of one step: frames for the policy's own CNN, else the frozen encoder's embedding."""
        if self.image_encoder is None:
            return {
                "rgb": torch.from_numpy(np.ascontiguousarray(observation["rgb"]))[None].to(self.device),
                "depth": torch.from_numpy(np.asarray(observation["depth"], np.float32))[None].to(self.device),
            }
        semantic = None
        if self.privileged:
            p = observation["privileged"]
            if not self._scene_set:
                self.image_encoder.set_scene({o.id: o.category for o in p.world.scene.objects if o.category})
                self._scene_set = True
            semantic = p.frame.semantic
        return torch.from_numpy(encode_observation(self.image_encoder, observation, semantic))[None].to(self.device)

    @torch.no_grad()
    def act(self, observation: dict) -> int:
        if self._state is None:
            self.reset({})
        if self.pointnav:
            if "pointgoal" not in observation:
                raise ValueError(
                    "this is a PointNav policy: it needs observation['pointgoal'] (an env with "
                    "task.kind=pointnav, e.g. `ovon evaluate --task pointnav`)"
                )
            goal = torch.as_tensor(np.asarray(observation["pointgoal"], np.float32))[None].to(self.device)
        else:
            goal = self.text.encode([observation["goal"]]).to(self.device)
        obs = self.policy.embed(self._image(observation), goal)
        first = torch.tensor([self._first], device=self.device)
        logits, _, self._state = self.policy.act_step(obs, self._prev, self._state, first)
        if self.deterministic:
            action = int(logits.argmax(-1).item())
        else:
            probs = torch.softmax(logits.float() / self.temperature, -1).cpu()
            action = int(torch.multinomial(probs, 1, generator=self._gen).item())
        self._prev = torch.tensor([action], device=self.device)
        self._first = False
        return action
