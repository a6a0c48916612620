"""Habitat frame helpers: y up, the agent looks along its local -z, quaternions stored [x, y, z, w]."""

from __future__ import annotations

import math

import numpy as np


def yaw_to_quat(yaw: float) -> list[float]:
    """Pure rotation about +y, Habitat order [x, y, z, w]."""
    return [0.0, math.sin(yaw / 2.0), 0.0, math.cos(yaw / 2.0)]


def quat_to_yaw(q) -> float:
    """Yaw of a quaternion [x, y, z, w] (its rotation about +y; tilt components are ignored)."""
    x, y, z, w = (float(v) for v in q)
    # forward (-z) rotated by q, projected on the floor plane
    fx = -(2.0 * (x * z + w * y))
    fz = -(1.0 - 2.0 * (x * x + y * y))
    return math.atan2(-fx, -fz)


def heading_vector(yaw: float) -> np.ndarray:
    """Unit forward vector on the floor for a yaw: yaw 0 looks along -z, positive yaw turns left."""
    return np.array([-math.sin(yaw), 0.0, -math.cos(yaw)])


def yaw_towards(src, dst) -> float:
    """Yaw that makes an agent at `src` face `dst` (x/z only)."""
    dx = float(dst[0]) - float(src[0])
    dz = float(dst[2]) - float(src[2])
    return math.atan2(-dx, -dz)


def wrap_angle(a: float) -> float:
    return (a + math.pi) % (2.0 * math.pi) - math.pi
