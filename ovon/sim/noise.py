"""Actuation and odometry noise (docs/spec.md#noise). Noise perturbs what happens or what is sensed, never the
ground-truth bookkeeping: callers keep the true pose and compute metrics from it.

Presets: habitat-sim's published PyRobot LoCoBot tables (means and *variances* of forward/lateral
translation in metres and rotation in radians, per controller; std = sqrt(variance)). The paper used a
Stretch mocap model that was never published.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class MotionNoise:
    """Truncated (3 sigma) Gaussian on (forward, lateral) translation and on rotation."""

    translation_mean: tuple[float, float]
    translation_std: tuple[float, float]
    rotation_mean: float
    rotation_std: float


@dataclass(frozen=True)
class ControllerNoise:
    move: MotionNoise  # applied after MOVE_FORWARD
    turn: MotionNoise  # applied after TURN_LEFT / TURN_RIGHT


def _mn(t_mean, t_var, r_mean, r_var) -> MotionNoise:
    return MotionNoise(
        tuple(t_mean),
        tuple(math.sqrt(v) for v in t_var),
        r_mean,
        math.sqrt(r_var),  # type: ignore[arg-type]
    )


# habitat-sim pyrobot_noisy_controls.py, robot "LoCoBot": (mean, variance) pairs.
LOCOBOT_PRESETS: dict[str, ControllerNoise] = {
    "ilqr": ControllerNoise(
        move=_mn([0.014, 0.009], [0.006, 0.005], 0.008, 0.004),
        turn=_mn([0.003, 0.003], [0.002, 0.003], 0.023, 0.012),
    ),
    "proportional": ControllerNoise(
        move=_mn([0.017, 0.042], [0.007, 0.023], 0.031, 0.026),
        turn=_mn([0.001, 0.005], [0.001, 0.004], 0.043, 0.017),
    ),
    "movebase": ControllerNoise(
        move=_mn([0.074, 0.036], [0.019, 0.033], 0.189, 0.038),
        turn=_mn([0.002, 0.003], [0.0, 0.002], 0.219, 0.019),
    ),
}


def gaussian_preset(translation_std: float = 0.02, rotation_std_deg: float = 2.0) -> ControllerNoise:
    """Zero-mean isotropic model for ablations."""
    m = MotionNoise((0.0, 0.0), (translation_std, translation_std), 0.0, math.radians(rotation_std_deg))
    return ControllerNoise(move=m, turn=m)


def truncated_normal(rng: np.random.Generator, mean, std, size=None, k: float = 3.0) -> np.ndarray:
    """Gaussian samples clipped to mean +- k std by resampling (not clipping), as habitat-sim does."""
    mean = np.asarray(mean, dtype=np.float64)
    std = np.asarray(std, dtype=np.float64)
    shape = np.broadcast_shapes(mean.shape, std.shape) if size is None else size
    out = rng.normal(mean, std, size=shape)
    bad = np.abs(out - mean) > k * std + 1e-12
    while np.any(bad):
        out[bad] = rng.normal(np.broadcast_to(mean, shape)[bad], np.broadcast_to(std, shape)[bad])
        bad = np.abs(out - mean) > k * std + 1e-12
    return out


class ActuationNoise:
    """Samples the pose error after one action, in the agent frame: (forward, lateral, dyaw)."""

    def __init__(self, model: ControllerNoise, multiplier: float = 1.0):
        self.model = model
        self.multiplier = float(multiplier)

    @classmethod
    def from_name(cls, name: str, multiplier: float = 1.0) -> ActuationNoise | None:
        if name == "none":
            return None
        if name == "gaussian":
            return cls(gaussian_preset(), multiplier)
        try:
            return cls(LOCOBOT_PRESETS[name], multiplier)
        except KeyError:
            raise ValueError(
                f"unknown actuation noise {name!r}; choose none, gaussian or one of {sorted(LOCOBOT_PRESETS)}"
            ) from None

    def sample(self, rng: np.random.Generator, is_turn: bool, turn_sign: float = 1.0):
        m = self.model.turn if is_turn else self.model.move
        t = truncated_normal(rng, m.translation_mean, m.translation_std) * self.multiplier
        r = float(truncated_normal(rng, m.rotation_mean, m.rotation_std)) * self.multiplier
        # Mean rotation error overshoots in the direction of the turn (habitat-sim convention).
        return float(t[0]), float(t[1]), r * (turn_sign if is_turn else 1.0)


class OdometryNoise:
    """Uniform error on the reported odometry each step: +-position_m per axis, +-heading_deg."""

    def __init__(self, position_m: float = 0.007, heading_deg: float = 2.0):
        self.position_m = float(position_m)
        self.heading_rad = math.radians(heading_deg)

    def sample(self, rng: np.random.Generator) -> np.ndarray:
        return np.array(
            [
                rng.uniform(-self.position_m, self.position_m),
                rng.uniform(-self.position_m, self.position_m),
                rng.uniform(-self.heading_rad, self.heading_rad),
            ]
        )
