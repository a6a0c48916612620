"""`<id>.ovon.json`: what the HM3DSem layout cannot carry for scenes we wrote (floor heights, named
regions, oriented boxes, which colour mode the visual mesh uses). Read back with every field checked,
so a hand-edited or truncated sidecar is one clear error, not a KeyError deep in the loader."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from ovon.scenes.hm3dsem.errors import SceneFileError, read_bytes
from ovon.scenes.model import Scene

SIDECAR_FORMAT = "ovon-scene-sidecar"
SIDECAR_VERSION = 1
_FIX = "delete the sidecar to load the scene as a plain scan (boxes recomputed from the mesh), or rewrite it"
_BOX_SHAPES = {"aabb_min": (3,), "aabb_max": (3,), "obb_center": (3,), "obb_half_extents": (3,), "obb_rotation": (3, 3)}


def sidecar_doc(scene: Scene, visual_mode: str) -> dict:
    def arr(a: Any) -> list:
        return np.asarray(a, dtype=np.float64).tolist()

    return {
        "format": SIDECAR_FORMAT,
        "version": SIDECAR_VERSION,
        "scene_id": scene.scene_id,
        "source": scene.source,
        "floor_heights": [float(h) for h in scene.floor_heights],
        "visual_colors": visual_mode,
        "regions": [
            {
                "id": int(r.id),
                "name": r.name,
                "floor": int(r.floor),
                "bounds": None if r.bounds is None else [float(v) for v in r.bounds],
            }
            for r in scene.regions
        ],
        "objects": {
            str(o.id): {
                "category": o.category,
                "aabb_min": arr(o.aabb_min),
                "aabb_max": arr(o.aabb_max),
                "obb_center": arr(o.obb_center),
                "obb_half_extents": arr(o.obb_half_extents),
                "obb_rotation": arr(o.obb_rotation),
                "region_name": o.region_name,
                "floor": int(o.floor),
            }
            for o in sorted(scene.objects, key=lambda o: o.id)
        },
    }


def read_sidecar(path: Path) -> dict:
    """The sidecar's document, validated: every key the loader uses exists with the right type/shape."""
    try:
        doc = json.loads(read_bytes(path).decode("utf-8"))
    except UnicodeDecodeError:
        raise SceneFileError(path, "is not UTF-8 text (a corrupt ovon sidecar)", _FIX) from None
    except json.JSONDecodeError as e:
        raise SceneFileError(path, f"is not valid JSON (line {e.lineno} column {e.colno}: {e.msg})", _FIX) from None
    if not isinstance(doc, dict) or doc.get("format") != SIDECAR_FORMAT:
        got = doc.get("format") if isinstance(doc, dict) else type(doc).__name__
        raise SceneFileError(path, f"is not an ovon scene sidecar (format {got!r}, expected {SIDECAR_FORMAT!r})", _FIX)

    def bad(what: str) -> SceneFileError:
        return SceneFileError(path, what, _FIX)

    fh = doc.get("floor_heights", [])
    if not isinstance(fh, list) or not all(isinstance(h, int | float) and np.isfinite(h) for h in fh):
        raise bad(f"'floor_heights' must be a list of finite numbers, got {str(fh)[:60]}")
    if doc.get("visual_colors", "none") not in ("face", "vertex", "texture", "none"):
        raise bad(f"'visual_colors' is {doc.get('visual_colors')!r}, expected face|vertex|texture|none")
    regions = doc.get("regions", [])
    if not isinstance(regions, list):
        raise bad("'regions' must be a list")
    for i, r in enumerate(regions):
        if not isinstance(r, dict) or not {"id", "name", "floor", "bounds"} <= set(r):
            raise bad(f"regions[{i}] must hold id, name, floor and bounds")
        if r["bounds"] is not None and (not isinstance(r["bounds"], list) or len(r["bounds"]) != 4):
            raise bad(f"regions[{i}].bounds must be null or [xmin, zmin, xmax, zmax]")
    objects = doc.get("objects", {})
    if not isinstance(objects, dict):
        raise bad("'objects' must be a mapping from instance id to its record")
    for key, rec in objects.items():
        if not str(key).isdigit() or not isinstance(rec, dict):
            raise bad(f"objects[{key!r}] is not an instance-id -> record entry")
        for name, shape in _BOX_SHAPES.items():
            if name not in rec:
                raise bad(f"object {key} lacks {name!r}")
            try:
                a = np.asarray(rec[name], dtype=np.float64)
            except (TypeError, ValueError):
                a = np.zeros(0)
            if a.shape != shape or not np.isfinite(a).all():
                raise bad(
                    f"object {key}: {name!r} must be {len(shape) == 2 and '3x3' or '3'} finite numbers, "
                    f"got {str(rec[name])[:60]}"
                )
    return doc
