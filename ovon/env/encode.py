"""Observation encoding as a wrapper: frames -> frozen-encoder embedding, goal text -> its embedding.

Why in the env (and so in the env's worker process): frozen encoders (oracle-vl, SigLIP) then run next
to the renderer, in parallel over workers, and only a small vector crosses to the learner. A trainable
CNN cannot run there: with `encoder.image == "cnn"` the frames pass through for the policy to encode.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from ovon.env.privileged import KEY as PRIVILEGED
from ovon.env.privileged import privileged_of
from ovon.models.config import EncoderConfig
from ovon.models.encoders import TableTextEncoder, encode_observation, make_image_encoder

IMAGE, GOAL = "image", "goal_emb"


@dataclass
class PendingImage:
    """An image embedding not computed yet: a vector env worker encodes the frames of all its envs in one
    batch (`resolve_pending`) instead of one forward pass per env."""

    encoder: Any
    inputs: dict[str, Any]


def resolve_pending(observations: list[dict]) -> None:
    """Replace every `PendingImage` by its embedding, one `encode` call per group of equivalent encoders."""
    groups: dict[Any, list[dict]] = {}
    for obs in observations:
        pending = obs.get(IMAGE)
        if isinstance(pending, PendingImage):
            groups.setdefault(pending.encoder.batch_key, []).append(obs)
    for members in groups.values():
        first = members[0][IMAGE]
        batch = {k: np.stack([m[IMAGE].inputs[k] for m in members]) for k in first.inputs}
        emb = first.encoder.encode(batch).numpy()
        for obs, e in zip(members, emb):
            obs[IMAGE] = e


class EncodeObservation(gym.Wrapper):
    """Replaces the observation by {"image" (D,) | "rgb"/"depth" (cnn), "goal_emb" (Dg,), "collided"
    [, "expert_action"]}. The oracle encoder (ORACLE PERCEPTION) reads the semantic frame from
    `info["privileged"]` and needs `PrivilegedInfo` below it; its noise stream is reseeded with each
    episode's reset seed, so an episode encodes the same way whenever it is replayed."""

    def __init__(self, env: gym.Env, encoder: EncoderConfig, text_table: dict[str, Any]) -> None:
        super().__init__(env)
        self.cfg = encoder
        self.text = TableTextEncoder(text_table, encoder)
        self.image_encoder = None if encoder.image == "cnn" else make_image_encoder(encoder, self.text)
        self.oracle = encoder.image == "oracle-vl"
        # set by a vector env worker that batches encoders with a `batch_key` (see `resolve_pending`)
        self.defer_encoding = False
        inner = env.observation_space.spaces
        # PointNav: the goal input is the goal vector the env computes from odometry, not a text embedding.
        self.point = "pointgoal" in inner
        self._scene_key: object = None
        self._goal_text, self._goal = "", np.zeros(0, np.float32)
        space: dict[str, spaces.Space] = {}
        if self.image_encoder is None:
            space.update({k: inner[k] for k in ("rgb", "depth") if k in inner})
        else:
            space[IMAGE] = spaces.Box(-np.inf, np.inf, (int(self.image_encoder.dim),), np.float32)
        space[GOAL] = (
            inner["pointgoal"] if self.point else spaces.Box(-np.inf, np.inf, (int(self.text.dim),), np.float32)
        )
        space.update({k: inner[k] for k in ("collided", "expert_action") if k in inner})
        self.observation_space = spaces.Dict(space)

    def _encode(self, obs: dict, info: dict) -> dict:
        out: dict[str, Any] = {}
        semantic = None
        if self.oracle:
            p = privileged_of(info)
            if self._scene_key is not p.world:
                self.image_encoder.set_scene({o.id: o.category for o in p.world.scene.objects if o.category})
                self._scene_key = p.world
            semantic = p.frame.semantic
        if self.image_encoder is None:
            out.update({k: obs[k] for k in ("rgb", "depth") if k in obs})
        elif self.defer_encoding and hasattr(self.image_encoder, "batch_key"):
            inputs = {"rgb": np.asarray(obs["rgb"]), "depth": np.asarray(obs["depth"])}
            out[IMAGE] = PendingImage(self.image_encoder, inputs | {"collided": int(obs.get("collided", 0))})
        else:
            out[IMAGE] = encode_observation(self.image_encoder, obs, semantic)
        if self.point:
            out[GOAL] = obs["pointgoal"]
        else:
            if obs["goal"] != self._goal_text:
                self._goal_text = obs["goal"]
                self._goal = self.text.encode([obs["goal"]])[0].numpy()
            out[GOAL] = self._goal
        out.update({k: obs[k] for k in ("collided", "expert_action") if k in obs})
        return out

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        obs, info = self.env.reset(seed=seed, options=options)
        if self.image_encoder is not None and hasattr(self.image_encoder, "reseed") and seed is not None:
            self.image_encoder.reseed(int(seed))
        return self._encode(obs, info), info

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        return self._encode(obs, info), reward, terminated, truncated, info


__all__ = ["EncodeObservation", "GOAL", "IMAGE", "PRIVILEGED", "PendingImage", "resolve_pending"]
