"""Pinhole camera maths shared by the GL and embree backends, so both sample the same pixel centres.

Conventions (Habitat frame, y up): the camera looks along its local -z with +y up and +x right.
World-from-camera rotation = Ry(yaw) @ Rx(pitch): yaw 0 looks along world -z, positive yaw turns left
(counter-clockwise seen from above), positive pitch looks up. Image row 0 is the top; pixel (row r,
column c) is sampled through its centre (c + 0.5, r + 0.5), which is where GL rasterisation samples.
Square pixels: fx = fy = (W / 2) / tan(hfov / 2), so VFOV = 2 atan(tan(hfov / 2) * H / W).
"""

from __future__ import annotations

import math

import numpy as np

NEAR = 0.01  # metres; GL near plane (embree hits closer than this are dropped to match)
FAR = 100.0  # metres; GL far plane (embree hits farther than this are dropped to match)


def focal_length(width: int, height: int, hfov_deg: float) -> float:
    """Focal length in pixels (same for x and y: square pixels)."""
    del height
    return (width / 2.0) / math.tan(math.radians(hfov_deg) / 2.0)


def vfov_deg(width: int, height: int, hfov_deg: float) -> float:
    """Vertical FOV implied by the aspect ratio with square pixels."""
    return math.degrees(2.0 * math.atan(math.tan(math.radians(hfov_deg) / 2.0) * height / width))


def intrinsics(width: int, height: int, hfov_deg: float) -> np.ndarray:
    """3x3 K for image coordinates with y down and the principal point at the image centre."""
    f = focal_length(width, height, hfov_deg)
    return np.array([[f, 0.0, width / 2.0], [0.0, f, height / 2.0], [0.0, 0.0, 1.0]])


def rotation(yaw: float, pitch: float) -> np.ndarray:
    """World-from-camera rotation (columns = camera x, y, z axes in world)."""
    cy, sy = math.cos(yaw), math.sin(yaw)
    cp, sp = math.cos(pitch), math.sin(pitch)
    ry = np.array([[cy, 0.0, sy], [0.0, 1.0, 0.0], [-sy, 0.0, cy]])
    rx = np.array([[1.0, 0.0, 0.0], [0.0, cp, -sp], [0.0, sp, cp]])
    return ry @ rx


def forward(yaw: float, pitch: float) -> np.ndarray:
    """Unit optical axis in world coordinates."""
    return -rotation(yaw, pitch)[:, 2]


def view_matrix(eye: np.ndarray, yaw: float, pitch: float) -> np.ndarray:
    """4x4 camera-from-world matrix (float64)."""
    r = rotation(yaw, pitch)
    m = np.eye(4)
    m[:3, :3] = r.T
    m[:3, 3] = -r.T @ np.asarray(eye, dtype=np.float64)
    return m


def projection_matrix(
    width: int, height: int, hfov_deg: float, near: float = NEAR, far: float = FAR, flip_y: bool = True
) -> np.ndarray:
    """4x4 OpenGL projection matching `ray_directions`.

    `flip_y` renders the image upside down in GL so that the framebuffer, read bottom-up, comes out with
    row 0 at the top (no flip copy needed); GL row k then samples at image row k's centre.
    """
    f = focal_length(width, height, hfov_deg)
    p = np.zeros((4, 4))
    p[0, 0] = 2.0 * f / width
    p[1, 1] = (-2.0 if flip_y else 2.0) * f / height
    p[2, 2] = -(far + near) / (far - near)
    p[2, 3] = -2.0 * far * near / (far - near)
    p[3, 2] = -1.0
    return p


def ray_directions(width: int, height: int, hfov_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """Unit camera-frame rays through every pixel centre, (H*W, 3) float64 row-major from the top row,
    and the z-depth factor per ray (cosine to the optical axis), so z-depth = t * factor."""
    f = focal_length(width, height, hfov_deg)
    xs = (np.arange(width) + 0.5 - width / 2.0) / f
    ys = (height / 2.0 - (np.arange(height) + 0.5)) / f
    d = np.empty((height, width, 3))
    d[..., 0] = xs[None, :]
    d[..., 1] = ys[:, None]
    d[..., 2] = -1.0
    d = d.reshape(-1, 3)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return d, -d[:, 2].copy()


def face_shade(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Per-face Lambert-like factor 0.55 + 0.45 |n . l| with a fixed light (no culling: |dot|)."""
    v = vertices.astype(np.float64)
    n = np.cross(v[faces[:, 1]] - v[faces[:, 0]], v[faces[:, 2]] - v[faces[:, 0]])
    norm = np.linalg.norm(n, axis=1)
    norm[norm == 0] = np.inf  # degenerate faces get the ambient term only
    ndotl = np.abs(n @ LIGHT_DIR) / norm
    return (0.55 + 0.45 * ndotl).astype(np.float32)


LIGHT_DIR = np.array([0.3, 1.0, 0.5]) / np.linalg.norm([0.3, 1.0, 0.5])
