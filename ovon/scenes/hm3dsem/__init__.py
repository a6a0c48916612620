"""HM3DSem scene folders and any other mesh: write our scenes in the HM3DSem layout, read them back, read
real HM3D v0.2 scans and bare `.glb` / `.gltf` / `.ply` / `.obj` meshes.

A scene folder holds `<id>.glb` (visual mesh; HM3D also ships `<id>.basis.glb`), `<id>.semantic.glb`
(instance colours), `<id>.semantic.txt` (first line `HM3D Semantic Annotations`, then
`id,HEXCOLOR,"raw label",region_id` per instance) and, for scenes we wrote, a sidecar `<id>.ovon.json`
with what HM3DSem cannot carry (floor heights, named regions, oriented boxes).

Modules, one job each: `files` (where a scene's files are), `semantic_txt`, `sidecar`, `glb_write`
(`write_scene`), `glb_read` (glTF reader), `mesh_formats` (PLY/OBJ), `textures` (PNG/JPEG/Basis),
`combine` (primitives -> Mesh, semantic ids), `geometry` (floors, oriented boxes), `upaxis`,
`errors`, `load` (`load_scene`).
"""

from ovon.scenes.hm3dsem.combine import MAX_ATLAS_DIM, sample_texture_nearest
from ovon.scenes.hm3dsem.errors import SceneFileError, SceneLoadWarning
from ovon.scenes.hm3dsem.files import MESH_SUFFIXES, find_scene_files, list_scenes
from ovon.scenes.hm3dsem.geometry import FLOOR_SEPARATION, detect_floors, face_normals_areas, yaw_obb
from ovon.scenes.hm3dsem.glb_read import _read_glb_file, read_primitives
from ovon.scenes.hm3dsem.glb_write import VERTEX_ID_ATTR, encode_glb, semantic_palette, write_scene
from ovon.scenes.hm3dsem.load import load_scene
from ovon.scenes.hm3dsem.semantic_txt import (
    SEMANTIC_HEADER,
    SEMANTIC_LINE_FORMAT,
    SemanticEntry,
    format_semantic_txt,
    parse_semantic_txt,
)
from ovon.scenes.hm3dsem.sidecar import SIDECAR_FORMAT, SIDECAR_VERSION

__all__ = [
    "FLOOR_SEPARATION",
    "MAX_ATLAS_DIM",
    "MESH_SUFFIXES",
    "SEMANTIC_HEADER",
    "SEMANTIC_LINE_FORMAT",
    "SIDECAR_FORMAT",
    "SIDECAR_VERSION",
    "VERTEX_ID_ATTR",
    "SceneFileError",
    "SceneLoadWarning",
    "SemanticEntry",
    "_read_glb_file",
    "detect_floors",
    "encode_glb",
    "face_normals_areas",
    "find_scene_files",
    "format_semantic_txt",
    "list_scenes",
    "load_scene",
    "parse_semantic_txt",
    "read_primitives",
    "sample_texture_nearest",
    "semantic_palette",
    "write_scene",
    "yaw_obb",
]
