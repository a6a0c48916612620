"""Image-text scorers: one number per frame saying how much the view suggests the goal (VLFM's value).

Protocol: `score(observation, goal_text) -> float` (a cosine for the built-ins), `reset(seed)`, `name`,
`privileged`. Picked by `ScorerConfig.kind`:
* "oracle-vl": cosine between the ORACLE PERCEPTION image embedding (`OracleVLEncoder`, from the semantic
  frame through the privileged channel) and the goal text, in MiniLM space;
* "siglip": cosine between the frozen SigLIP image and text embeddings (the existing encoders, local
  Hugging Face cache only), the open replacement for VLFM's BLIP-2 ITC score;
* "world-vl": ovon's pretrained image-text match (learned perception from RGB, weights shipped):
  `ovon.models.world.roles.WorldVLScorer`;
* "constant": 1 for every frame (frontier choice falls back to the nearest frontier: plain frontier
  exploration, an ablation);
* "package.module:Class": your own, constructed with the `ScorerConfig` (`ovon.models.config`).
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np

from ovon.config.base import validate, values_from_option
from ovon.models.config import ScorerConfig
from ovon.plugins import load_named

BUILTIN: dict[str, str] = {
    "oracle-vl": "ovon.models.scorers:OracleVLScorer",
    "siglip": "ovon.models.scorers:SiglipScorer",
    "constant": "ovon.models.scorers:ConstantScorer",
    "world-vl": "ovon.models.world.roles:WorldVLScorer",
}
SCORERS = tuple(BUILTIN)


@runtime_checkable
class ImageTextScorer(Protocol):
    name: str
    privileged: bool

    def reset(self, seed: int) -> None: ...

    def score(self, observation: dict, goal_text: str) -> float: ...


def _cosine(a: np.ndarray, b: np.ndarray) -> float:
    na, nb = float(np.linalg.norm(a)), float(np.linalg.norm(b))
    if na < 1e-12 or nb < 1e-12:
        return 0.0
    return float(a @ b) / (na * nb)


class OracleVLScorer:
    """ORACLE PERCEPTION: the frame's area-weighted category embeddings against the goal text."""

    name = "oracle-vl value"
    privileged = True

    def __init__(self, cfg: ScorerConfig | None = None, text_encoder=None) -> None:
        from ovon.models.encoders import make_text_encoder
        from ovon.models.encoders.oracle_vl import OracleVLEncoder

        self.cfg = cfg or ScorerConfig()
        self.text = text_encoder if text_encoder is not None else make_text_encoder()
        self.encoder = OracleVLEncoder(
            self.text,
            grid=1,
            include_global=False,
            noise_std=self.cfg.oracle_noise_std,
            dropout=self.cfg.oracle_dropout,
        )
        self._scene_key: object = None
        self._goal: tuple[str, np.ndarray] | None = None

    def reset(self, seed: int) -> None:
        self.encoder.reseed(int(seed))

    def score(self, observation: dict, goal_text: str) -> float:
        p = observation["privileged"]
        key = p.world.key or id(p.world)  # an unnamed scene (scene_id "") is told apart by identity
        if key != self._scene_key:
            self.encoder.set_scene({o.id: o.category for o in p.world.scene.objects if o.category})
            self._scene_key = key
        if self._goal is None or self._goal[0] != goal_text:
            text = self.cfg.prompt.format(goal=goal_text)
            self._goal = (goal_text, np.asarray(self.text.encode([text]), dtype=np.float64)[0])
        emb = self.encoder.encode_frame(np.asarray(p.frame.semantic)).astype(np.float64)
        return _cosine(emb, self._goal[1])


class SiglipScorer:
    """Cosine between frozen SigLIP image and text embeddings (weights from the local cache only)."""

    name = "SigLIP value"
    privileged = False

    def __init__(self, cfg: ScorerConfig | None = None, text_encoder=None) -> None:
        del text_encoder  # SigLIP scores with its own text tower
        from ovon.models.encoders.siglip import SiglipImageEncoder
        from ovon.models.encoders.text import SiglipText

        self.cfg = cfg or ScorerConfig(kind="siglip")
        self.image = SiglipImageEncoder(self.cfg.siglip_model, self.cfg.device, normalize=True)
        self.text = SiglipText(self.cfg.siglip_model, self.cfg.device, normalize=True)

    def reset(self, seed: int) -> None:
        del seed

    def score(self, observation: dict, goal_text: str) -> float:
        img = self.image.encode({"rgb": np.asarray(observation["rgb"])[None]})
        txt = self.text.encode([self.cfg.prompt.format(goal=goal_text)])
        return float(self.image.score(img, txt)[0, 0])


class ConstantScorer:
    """No semantics: every frame scores 1, so frontier choice is by distance alone."""

    name = "no value (constant)"
    privileged = False

    def __init__(self, cfg: ScorerConfig | None = None, text_encoder=None) -> None:
        del text_encoder  # no semantics
        self.cfg = cfg or ScorerConfig(kind="constant")

    def reset(self, seed: int) -> None:
        del seed

    def score(self, observation: dict, goal_text: str) -> float:
        return 1.0


def make_scorer(cfg: ScorerConfig | None = None, text_encoder=None) -> ImageTextScorer:
    """The scorer `cfg.kind` names; built-ins get the shared goal-text encoder, plug-ins only the config.
    A value outside its declared domain is one line, as from `--agent-arg`."""
    cfg = cfg or ScorerConfig()
    with values_from_option("--agent-arg"):
        validate(cfg, "value.scorer")
    cls = load_named(cfg.kind, BUILTIN, "value.scorer.kind")
    return cls(cfg, text_encoder) if cfg.kind in BUILTIN else cls(cfg)


def describe_scorer(cfg: ScorerConfig) -> str:
    return {
        "oracle-vl": "oracle-vl value",
        "siglip": "SigLIP value",
        "constant": "no value",
        "world-vl": "world-vl value (learned)",
    }.get(  # fmt: skip
        cfg.kind, f"{cfg.kind} value"
    )
