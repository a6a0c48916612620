"""`load_scene`: one scene from disk, by one of two paths.

* Our own scenes (a `<id>.ovon.json` sidecar beside the HM3DSem files): y up by construction, boxes,
  floors and named regions from the sidecar, exact round trip of what `write_scene` wrote.
* Real scans and any other mesh (HM3D v0.2 folders, a bare `.glb`/`.gltf`/`.ply`/`.obj`): the up axis
  from habitat's configs or `up=`, a warning when the scene still looks rotated, semantics when
  `<id>.semantic.glb` + `<id>.semantic.txt` exist (boxes and floors computed from the meshes), else a
  scene without objects whose `semantics_missing` says what ObjectNav would need.

Why one loader for procedural houses and scans: both go through the same mesh readers, so a bug in
reading real scans shows up on the embedded world too.
"""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Any

import numpy as np

from ovon.scenes.hm3dsem.combine import _combine, _decode_face_ids, _semantic_face_colors
from ovon.scenes.hm3dsem.errors import SceneLoadWarning
from ovon.scenes.hm3dsem.files import find_scene_files
from ovon.scenes.hm3dsem.geometry import _faces_by_instance, detect_floors, yaw_obb
from ovon.scenes.hm3dsem.mesh_formats import read_mesh_primitives
from ovon.scenes.hm3dsem.semantic_txt import (
    SEMANTIC_HEADER,
    SEMANTIC_LINE_FORMAT,
    SemanticEntry,
    _hex,
    parse_semantic_txt,
)
from ovon.scenes.hm3dsem.sidecar import read_sidecar
from ovon.scenes.hm3dsem.upaxis import configured_up, frame_rotation, parse_up, rotate_mesh, rotation_warning
from ovon.scenes.model import Mesh, ObjectInstance, Region, Scene


def load_scene(path: str | Path, vocab: Any = None, up: str | None = None) -> Scene:
    """Load one scene given its folder or any of its files (see the module docstring for the two paths).

    `vocab` (default: the embedded vocabulary) cleans raw labels into categories. `up` ("y", "z", "-z",
    ... or "x,y,z") overrides the asset's up axis for scans and bare meshes. Warnings of class
    `SceneLoadWarning` report approximations (undecodable textures, unknown semantic colours, a scene
    that looks rotated); broken files raise `SceneFileError` (one line naming the file).
    """
    files = find_scene_files(path)
    if vocab is None:
        from ovon.scenes.vocabulary import load_vocabulary

        vocab = load_vocabulary()
    if files["sidecar"] is not None:
        if up is not None:
            raise ValueError(f"{files['sidecar']}: scenes written by ovon are y-up already; drop --up/up=")
        scene, notes = _load_ours(files, vocab)
    else:
        scene, notes = _load_scan(files, vocab, up)
    for n in notes:
        warnings.warn(f"{files['folder']}: {n}", SceneLoadWarning, stacklevel=2)
    return scene


# --------------------------------------------------------------------------------- our own scenes


def _require_annotations(files: dict) -> None:
    folder, stem = files["folder"], files["stem"]
    if files["semantic_txt"] is None:
        raise FileNotFoundError(
            f"scene {stem}: {folder / (stem + '.semantic.txt')} is missing (HM3DSem annotations: first line "
            f"'{SEMANTIC_HEADER}', then {SEMANTIC_LINE_FORMAT} per instance)"
        )
    if files["semantic"] is None:
        raise FileNotFoundError(f"scene {stem}: semantic mesh {folder / (stem + '.semantic.glb')} is missing")


def _load_ours(files: dict, vocab: Any) -> tuple[Scene, list[str]]:
    side = read_sidecar(files["sidecar"])
    _require_annotations(files)
    entries = parse_semantic_txt(files["semantic_txt"])
    mesh, notes = _visual_mesh(files["visual"])
    if mesh.vertex_colors is not None:
        if side.get("visual_colors") == "face":
            mesh.vertex_colors = None
        elif side.get("visual_colors") == "vertex":
            mesh.face_colors = None
    semantic_mesh, geom, n2 = _semantic(files, entries, mesh, np.eye(3))
    notes += n2
    scene = Scene(
        scene_id=side.get("scene_id") or files["scene_id"],
        mesh=mesh,
        floor_heights=[float(h) for h in side["floor_heights"]] or detect_floors(mesh),
        semantic_mesh=semantic_mesh,
        semantic_colors={e.id: e.color for e in entries},
        source=side.get("source") or str(files["folder"]),
        navmesh=str(files["navmesh"] or ""),
    )
    records = side.get("objects", {})
    mismatched: list[str] = []
    from_faces: list[SemanticEntry] = []
    for e in entries:
        so = records.get(str(e.id))
        category = vocab.clean(e.raw_label)
        if so is None:
            from_faces.append(e)
            continue
        if so.get("category") != category:
            mismatched.append(f"{e.raw_label!r}: {so.get('category')!r} -> {category!r}")
        scene.objects.append(ObjectInstance(
            id=e.id, raw_label=e.raw_label, category=category,
            aabb_min=np.asarray(so["aabb_min"], dtype=np.float64),
            aabb_max=np.asarray(so["aabb_max"], dtype=np.float64),
            obb_center=np.asarray(so["obb_center"], dtype=np.float64),
            obb_half_extents=np.asarray(so["obb_half_extents"], dtype=np.float64),
            obb_rotation=np.asarray(so["obb_rotation"], dtype=np.float64),
            region_id=e.region_id, region_name=so.get("region_name", ""), floor=int(so.get("floor", 0)), color=e.color,
        ))  # fmt: skip
    regions_side = {int(r["id"]): r for r in side.get("regions", [])}
    notes += _objects_from_faces(scene, geom, from_faces, vocab, regions_side)
    order = {e.id: i for i, e in enumerate(entries)}
    scene.objects.sort(key=lambda o: order[o.id])
    if mismatched:
        notes.append(
            f"{len(mismatched)} objects clean to a different category than the sidecar records "
            f"(vocabulary changed?), e.g. {mismatched[:3]}; the cleaned one is used"
        )
    scene.regions = [
        Region(int(r["id"]), r["name"], int(r["floor"]), None if r["bounds"] is None else tuple(r["bounds"]))
        for r in side.get("regions", [])
    ]
    return scene, notes


# ------------------------------------------------------------------------- real scans, any mesh


def _load_scan(files: dict, vocab: Any, up: str | None) -> tuple[Scene, list[str]]:
    folder, stem = files["folder"], files["stem"]
    mesh, notes = _visual_mesh(files["visual"])
    frame_note = ""
    if up is not None:
        u, f = parse_up(up)
        frame_note = f"up axis {up} (given)"
    else:
        conf = configured_up(files["stage_config"], files["dataset_config"])
        u, f = (conf[0], conf[1]) if conf else (np.array([0.0, 1.0, 0.0]), np.array([0.0, 0.0, -1.0]))
        frame_note = f"up axis {conf[0].round(3).tolist()} from {conf[2]}" if conf else ""
    rot = frame_rotation(u, f)
    rotate_mesh(mesh, rot)
    why = rotation_warning(mesh)
    if why:
        notes.append(why + (f" ({frame_note})" if frame_note else ""))
    has_txt, has_sem = files["semantic_txt"] is not None, files["semantic"] is not None
    if has_txt != has_sem:
        _require_annotations(files)  # one of the two is missing: name it
    entries = parse_semantic_txt(files["semantic_txt"]) if has_txt else []
    scene = Scene(
        scene_id=files["scene_id"],
        mesh=mesh,
        floor_heights=detect_floors(mesh),
        semantic_colors={e.id: e.color for e in entries},
        source=str(files["visual"] if not has_txt else folder),
        navmesh=str(files["navmesh"] or ""),
    )
    if not has_txt:
        scene.semantics_missing = (
            f"{folder / (stem + '.semantic.txt')} and {stem}.semantic.glb do not exist (HM3DSem layout); "
            "navigation, rendering and exploration work without them"
        )
        return scene, notes
    semantic_mesh, geom, n2 = _semantic(files, entries, mesh, rot)
    notes += n2
    scene.semantic_mesh = semantic_mesh
    notes += _objects_from_faces(scene, geom, entries, vocab, {})
    scene.regions = _regions_from_objects(scene)
    return scene, notes


# ------------------------------------------------------------------------------------ shared steps


def _visual_mesh(path: Path) -> tuple[Mesh, list[str]]:
    prims, notes = read_mesh_primitives(path)
    mesh, n2 = _combine(prims, "visual", path)
    return mesh, notes + n2


def _semantic(
    files: dict, entries: list[SemanticEntry], mesh: Mesh, rot: np.ndarray
) -> tuple[Mesh | None, Mesh, list[str]]:
    """(separate semantic mesh or None when it has the visual mesh's triangles, the mesh carrying ids,
    notes). Ids come from the semantic mesh's colours through semantic.txt."""
    sem_prims, notes = read_mesh_primitives(files["semantic"])
    if not sem_prims:
        raise ValueError(f"{files['semantic']}: the semantic mesh has no triangles")
    color_to_id = {e.color: e.id for e in entries}
    face_rgb, _how = _semantic_face_colors(sem_prims)
    face_ids, unknown, missing = _decode_face_ids(face_rgb, color_to_id)
    if unknown:
        notes.append(
            f"{unknown} semantic faces have colours missing from {files['semantic_txt'].name} "
            f"({len(missing)} colours, e.g. {sorted(_hex(c) for c in missing)[:5]}); assigned id 0"
        )
    sem_mesh, n4 = _combine(sem_prims, "semantic", files["semantic"])
    notes += n4
    rotate_mesh(sem_mesh, rot)
    sem_mesh.face_instance = face_ids.astype(np.int32)
    same = (
        sem_mesh.texture is None  # painted textures stay a separate mesh: renderers sample them per pixel
        and sem_mesh.vertices.shape == mesh.vertices.shape
        and sem_mesh.faces.shape == mesh.faces.shape
        and np.array_equal(sem_mesh.faces, mesh.faces)
        and np.array_equal(sem_mesh.vertices, mesh.vertices)
    )
    if same:
        mesh.face_instance = sem_mesh.face_instance
        return None, mesh, notes
    separate = Mesh(
        vertices=sem_mesh.vertices,
        faces=sem_mesh.faces,
        face_colors=None if sem_mesh.texture is not None else face_rgb,
        vertex_colors=sem_mesh.vertex_colors if sem_mesh.texture is None else None,
        uvs=sem_mesh.uvs,
        texture=sem_mesh.texture,
        face_instance=sem_mesh.face_instance,
    )
    return separate, separate, notes


def _objects_from_faces(
    scene: Scene, geom: Mesh, entries: list[SemanticEntry], vocab: Any, regions_side: dict
) -> list[str]:
    """Append an object per entry with its boxes computed from its faces; entries without faces are skipped."""
    groups = _faces_by_instance(np.asarray(geom.face_instance))
    no_faces: list[int] = []
    for e in entries:
        fidx = groups.get(e.id)
        if fidx is None or e.id == 0:
            no_faces.append(e.id)
            continue
        pts = geom.vertices[np.unique(geom.faces[fidx].reshape(-1))].astype(np.float64)
        center, half, rot = yaw_obb(pts)
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        rname = regions_side.get(e.region_id, {}).get("name") or (f"region_{e.region_id}" if e.region_id >= 0 else "")
        scene.objects.append(ObjectInstance(
            id=e.id, raw_label=e.raw_label, category=vocab.clean(e.raw_label),
            aabb_min=lo, aabb_max=hi, obb_center=center, obb_half_extents=half, obb_rotation=rot,
            region_id=e.region_id, region_name=rname, floor=scene.floor_of_height(float(lo[1])), color=e.color,
        ))  # fmt: skip
    if no_faces:
        return [f"{len(no_faces)} annotated instances have no faces and were skipped (ids {no_faces[:10]})"]
    return []


def _regions_from_objects(scene: Scene) -> list[Region]:
    """Regions of a real scan: one per region_id, named "region_<id>", bounds = union of its objects'
    footprints, floor = the most common floor of its objects."""
    by: dict[int, list[ObjectInstance]] = {}
    for o in scene.objects:
        if o.region_id >= 0:
            by.setdefault(o.region_id, []).append(o)
    out = []
    for rid in sorted(by):
        objs = by[rid]
        lo = np.min([o.aabb_min for o in objs], axis=0)
        hi = np.max([o.aabb_max for o in objs], axis=0)
        floors = np.bincount([o.floor for o in objs])
        out.append(
            Region(
                rid, f"region_{rid}", int(np.argmax(floors)), (float(lo[0]), float(lo[2]), float(hi[0]), float(hi[2]))
            )
        )
    return out
