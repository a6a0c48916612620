"""Which way is up: habitat's configs, a user's `--up`, and a check that warns when a scene looks rotated.

Habitat's frame is y up, -z front. A stage config (`<id>.stage_config.json`, `"up"` and `"front"`)
wins over the scene dataset config (`*.scene_dataset_config.json`, `stages.default_attributes`), which
wins over the default (y up: glTF's convention). An explicit `up` argument wins over all of them.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ovon.scenes.model import Mesh

AXES = {"x": (1, 0, 0), "-x": (-1, 0, 0), "y": (0, 1, 0), "-y": (0, -1, 0), "z": (0, 0, 1), "-z": (0, 0, -1)}
# front that goes with an up axis when only the up axis is given (habitat's pairs: y/-z, z/y)
_DEFAULT_FRONT = {"y": "-z", "-y": "z", "z": "y", "-z": "-y", "x": "-z", "-x": "-z"}
FLAT_COS = 0.95  # a face is flat along an axis when its normal is within ~18 deg of it


def parse_up(text: str) -> tuple[np.ndarray, np.ndarray]:
    """`--up` value ("y", "z", "-z", ... or "x,y,z" numbers) -> (up, front) unit vectors."""
    t = text.strip().lower()
    if t in AXES:
        return np.asarray(AXES[t], float), np.asarray(AXES[_DEFAULT_FRONT[t]], float)
    try:
        v = np.asarray([float(x) for x in t.split(",")], dtype=float)
    except ValueError:
        v = np.zeros(0)
    if v.shape != (3,) or not np.isfinite(v).all():
        raise ValueError(f"--up {text!r}: expected one of {sorted(AXES)} or three numbers x,y,z")
    if np.linalg.norm(v) < 1e-9:
        raise ValueError(f"--up {text!r}: the up vector must not be all zero; fix: e.g. --up 0,0,1 or --up z")
    return v / np.linalg.norm(v), _perpendicular_front(v / np.linalg.norm(v))


def _perpendicular_front(up: np.ndarray) -> np.ndarray:
    for cand in ((0, 0, -1), (0, 1, 0), (1, 0, 0)):
        c = np.asarray(cand, float)
        f = c - up * (c @ up)
        if np.linalg.norm(f) > 0.3:
            return f / np.linalg.norm(f)
    raise AssertionError("unreachable")


def _vec(doc: dict, key: str, where: Path) -> np.ndarray | None:
    v = doc.get(key)
    if v is None:
        return None
    a = np.asarray(v, dtype=float) if isinstance(v, list) and len(v) == 3 else np.zeros(0)
    if a.shape != (3,) or not np.isfinite(a).all() or np.linalg.norm(a) < 1e-9:
        raise ValueError(f"{where}: {key!r} must be three numbers, got {v!r}")
    return a / np.linalg.norm(a)


def configured_up(stage_config: Path | None, dataset_config: Path | None) -> tuple[np.ndarray, np.ndarray, str] | None:
    """(up, front, source) from habitat's configs, or None when they say nothing."""
    for path, pick in (
        (stage_config, lambda d: d),
        (dataset_config, lambda d: (d.get("stages") or {}).get("default_attributes")),
    ):
        if path is None:
            continue
        try:
            doc = json.loads(Path(path).read_text())
        except (OSError, ValueError) as e:
            raise ValueError(f"{path}: not a readable habitat config ({e})") from None
        sub = pick(doc) if isinstance(doc, dict) else None
        if not isinstance(sub, dict):
            continue
        up = _vec(sub, "up", path)
        if up is None:
            continue
        front = _vec(sub, "front", path)
        if front is None or abs(float(front @ up)) > 1e-3:
            front = _perpendicular_front(up)
        return up, front, str(path)
    return None


def frame_rotation(up: np.ndarray, front: np.ndarray) -> np.ndarray:
    """Rotation taking the asset frame to habitat's: up -> +y, front -> -z (right = front x up -> +x)."""
    up = up / np.linalg.norm(up)
    front = front - up * (front @ up)
    front = front / np.linalg.norm(front)
    right = np.cross(front, up)
    return np.stack([right, up, -front])


def rotate_mesh(mesh: Mesh, rot: np.ndarray) -> Mesh:
    """The mesh with vertices rotated (float32 in, float32 out); faces keep their winding (det = +1)."""
    if np.allclose(rot, np.eye(3)):
        return mesh
    mesh.vertices = (mesh.vertices.astype(np.float64) @ rot.T).astype(np.float32)
    return mesh


def rotation_warning(mesh: Mesh) -> str | None:
    """Why the mesh looks rotated in habitat's frame (None when it looks upright).

    Indoor scenes have more flat area facing up/down (floors, ceilings, table tops) than along any
    horizontal axis: a scene lying on its side has most of its flat area facing x or z. A scene whose
    horizontal faces all point down is upside down (or has inverted winding). Long corridors can have
    more wall than floor area: this is a warning, never a silent change.
    """
    if mesh.num_faces == 0:
        return None
    v = mesh.vertices.astype(np.float64)
    f = mesh.faces
    cr = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    area = 0.5 * np.linalg.norm(cr, axis=1)
    total = area.sum()
    if total <= 0:
        return None
    n = cr / np.maximum(2 * area, 1e-12)[:, None]
    flat = [float(area[np.abs(n[:, k]) > FLAT_COS].sum()) for k in range(3)]
    axis = int(np.argmax(flat))
    if axis != 1 and flat[axis] > 1.2 * flat[1]:
        name = "xyz"[axis]
        return (
            f"most flat area faces the {name} axis ({flat[axis]:.0f} m² vs {flat[1]:.0f} m² facing y): the scene "
            f'looks rotated; if its up axis is {name}, pass --up {name} (or up="{name}"), or add a '
            '<id>.stage_config.json with "up"'
        )
    if not (n[:, 1] > FLAT_COS).any() and flat[1] > 0:
        return (
            "no horizontal face points up (all face down): the scene looks upside down or has inverted "
            "winding; pass --up -y if it is upside down"
        )
    return None
