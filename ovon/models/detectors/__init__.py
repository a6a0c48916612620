"""Goal detectors behind one protocol, picked by config: "oracle" (ORACLE DETECTION, from the semantic
frame through the privileged channel) and "owlv2" (the paper's open-vocabulary detector, local cache only);
"package.module:Class" plugs in your own (constructed with the `DetectorConfig`)."""

from __future__ import annotations

from ovon.models.detectors.base import Detection, Detector, box_of
from ovon.models.detectors.config import DETECTOR_PRESETS, DetectorConfig, detector_preset
from ovon.plugins import is_spec, load_class

DETECTORS = ("oracle", "owlv2")


def make_detector(cfg: DetectorConfig | None = None, text_encoder=None) -> Detector:
    cfg = cfg or DetectorConfig()
    if cfg.kind == "oracle":
        from ovon.models.detectors.oracle import OracleDetector

        return OracleDetector(cfg, text_encoder)
    if cfg.kind == "owlv2":
        from ovon.models.detectors.owlv2 import OWLv2Detector

        return OWLv2Detector(cfg)
    if is_spec(cfg.kind):
        return load_class(cfg.kind, "detector.kind", f"one of {list(DETECTORS)} or package.module:Class")(cfg)
    raise ValueError(f"detector.kind = {cfg.kind!r} is unknown; use one of {list(DETECTORS)} or package.module:Class")


def describe_detector(cfg: DetectorConfig) -> str:
    """How reports name the detector (oracle detection always says so)."""
    if cfg.kind == "oracle":
        perfect = cfg.miss_rate == 0 and cfg.fp_rate == 0
        return "oracle detection" + ("" if perfect else f" (miss {cfg.miss_rate:g}, fp {cfg.fp_rate:g})")
    if cfg.kind == "owlv2":
        return "OWLv2"
    return cfg.kind


__all__ = [
    "DETECTORS",
    "DETECTOR_PRESETS",
    "Detection",
    "Detector",
    "DetectorConfig",
    "box_of",
    "describe_detector",
    "detector_preset",
    "make_detector",
]
