"""Episode and goal records of the released HM3D-OVON format, with lossless (de)serialisation.

Why a hand-written parser: the released files must load without Habitat, a corrupt record must be an
error that says which record and key is wrong, and keys we do not model are kept in `extra` and
written back so that read -> write round trips lose nothing.
"""

from __future__ import annotations

import math
import os
import posixpath
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath, PureWindowsPath
from typing import Any

SCENE_DATASETS_PREFIX = "data/scene_datasets/"


class DatasetError(ValueError):
    """A dataset file or record is malformed; the message names the file and the key / record index."""


# ----------------------------------------------------------------------------------------------------
# field checkers (the `where` string is a JSON path such as `episodes[3].start_rotation`)


def _numbers(v: Any, n: int, where: str) -> list[float]:
    if (
        not isinstance(v, list | tuple)
        or len(v) != n
        or not all(isinstance(x, int | float) and not isinstance(x, bool) for x in v)
    ):
        raise DatasetError(f"{where}: expected {n} numbers, got {_short(v)}")
    out = [float(x) for x in v]
    if not all(math.isfinite(x) for x in out):
        raise DatasetError(f"{where}: expected {n} finite numbers, got {_short(v)}")
    return out


# Scene coordinates are metres around the scene's origin (HM3D scans span tens of metres): a position far
# beyond this is a corrupt value, refused here rather than overflowing a grid index later.
MAX_COORDINATE = 1e5


def _position(v: Any, where: str) -> list[float]:
    out = _numbers(v, 3, where)
    if any(abs(x) > MAX_COORDINATE for x in out):
        raise DatasetError(
            f"{where}: expected 3 coordinates within ±{MAX_COORDINATE:g} m of the scene's origin, got {_short(v)}"
        )
    return out


def _number(v: Any, where: str) -> float:
    if not isinstance(v, int | float) or isinstance(v, bool) or not math.isfinite(v):
        raise DatasetError(f"{where}: expected a number, got {_short(v)}")
    return float(v)


def _str(v: Any, where: str) -> str:
    if not isinstance(v, str):
        raise DatasetError(f"{where}: expected a string, got {_short(v)}")
    return v


def _str_list(v: Any, where: str) -> list[str]:
    if not isinstance(v, list) or not all(isinstance(x, str) for x in v):
        raise DatasetError(f"{where}: expected a list of strings, got {_short(v)}")
    return list(v)


def _dict(v: Any, where: str) -> dict[str, Any]:
    if not isinstance(v, dict):
        raise DatasetError(f"{where}: expected an object, got {_short(v)}")
    return v


def _list(v: Any, where: str) -> list[Any]:
    if not isinstance(v, list):
        raise DatasetError(f"{where}: expected a list, got {_short(v)}")
    return v


def _req(d: dict[str, Any], key: str, where: str) -> Any:
    if key not in d:
        raise DatasetError(f"{where}.{key}: missing key" if where else f"{key}: missing key")
    return d[key]


def _short(v: Any) -> str:
    s = repr(v)
    return s if len(s) <= 80 else s[:77] + "..."


# ----------------------------------------------------------------------------------------------------
# records


@dataclass
class ViewPoint:
    """An agent pose from which the goal is well seen; `iou` is the frame-coverage score."""

    position: list[float]
    rotation: list[float]  # [x, y, z, w]
    iou: float

    def to_dict(self) -> dict[str, Any]:
        return {
            "agent_state": {"position": list(self.position), "rotation": list(self.rotation)},
            "iou": self.iou,
        }

    @classmethod
    def from_dict(cls, d: Any, where: str = "view_point") -> ViewPoint:
        d = _dict(d, where)
        w = f"{where}.agent_state"
        state = _dict(_req(d, "agent_state", where), w)
        return cls(
            position=_position(_req(state, "position", w), f"{w}.position"),
            rotation=_numbers(_req(state, "rotation", w), 4, f"{w}.rotation"),
            iou=_number(_req(d, "iou", where), f"{where}.iou"),
        )


_GOAL_KEYS = ("object_category", "object_id", "position", "view_points")


@dataclass
class ObjectGoal:
    """One goal instance of a category in a scene (an entry of `goals_by_category[key]`)."""

    object_category: str
    object_id: str  # "<raw label>_<semantic id>", e.g. "armchair_57"
    position: list[float]  # bounding-box centre
    view_points: list[ViewPoint] = field(default_factory=list)
    extra: dict[str, Any] = field(default_factory=dict)  # unknown released keys, written back as-is

    @property
    def instance_id(self) -> int:
        """The HM3D semantic instance id: the integer after the last `_` of `object_id`."""
        tail = str(self.object_id).rsplit("_", 1)[-1]
        try:
            return int(tail)
        except ValueError:
            raise ValueError(
                f"object_id {self.object_id!r} does not end in _<semantic id> (expected e.g. 'armchair_57')"
            ) from None

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {
            "object_category": self.object_category,
            "object_id": self.object_id,
            "position": list(self.position),
            "view_points": [v.to_dict() for v in self.view_points],
        }
        for k, v in self.extra.items():
            if k not in d:
                d[k] = v
        return d

    @classmethod
    def from_dict(cls, d: Any, where: str = "goal") -> ObjectGoal:
        d = _dict(d, where)
        object_id = _req(d, "object_id", where)
        if isinstance(object_id, int) and not isinstance(object_id, bool):
            object_id = str(object_id)  # tolerated: a bare id; written back as a string
        vps = _list(_req(d, "view_points", where), f"{where}.view_points")
        return cls(
            object_category=_str(_req(d, "object_category", where), f"{where}.object_category"),
            object_id=_str(object_id, f"{where}.object_id"),
            position=_position(_req(d, "position", where), f"{where}.position"),
            view_points=[ViewPoint.from_dict(v, f"{where}.view_points[{i}]") for i, v in enumerate(vps)],
            extra={k: v for k, v in d.items() if k not in _GOAL_KEYS},
        )


_EPISODE_KEYS = (
    "episode_id",
    "scene_id",
    "scene_dataset_config",
    "additional_obj_config_paths",
    "start_position",
    "start_rotation",
    "info",
    "goals",
    "start_room",
    "shortest_paths",
    "object_category",
    "children_object_categories",
)


@dataclass
class Episode:
    """One episode. `goals` is empty on disk; use `goals_for` to re-attach them from goals_by_category."""

    episode_id: str
    scene_id: str
    start_position: list[float]
    start_rotation: list[float]  # [x, y, z, w], pure yaw
    object_category: str
    scene_dataset_config: str = ""
    additional_obj_config_paths: list[Any] = field(default_factory=list)
    info: dict[str, Any] = field(default_factory=dict)  # geodesic_distance, euclidean_distance
    children_object_categories: list[str] = field(default_factory=list)
    goals: list[ObjectGoal] = field(default_factory=list)
    start_room: Any = None
    shortest_paths: Any = None
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def goal_categories(self) -> list[str]:
        """The goal category followed by its children (all their instances count as goals)."""
        return [self.object_category, *self.children_object_categories]

    @property
    def goal_key(self) -> str:
        return goal_key(self.scene_id, self.object_category)

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {
            "episode_id": self.episode_id,
            "scene_id": self.scene_id,
            "scene_dataset_config": self.scene_dataset_config,
            "additional_obj_config_paths": list(self.additional_obj_config_paths),
            "start_position": list(self.start_position),
            "start_rotation": list(self.start_rotation),
            "info": dict(self.info),
            "goals": [g.to_dict() for g in self.goals],
            "start_room": self.start_room,
            "shortest_paths": self.shortest_paths,
            "object_category": self.object_category,
            "children_object_categories": list(self.children_object_categories),
        }
        for k, v in self.extra.items():
            if k not in d:
                d[k] = v
        return d

    @classmethod
    def from_dict(cls, d: Any, where: str = "episode") -> Episode:
        d = _dict(d, where)
        episode_id = _req(d, "episode_id", where)
        if not isinstance(episode_id, str | int) or isinstance(episode_id, bool):
            raise DatasetError(f"{where}.episode_id: expected a string, got {_short(episode_id)}")
        goals = _list(d.get("goals", []) or [], f"{where}.goals")
        return cls(
            episode_id=episode_id,  # type: ignore[arg-type]  # kept as written
            scene_id=_str(_req(d, "scene_id", where), f"{where}.scene_id"),
            start_position=_position(_req(d, "start_position", where), f"{where}.start_position"),
            start_rotation=_numbers(_req(d, "start_rotation", where), 4, f"{where}.start_rotation"),
            object_category=_str(_req(d, "object_category", where), f"{where}.object_category"),
            scene_dataset_config=_str(d.get("scene_dataset_config", ""), f"{where}.scene_dataset_config"),
            additional_obj_config_paths=_list(
                d.get("additional_obj_config_paths", []), f"{where}.additional_obj_config_paths"
            ),
            info=_dict(d.get("info", {}) or {}, f"{where}.info"),
            children_object_categories=_str_list(
                d.get("children_object_categories", []) or [], f"{where}.children_object_categories"
            ),
            goals=[ObjectGoal.from_dict(g, f"{where}.goals[{i}]") for i, g in enumerate(goals)],
            start_room=d.get("start_room"),
            shortest_paths=d.get("shortest_paths"),
            extra={k: v for k, v in d.items() if k not in _EPISODE_KEYS},
        )


# ----------------------------------------------------------------------------------------------------
# keys and scene ids


def scene_basename(scene_id: str) -> str:
    """`hm3d/val/00800-TEEsavR23oF/TEEsavR23oF.basis.glb` -> `TEEsavR23oF.basis.glb`."""
    return os.path.basename(str(scene_id).replace("\\", "/"))


def scene_stem(scene_id: str) -> str:
    """Scene name without extensions (`TEEsavR23oF`): the shard file name of the scene."""
    name = scene_basename(scene_id)
    for suffix in (".basis.glb", ".semantic.glb", ".glb"):
        if name.endswith(suffix):
            return name[: -len(suffix)]
    return name


def goal_key(scene_id: str, category: str) -> str:
    """Key of `goals_by_category`: `f"{basename(scene_id)}_{category}"`."""
    return f"{scene_basename(scene_id)}_{category}"


def category_from_key(key: str) -> str:
    """Category of a goals_by_category key; split on `glb_` because scene file names contain `_`."""
    head, sep, tail = key.partition("glb_")
    if not sep:
        raise ValueError(f"goals_by_category key {key!r} does not contain 'glb_' (expected '<scene>.glb_<category>')")
    return tail


def strip_scene_prefix(scene_id: str) -> str:
    """Drop a leading `./` and `data/scene_datasets/` so the id is relative to the scene-datasets root."""
    s = str(scene_id).replace("\\", "/")
    while s.startswith("./"):
        s = s[2:]
    idx = s.find(SCENE_DATASETS_PREFIX)
    if idx == 0 or (idx > 0 and s[idx - 1] == "/"):
        s = s[idx + len(SCENE_DATASETS_PREFIX) :]
    return s


def confined_scene_id(scene_id: str, scenes_root: str | Path) -> str:
    """The episode's scene id as a normalised path relative to the scenes root.

    Why: episode files come from elsewhere; they must not choose which files are read. `..` that climbs
    out of the root, and absolute paths outside it, are a DatasetError (an absolute path inside the
    root, or one containing `data/scene_datasets/`, is made relative)."""
    raw = str(scene_id)
    s = strip_scene_prefix(raw)
    fix = (
        "fix: scene ids must be paths inside the scenes root (e.g. hm3d/val/00800-TEEsavR23oF/TEEsavR23oF"
        ".basis.glb); correct the episode file, or pass the scenes root that holds it"
    )
    if "\0" in s or not s.strip():
        raise DatasetError(f"scene_id {raw!r} is not a path; {fix}")
    if posixpath.isabs(s) or PureWindowsPath(s).drive:
        root = posixpath.normpath(Path(os.path.abspath(scenes_root)).as_posix())
        norm = posixpath.normpath(s)
        if norm != root and not norm.startswith(root.rstrip("/") + "/"):
            raise DatasetError(f"scene_id {raw!r} is an absolute path outside the scenes root {root}; {fix}")
        s = norm[len(root) :].lstrip("/")
    rel = posixpath.normpath(s)
    if rel in (".", "") or rel == ".." or rel.startswith("../"):
        raise DatasetError(
            f"scene_id {raw!r} points outside the scenes root {scenes_root} ({rel!r} after normalisation); {fix}"
        )
    return rel


def scene_path_candidates(scene_id: str, scenes_root: str | Path) -> list[Path]:
    """Every path `resolve_scene_path` tries, in order (all inside `scenes_root`)."""
    rel = PurePosixPath(confined_scene_id(scene_id, scenes_root))
    root = Path(scenes_root)
    rels = [rel]
    if len(rel.parts) > 1:
        rels.append(PurePosixPath(*rel.parts[1:]))  # root is the dataset folder itself (`.../hm3d`)
    out: list[Path] = []
    for r in rels:
        p = root / r
        out.append(p)
        if p.name.endswith(".basis.glb"):
            out.append(p.with_name(p.name[: -len(".basis.glb")] + ".glb"))  # HM3D plain-glb release
    return out


def resolve_scene_path(scene_id: str, scenes_root: str | Path) -> Path:
    """Scene file for an episode's `scene_id` under the scene-datasets root (Habitat's
    `data/scene_datasets`, or the dataset folder itself); falls back from `.basis.glb` to `.glb`.
    Never outside the root (see `confined_scene_id`)."""
    tried = scene_path_candidates(scene_id, scenes_root)
    for p in tried:
        if p.is_file():
            return p
    raise FileNotFoundError(
        f"scene {scene_id!r} not found under {str(scenes_root)!r}; tried: "
        + ", ".join(str(p) for p in tried)
        + " (pass the scene-datasets root, i.e. the folder that holds hm3d/, or the hm3d folder itself)"
    )
