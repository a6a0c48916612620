"""Model configs: which perception encoders feed the policy, the policy's size, the modular agents' goal
detector and image-text scorer, and their presets.

Why a dataclass per part: every number of docs/spec.md#baselines is a config value, so a YAML file or a
`key=value` override (see `ovon.config.base`) can change it and a wrong key fails loudly.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import ClassVar, Literal

from ovon.config.base import (
    Each,
    ExistingPath,
    Pattern,
    Positive,
    Range,
    constrained,
    in_range,
    non_empty,
    non_negative,
    positive,
    rule,
)

ImageEncoderName = Literal["oracle-vl", "world-vl", "siglip", "cnn", "depth-grid"]
TextEncoderName = Literal["minilm-text", "siglip-text"]
DEFAULT_SIGLIP = "google/siglip-base-patch16-256"
DEFAULT_OWLV2 = "google/owlv2-base-patch16-ensemble"
# a prompt the goal text is inserted into (`prompt.format(goal=...)`)
GOAL_PROMPT = Pattern(r"(?s).*\{goal\}.*", "a string containing {goal}")


# world-vl weights: a world_vl.safetensors or the `ovon perception pretrain` run folder holding one; "" = shipped
WORLD_WEIGHTS = ExistingPath("any", optional=True, empty="for the weights shipped in the package")


@dataclass(frozen=True)
class EncoderConfig:
    """Perception encoders.

    The default (`oracle-vl` + `minilm-text`) runs on any machine because it needs no downloaded
    weights; it is *oracle perception* (computed from the semantic frame) and every report using it
    must say so. `siglip` / `siglip-text` are the paper's encoders, loaded only from a local
    Hugging Face cache or folder.
    """

    image: ImageEncoderName = "oracle-vl"
    text: TextEncoderName = "minilm-text"
    # world-vl (ovon's pretrained encoder, learned perception): "" = the weights shipped in the package, or a
    # world_vl.safetensors / `ovon perception pretrain` run folder. It fills the oracle-vl layout: the
    # oracle_grid, oracle_global, oracle_depth_grid and oracle_collision fields below apply to it too.
    world_checkpoint: str = constrained("", WORLD_WEIGHTS)
    # world-vl frames per forward pass: every frame is computed in a batch of exactly this size (padded), so
    # its embedding does not depend on which frames share the batch (vector env workers batch their envs)
    world_batch: int = in_range(4, 1, 256)
    # SigLIP: a hub id found in the local HF cache, or a folder written by `save_pretrained`.
    siglip_model: str = non_empty(DEFAULT_SIGLIP)
    siglip_normalize: bool = True  # L2-normalise SigLIP embeddings (cosine-ready)
    # Where SigLIP runs (in each env worker for training, in the agent for evaluation); a torch device name,
    # not `auto`: the workers do not share the learner's GPU unless asked to.
    device: str = constrained("cpu", Pattern(r"cpu|cuda(:[0-9]+)?|mps", "cpu, cuda, cuda:N or mps"))
    # Oracle vision-language encoder (oracle perception).
    oracle_grid: int = in_range(2, 1, 32)  # grid x grid spatial cells
    oracle_global: bool = True  # prepend the whole-frame pooled vector
    # Append coarse depth (rows, cols); (0, 0) = none. Also the grid of the `depth-grid` encoder (PointNav),
    # which is this depth part (+ the collision flag with `oracle_collision`) without the semantic part.
    oracle_depth_grid: tuple[int, int] = constrained((0, 0), Each(Range(0, 64)))
    # Append the collision flag of the last step (a bump sensor, not privileged). Low furniture right in
    # front of the agent is below the camera's view, so without it a blocked MOVE_FORWARD looks like a free one.
    oracle_collision: bool = False
    oracle_noise_std: float = non_negative(0.0)  # per-instance noise norm relative to the unit text embedding
    # Probability that a visible instance is missed in a frame.
    oracle_dropout: float = in_range(0.0, 0.0, 1.0, hi_open=True)
    oracle_seed: int = non_negative(0)
    # Small trainable CNN on RGB (+ depth).
    cnn_dim: int = in_range(256, 1, 65536)
    cnn_channels: tuple[int, ...] = non_empty((32, 64, 128, 128), each=Positive())
    cnn_depth: bool = False
    cnn_max_depth: float = positive(5.0)  # metres; depth is divided by this

    rules: ClassVar = (
        rule(("oracle_depth_grid",), lambda g: (g[0] == 0) == (g[1] == 0), "oracle_depth_grid both 0 or both > 0"),
        rule(
            ("image", "oracle_depth_grid"),
            lambda i, g: i != "depth-grid" or g[0] > 0,
            "oracle_depth_grid > 0 for the depth-grid encoder",
        ),
    )


@dataclass(frozen=True)
class PolicyConfig:
    """Policy over per-step embeddings: `[image, goal, prev action] -> Linear -> core -> heads`."""

    core: Literal["transformer", "lstm"] = "transformer"
    hidden: int = in_range(512, 1, 65536)
    layers: int = in_range(4, 1, 256)
    heads: int = in_range(8, 1, 1024)
    mlp: int = in_range(1024, 1, 262144)
    context: int = in_range(100, 1, 100_000)
    prev_action_dim: int = in_range(32, 0, 65536)
    # The first `num_actions` of STOP FORWARD LEFT RIGHT UP DOWN (docs/spec.md#actions): 4 leaves the camera tilt out,
    # which RL from scratch at CPU scale needs (docs/concepts/learned-policies.md, "Rewards for RL from scratch").
    num_actions: int = in_range(6, 4, 6)
    rope_base: float = positive(10000.0)
    norm_eps: float = positive(1e-6)
    # Online acting of the transformer: "kv" = sliding-window key/value cache (O(context) per
    # step); "recompute" = re-run the window of stored inputs every step (O(context^2)).
    act_mode: Literal["kv", "recompute"] = "kv"
    # LSTM core width; 0 = chosen so the core's parameter count matches the transformer core's.
    lstm_hidden: int = in_range(0, 0, 65536)
    # Append, per text-aligned part of the image embedding (oracle-vl: global + grid cells; SigLIP:
    # the whole embedding), its dot product, cosine and norm against the unit goal embedding. This is
    # the image-text score a VLM agent computes anyway (VLFM's value map); a linear input layer cannot
    # form a product of two of its inputs, and learning it costs far more steps than a CPU run has.
    goal_similarity: bool = False
    # Initial bias of the STOP logit (0 = a uniform initial policy). RL from scratch: a uniform policy
    # STOPs every 6th step, so early episodes end before the dense reward can teach anything (and the env
    # spends its time resetting); -4 makes a random STOP rare (~0.4% per step) without forbidding it.
    stop_bias: float = in_range(0.0, -100.0, 100.0)  # a logit: beyond +-100 softmax saturates in float32

    # RoPE rotates pairs of channels of each head, so a head's width must be even.
    rules: ClassVar = (
        rule(
            ("hidden", "heads"),
            lambda h, n: h % n == 0 and (h // n) % 2 == 0,
            "hidden divisible by heads into an even head width",
        ),
    )


@dataclass(frozen=True)
class DetectorConfig:
    """The modular agents' goal detector. `kind`: "oracle" (ORACLE DETECTION from the semantic frame),
    "owlv2" (the paper's detector, local Hugging Face cache only) or "package.module:Class" (constructed
    with this config)."""

    kind: str = "oracle"
    # oracle: a goal instance (the goal category or one of its children) is a candidate when it covers at
    # least `min_frame_share` of the frame; each candidate is missed with probability `miss_rate`.
    min_frame_share: float = in_range(0.01, 0, 1)
    miss_rate: float = in_range(0.0, 0, 1)
    # oracle false positives: each visible non-goal instance (same minimum share) is reported as the goal
    # with probability fp_rate * clip((s - fp_min_similarity) / (1 - fp_min_similarity), 0, 1) ** fp_power,
    # s = MiniLM cosine between its category and the goal text (couch-sofa 0.86, couch-toaster 0.25).
    fp_rate: float = in_range(0.0, 0, 1)
    fp_min_similarity: float = in_range(0.4, 0, 1, hi_open=True)
    fp_power: float = positive(2.0)
    seed: int = 0
    # owlv2
    owlv2_model: str = DEFAULT_OWLV2  # hub id in the local HF cache, or a folder written by save_pretrained
    owlv2_threshold: float = in_range(0.3, 0, 1)  # keep boxes scoring above this
    owlv2_prompt: str = constrained("a photo of a {goal}", GOAL_PROMPT)
    device: str = "cpu"
    # world-owl (ovon's pretrained detector): "" = the shipped weights, or a world_vl.safetensors / run folder;
    # world_threshold < 0 keeps the threshold calibrated on the pretraining houses
    checkpoint: str = constrained("", WORLD_WEIGHTS)
    world_threshold: float = in_range(-1.0, -1.0, 1.0)


@dataclass(frozen=True)
class ScorerConfig:
    """VLFM's image-text value scorer. `kind`: "oracle-vl", "siglip", "constant" or "package.module:Class"
    (see `ovon.models.scorers`)."""

    kind: str = "oracle-vl"
    # the text scored against the image; VLFM used "Seems like there is a {goal} ahead." with BLIP-2
    prompt: str = constrained("{goal}", GOAL_PROMPT)
    siglip_model: str = DEFAULT_SIGLIP
    oracle_noise_std: float = non_negative(0.0)  # oracle-vl noise (see OracleVLEncoder)
    oracle_dropout: float = in_range(0.0, 0, 1)
    device: str = "cpu"
    checkpoint: str = constrained("", WORLD_WEIGHTS)  # world-vl: "" = the shipped weights, or a file / run folder


def text_aligned_parts(cfg: EncoderConfig) -> int:
    """How many goal-text-space vectors (each `text_dim` long) open the image embedding."""
    if cfg.image in ("oracle-vl", "world-vl"):
        return cfg.oracle_grid * cfg.oracle_grid + (1 if cfg.oracle_global else 0)
    if cfg.image == "siglip":
        return 1
    return 0  # a trainable CNN's features are not in the text space


def _encoder_presets() -> dict[str, EncoderConfig]:
    return {
        "default": EncoderConfig(),
        "oracle": EncoderConfig(),
        "paper": EncoderConfig(image="siglip", text="siglip-text"),
        "tiny": EncoderConfig(oracle_grid=1, oracle_global=False),
        "cnn": EncoderConfig(image="cnn"),
        "depth-grid": EncoderConfig(image="depth-grid", oracle_depth_grid=(8, 4), oracle_collision=True),
    }


def _policy_presets() -> dict[str, PolicyConfig]:
    return {
        "paper": PolicyConfig(),
        "paper-lstm": PolicyConfig(core="lstm"),
        "tiny": PolicyConfig(hidden=64, layers=2, heads=4, mlp=128),
        "tiny-lstm": PolicyConfig(core="lstm", hidden=64, layers=2, heads=4, mlp=128),
    }


def _detector_presets() -> dict[str, DetectorConfig]:
    return {
        # every goal instance covering >= 1% of the frame, nothing else (the task's own "seen" threshold)
        "perfect": DetectorConfig(),
        # an imperfect open-vocabulary detector (docs/concepts/modular-agents.md)
        "noisy": DetectorConfig(min_frame_share=0.02, miss_rate=0.3, fp_rate=0.3, fp_min_similarity=0.4),
        "owlv2": DetectorConfig(kind="owlv2"),
    }


ENCODER_PRESETS = _encoder_presets()
POLICY_PRESETS = _policy_presets()
DETECTOR_PRESETS = _detector_presets()


def encoder_preset(name: str) -> EncoderConfig:
    """Named encoder preset; an unknown name lists the valid ones."""
    if name not in ENCODER_PRESETS:
        raise KeyError(f"unknown encoder preset {name!r}; valid: {sorted(ENCODER_PRESETS)}")
    return ENCODER_PRESETS[name]


def policy_preset(name: str, **overrides: object) -> PolicyConfig:
    """Named policy preset with optional field overrides (e.g. `core="lstm"`)."""
    if name not in POLICY_PRESETS:
        raise KeyError(f"unknown policy preset {name!r}; valid: {sorted(POLICY_PRESETS)}")
    return dataclasses.replace(POLICY_PRESETS[name], **overrides)


def detector_preset(name: str, **overrides: object) -> DetectorConfig:
    """Named detector preset with optional field overrides; an unknown name lists the valid ones."""
    if name not in DETECTOR_PRESETS:
        raise ValueError(f"unknown detector preset {name!r}; valid: {sorted(DETECTOR_PRESETS)}")
    return dataclasses.replace(DETECTOR_PRESETS[name], **overrides)
