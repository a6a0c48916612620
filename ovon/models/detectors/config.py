"""Detector config and presets: every rate and threshold of the detectors is a config value."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

DEFAULT_OWLV2 = "google/owlv2-base-patch16-ensemble"


@dataclass(frozen=True)
class DetectorConfig:
    """`kind`: "oracle" (ORACLE DETECTION from the semantic frame), "owlv2" (the paper's detector, local
    Hugging Face cache only) or "package.module:Class" (constructed with this config)."""

    kind: str = "oracle"
    # oracle: a goal instance (the goal category or one of its children) is a candidate when it covers at
    # least `min_frame_share` of the frame; each candidate is missed with probability `miss_rate`.
    min_frame_share: float = 0.01
    miss_rate: float = 0.0
    # oracle false positives: each visible non-goal instance (same minimum share) is reported as the goal
    # with probability fp_rate * clip((s - fp_min_similarity) / (1 - fp_min_similarity), 0, 1) ** fp_power,
    # s = MiniLM cosine between its category and the goal text (couch-sofa 0.86, couch-toaster 0.25).
    fp_rate: float = 0.0
    fp_min_similarity: float = 0.4
    fp_power: float = 2.0
    seed: int = 0
    # owlv2
    owlv2_model: str = DEFAULT_OWLV2  # hub id in the local HF cache, or a folder written by save_pretrained
    owlv2_threshold: float = 0.3  # keep boxes scoring above this
    owlv2_prompt: str = "a photo of a {goal}"
    device: str = "cpu"

    def __post_init__(self) -> None:
        for name in ("min_frame_share", "miss_rate", "fp_rate", "fp_min_similarity", "owlv2_threshold"):
            v = getattr(self, name)
            if not 0.0 <= v <= 1.0:
                raise ValueError(f"detector.{name} = {v!r} is outside [0, 1]; pass a probability/fraction")
        if self.fp_min_similarity >= 1.0:
            raise ValueError("detector.fp_min_similarity must be < 1")
        if self.fp_power <= 0:
            raise ValueError(f"detector.fp_power = {self.fp_power!r} must be > 0")
        if "{goal}" not in self.owlv2_prompt:
            raise ValueError(f"detector.owlv2_prompt {self.owlv2_prompt!r} must contain {{goal}}")


def _presets() -> dict[str, DetectorConfig]:
    return {
        # every goal instance covering >= 1% of the frame, nothing else (the task's own "seen" threshold)
        "perfect": DetectorConfig(),
        # an imperfect open-vocabulary detector (rates argued in the README, "Modular baselines")
        "noisy": DetectorConfig(min_frame_share=0.02, miss_rate=0.3, fp_rate=0.3, fp_min_similarity=0.4),
        "owlv2": DetectorConfig(kind="owlv2"),
    }


DETECTOR_PRESETS = _presets()


def detector_preset(name: str, **overrides: object) -> DetectorConfig:
    """Named preset with optional field overrides; an unknown name lists the valid ones."""
    if name not in DETECTOR_PRESETS:
        raise ValueError(f"unknown detector preset {name!r}; valid: {sorted(DETECTOR_PRESETS)}")
    return dataclasses.replace(DETECTOR_PRESETS[name], **overrides)
