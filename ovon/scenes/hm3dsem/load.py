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
from ovon.scenes.hm3dsem.errors import SceneFileError, SceneLoadWarning, lfs_pointer_error
from ovon.scenes.hm3dsem.files import find_scene_files
from ovon.scenes.hm3dsem.geometry import _faces_by_instance, detect_floors, yaw_obb
from ovon.scenes.hm3dsem.mesh_formats import read_mesh_primitives
from ovon.scenes.hm3dsem.semantic_txt import (
    SEMANTIC_HEADER,
    SEMANTIC_LINE_FORMAT,
    SemanticEntry,
    _hex,
    parse_semantic_txt,
    shadowed_entries,
)
from ovon.scenes.hm3dsem.sidecar import read_sidecar
from ovon.scenes.hm3dsem.upaxis import configured_up, frame_rotation, parse_up, rotate_mesh, rotation_warning
from ovon.scenes.model import Mesh, ObjectInstance, Region, Scene

# Widest horizontal extent (x or z, metres, habitat frame) a scene may have. No building scanned for
# embodied AI comes near it (HM3D's largest span tens of metres; even a very large mall or factory floor
# stays within a few hundred), while a house exported in millimetres or centimetres goes far beyond it
# (a 4 m room in mm spans 4000 m). Without the check such a mesh loads "fine" and then asks for a
# navigation grid of billions of cells (reported as out of memory) or a scene 1000x too big for the agent.
MAX_SCENE_SPAN_M = 500.0

Notes = list[tuple[Path, str]]  # (file the note is about, what it says): warnings name the file


def check_scene_span(mesh: Mesh, path: Path) -> None:
    """Refuse a mesh wider than MAX_SCENE_SPAN_M horizontally (habitat frame, y up), naming `path`:
    mesh units other than metres, or stray vertices far from the rest (see MAX_SCENE_SPAN_M)."""
    v = mesh.vertices
    if v.size == 0:
        return
    span = np.array([float(v[:, k].max()) - float(v[:, k].min()) for k in (0, 2)])  # column views: no copy
    if span.max() <= MAX_SCENE_SPAN_M:
        return
    xz = v[:, [0, 2]].astype(np.float64)
    core_lo, core_hi = np.percentile(xz, [0.5, 99.5], axis=0)
    core = core_hi - core_lo
    if core.max() <= MAX_SCENE_SPAN_M / 2:
        far = np.abs(xz - (core_lo + core_hi) / 2).max(axis=1) > MAX_SCENE_SPAN_M / 2
        i = int(np.flatnonzero(far)[0])
        raise SceneFileError(
            path,
            f"spans {span[0]:,.0f} x {span[1]:,.0f} m horizontally (max {MAX_SCENE_SPAN_M:g} m), but 99% of its "
            f"vertices lie within {core[0]:,.1f} x {core[1]:,.1f} m: {int(far.sum()):,} stray vertices lie far away "
            f"(e.g. vertex {i} at {np.round(mesh.vertices[i].astype(np.float64), 1).tolist()})",
            "fix: delete the stray geometry from the mesh",
        )
    raise _span_error(path, span)


def _span_error(path: Path, span: np.ndarray) -> SceneFileError:
    hints = "; ".join(
        f"read as {unit}: {span[0] / k:,.1f} x {span[1] / k:,.1f} m"
        for unit, k in (("mm", 1000.0), ("cm", 100.0))
        if span.max() / k <= MAX_SCENE_SPAN_M
    )
    return SceneFileError(
        path,
        f"spans {span[0]:,.0f} x {span[1]:,.0f} m horizontally (x by z), more than any building (max "
        f"{MAX_SCENE_SPAN_M:g} m): are its units millimetres or centimetres?{f' ({hints})' if hints else ''}",
        "fix: scale the mesh to metres (x0.001 from mm, x0.01 from cm) and re-export it",
    )


def preflight_scene(path: str | Path, up: str | None = None) -> dict[str, Any]:
    """Cheap checks of one scene's files, for a command about to spend minutes or hours on many scenes
    (`ovon dataset generate`): a broken file is found before any work instead of after the scenes before
    it were processed. Reads no vertex data: glTF containers, buffer / accessor lengths, index types and
    node transforms (`preflight_gltf`), the extent from the POSITION bounds when they are exact, PLY / OBJ
    headers only (not empty, not a Git LFS pointer), the semantic.txt and sidecar in full (small).

    Raises what `load_scene` would raise for the same problem (SceneFileError / FileNotFoundError, one
    line naming the file); returns the scene's files (`find_scene_files`). A scene that passes can still
    fail to load on what only its vertex data shows (NaN positions, indices out of range, and the extent
    when the POSITION bounds are missing or node transforms rotate off the axes)."""
    from ovon.scenes.hm3dsem.glb_read import preflight_gltf

    files = find_scene_files(path)
    bounds = None
    for key in ("visual", "semantic"):
        mesh_path: Path | None = files[key]
        if mesh_path is None:
            continue
        if mesh_path.suffix.lower() in (".glb", ".gltf"):
            b = preflight_gltf(mesh_path)
            bounds = b if key == "visual" else bounds
        else:
            with open(mesh_path, "rb") as f:
                head = f.read(200)
            err = lfs_pointer_error(mesh_path, head)
            if err is not None:
                raise err
            if not head.strip():
                raise SceneFileError(mesh_path, "is empty (not a mesh)")
    if files["sidecar"] is not None:
        read_sidecar(files["sidecar"])
    if files["sidecar"] is not None or (files["semantic_txt"] is None) != (files["semantic"] is None):
        _require_annotations(files)  # our scenes need both annotation files, a scan both or neither
    if files["semantic_txt"] is not None:
        parse_semantic_txt(files["semantic_txt"])
    if bounds is not None:
        rot = np.eye(3)
        if files["sidecar"] is None:
            if up is not None:
                rot = frame_rotation(*parse_up(up))
            else:
                conf = configured_up(files["stage_config"], files["dataset_config"])
                rot = frame_rotation(conf[0], conf[1]) if conf else np.eye(3)
        lo, hi = bounds
        corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
        c = corners @ rot.T
        span = (c.max(axis=0) - c.min(axis=0))[[0, 2]]
        if _axis_aligned_rotation(rot) and span.max() > MAX_SCENE_SPAN_M:
            # the declared bounds say too wide: confirm on the vertices (bounds can be stale, and only the
            # vertices tell wrong units from stray geometry); rare, so reading the mesh here costs little
            mesh, _ = _visual_mesh(files["visual"])
            check_scene_span(rotate_mesh(mesh, rot), files["visual"])
    return files


def _axis_aligned_rotation(rot: np.ndarray) -> bool:
    """The rotation permutes axes (habitat's up-axis conversions do), so a rotated box stays exact."""
    return bool((np.count_nonzero(np.abs(rot) > 1e-9, axis=1) == 1).all())


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
    for where, n in notes:
        warnings.warn(f"{where}: {n}", SceneLoadWarning, stacklevel=2)
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


def _load_ours(files: dict, vocab: Any) -> tuple[Scene, Notes]:
    side = read_sidecar(files["sidecar"])
    _require_annotations(files)
    entries = parse_semantic_txt(files["semantic_txt"])
    mesh, notes = _visual_mesh(files["visual"])
    check_scene_span(mesh, files["visual"])
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
    notes += _objects_from_faces(scene, geom, from_faces, vocab, regions_side, files["semantic_txt"])
    order = {e.id: i for i, e in enumerate(entries)}
    scene.objects.sort(key=lambda o: order[o.id])
    if mismatched:
        notes.append(
            (
                files["sidecar"],
                f"{len(mismatched)} objects clean to a different category than the sidecar records "
                f"(vocabulary changed?), e.g. {mismatched[:3]}; the cleaned one is used",
            )
        )
    scene.regions = [
        Region(int(r["id"]), r["name"], int(r["floor"]), None if r["bounds"] is None else tuple(r["bounds"]))
        for r in side.get("regions", [])
    ]
    return scene, notes


# ------------------------------------------------------------------------- real scans, any mesh


def _load_scan(files: dict, vocab: Any, up: str | None) -> tuple[Scene, Notes]:
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
    check_scene_span(mesh, files["visual"])
    why = rotation_warning(mesh)
    if why:
        notes.append((files["visual"], why + (f" ({frame_note})" if frame_note else "")))
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
    notes += _objects_from_faces(scene, geom, entries, vocab, {}, files["semantic_txt"])
    scene.regions = _regions_from_objects(scene)
    return scene, notes


# ------------------------------------------------------------------------------------ shared steps


def _visual_mesh(path: Path) -> tuple[Mesh, Notes]:
    prims, notes = read_mesh_primitives(path)
    mesh, n2 = _combine(prims, "visual", path)
    return mesh, [(path, n) for n in notes + n2]


def _semantic(
    files: dict, entries: list[SemanticEntry], mesh: Mesh, rot: np.ndarray
) -> tuple[Mesh | None, Mesh, Notes]:
    """(separate semantic mesh or None when it has the visual mesh's triangles, the mesh carrying ids,
    notes). Ids come from the semantic mesh's colours through semantic.txt."""
    sem_prims, read_notes = read_mesh_primitives(files["semantic"])
    notes: Notes = [(files["semantic"], n) for n in read_notes]
    if not sem_prims:
        raise ValueError(f"{files['semantic']}: the semantic mesh has no triangles")
    color_to_id, shadowed = shadowed_entries(entries)
    if shadowed:
        e, first = shadowed[0]
        notes.append(
            (
                files["semantic_txt"],
                f"{len(shadowed)} instance(s) share a colour with an earlier line, e.g. instance {e.id} "
                f"({e.raw_label!r}, colour {_hex(e.color)}) with instance {first}: the earlier one keeps the faces of "
                "that colour (as habitat-sim reads it), these have none and are left out",
            )
        )
    face_rgb, _how = _semantic_face_colors(sem_prims)
    face_ids, unknown, missing = _decode_face_ids(face_rgb, color_to_id)
    if unknown:
        notes.append(
            (
                files["semantic"],
                f"{unknown} semantic faces have colours missing from {files['semantic_txt'].name} "
                f"({len(missing)} colours, e.g. {sorted(_hex(c) for c in missing)[:5]}); assigned id 0",
            )
        )
    sem_mesh, n4 = _combine(sem_prims, "semantic", files["semantic"])
    notes += [(files["semantic"], n) for n in n4]
    rotate_mesh(sem_mesh, rot)
    check_scene_span(sem_mesh, files["semantic"])
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
    scene: Scene, geom: Mesh, entries: list[SemanticEntry], vocab: Any, regions_side: dict, txt: Path
) -> Notes:
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
        return [
            (
                txt,
                f"{len(no_faces)} annotated instances have no faces in the semantic mesh and were skipped "
                f"(ids {no_faces[:10]})",
            )
        ]
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
