"""The scene model shared by procedural houses and real HM3DSem scans (Habitat frame, y up, metres).

Arrays: vertices float32 (N, 3); faces int32 (M, 3); colours uint8; instance ids int32 with 0 meaning
"no instance" (HM3DSem ids start at 1).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class Mesh:
    vertices: np.ndarray  # (N, 3) float32
    faces: np.ndarray  # (M, 3) int32
    face_colors: np.ndarray | None = None  # (M, 3) uint8, flat shading colour
    vertex_colors: np.ndarray | None = None  # (N, 3) uint8
    uvs: np.ndarray | None = None  # (N, 2) float32, with `texture`
    texture: np.ndarray | None = None  # (H, W, 3) uint8; glTF UV convention: uv (0, 0) = row 0, top-left
    face_instance: np.ndarray | None = None  # (M,) int32 semantic instance id per face, 0 = none

    @property
    def num_faces(self) -> int:
        return int(len(self.faces))

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        return self.vertices.min(axis=0), self.vertices.max(axis=0)


@dataclass
class ObjectInstance:
    id: int  # semantic instance id (>= 1)
    raw_label: str  # label as annotated, e.g. "sofa"
    category: str | None  # canonical category after cleaning, None when dropped
    aabb_min: np.ndarray  # (3,)
    aabb_max: np.ndarray  # (3,)
    obb_center: np.ndarray  # (3,)
    obb_half_extents: np.ndarray  # (3,) along the box's local x, y, z
    obb_rotation: np.ndarray  # (3, 3) local -> world; columns are the box axes
    region_id: int = -1
    region_name: str = ""
    floor: int = 0
    color: tuple[int, int, int] = (0, 0, 0)  # semantic colour (HM3DSem hex colour)

    @property
    def center(self) -> np.ndarray:
        return (np.asarray(self.aabb_min) + np.asarray(self.aabb_max)) / 2.0

    @property
    def name(self) -> str:
        """HM3D instance name used as `object_id` in episodes: "<raw label>_<id>"."""
        return f"{self.raw_label}_{self.id}"


@dataclass
class Region:
    id: int
    name: str  # room type, e.g. "kitchen"
    floor: int
    bounds: tuple[float, float, float, float] | None = None  # (xmin, zmin, xmax, zmax) when known


@dataclass
class Scene:
    scene_id: str  # e.g. "00800-TEEsavR23oF"
    mesh: Mesh  # visual mesh
    objects: list[ObjectInstance] = field(default_factory=list)
    regions: list[Region] = field(default_factory=list)
    floor_heights: list[float] = field(default_factory=list)  # y of each floor surface, ascending
    semantic_mesh: Mesh | None = None  # separate semantic mesh (real scans); None: `mesh` carries ids
    semantic_colors: dict[int, tuple[int, int, int]] = field(default_factory=dict)  # id -> RGB
    source: str = ""  # path it was loaded from, or "procedural:<seed>"
    semantics_missing: str = ""  # non-empty for a bare mesh without annotations: which files are missing
    navmesh: str = ""  # habitat navmesh beside the mesh (<id>.navmesh or <id>.basis.navmesh), "" when none

    def object_by_id(self, instance_id: int) -> ObjectInstance:
        for o in self.objects:
            if o.id == instance_id:
                return o
        raise KeyError(f"scene {self.scene_id} has no object with instance id {instance_id}")

    def require_semantics(self, purpose: str = "ObjectNav goals") -> None:
        """Raise the one-line error of a task that needs instance annotations on a bare mesh."""
        if self.semantics_missing:
            raise ValueError(
                f"scene {self.scene_id}: {purpose} need semantic annotations, but {self.semantics_missing}"
            )

    def objects_of(self, category: str) -> list[ObjectInstance]:
        return [o for o in self.objects if o.category == category]

    @property
    def categories(self) -> list[str]:
        return sorted({o.category for o in self.objects if o.category})

    @property
    def semantic_source(self) -> Mesh:
        """Mesh whose faces (or texture) carry instance ids."""
        return self.semantic_mesh if self.semantic_mesh is not None else self.mesh

    def floor_of_height(self, y: float) -> int:
        """Index of the floor whose surface is the highest one at or below `y` (+ a small tolerance)."""
        if not self.floor_heights:
            return 0
        idx = 0
        for i, h in enumerate(self.floor_heights):
            if y >= h - 0.3:
                idx = i
        return idx
