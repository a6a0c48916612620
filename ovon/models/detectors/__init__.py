"""Goal detectors behind one protocol, picked by config: "oracle" (ORACLE DETECTION, from the semantic
frame through the privileged channel), "owlv2" (the paper's open-vocabulary detector, local cache only) and
"world-owl" (ovon's pretrained open-vocabulary detector for the embedded world, weights shipped);
"package.module:Class" plugs in your own (constructed with the `ovon.models.config.DetectorConfig`)."""

from __future__ import annotations

from ovon.config.base import validate, values_from_option
from ovon.models.config import DetectorConfig
from ovon.models.detectors.base import Detection, Detector, box_of
from ovon.plugins import load_named

BUILTIN: dict[str, str] = {
    "oracle": "ovon.models.detectors.oracle:OracleDetector",
    "owlv2": "ovon.models.detectors.owlv2:OWLv2Detector",
    "world-owl": "ovon.models.world.roles:WorldOWLDetector",
}
DETECTORS = tuple(BUILTIN)


def make_detector(cfg: DetectorConfig | None = None, text_encoder=None) -> Detector:
    """The detector `cfg.kind` names; built-ins get the shared goal-text encoder, plug-ins only the config.
    A value outside its declared domain (a miss rate of 1.5) is one line, as from `--agent-arg`."""
    cfg = cfg or DetectorConfig()
    with values_from_option("--agent-arg"):
        validate(cfg, "detector")
    cls = load_named(cfg.kind, BUILTIN, "detector.kind")
    return cls(cfg, text_encoder) if cfg.kind in BUILTIN else cls(cfg)


def describe_detector(cfg: DetectorConfig) -> str:
    """How reports name the detector (oracle detection always says so)."""
    if cfg.kind == "oracle":
        perfect = cfg.miss_rate == 0 and cfg.fp_rate == 0
        return "oracle detection" + ("" if perfect else f" (miss {cfg.miss_rate:g}, fp {cfg.fp_rate:g})")
    if cfg.kind == "owlv2":
        return "OWLv2"
    if cfg.kind == "world-owl":
        return "world-owl detection (learned" + (f", {cfg.checkpoint})" if cfg.checkpoint else ")")
    return cfg.kind


__all__ = [
    "DETECTORS",
    "Detection",
    "Detector",
    "box_of",
    "describe_detector",
    "make_detector",
]
