"""Where the files of one scene are: HM3DSem layout (`<id>.glb`, `<id>.semantic.glb`, `<id>.semantic.txt`,
our `<id>.ovon.json` sidecar) or a bare mesh (`.glb`, `.gltf` + `.bin`, `.ply`, `.obj`), plus the habitat
configs that say which axis is up (`*.stage_config.json`, `*.scene_dataset_config.json`)."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

# visual mesh suffixes, in order of preference inside one folder (plain glb first: HM3D's glb release
# has JPEG/PNG textures, cheaper to decode than the Basis ones of `.basis.glb`)
MESH_SUFFIXES = (".glb", ".basis.glb", ".gltf", ".ply", ".obj")
_SUFFIXES = (
    ".semantic.glb",
    ".semantic.txt",
    ".ovon.json",
    ".stage_config.json",
    ".basis.navmesh",
    ".navmesh",
    ".basis.glb",
    ".glb",
    ".gltf",
    ".ply",
    ".obj",
)
NAVMESH_SUFFIXES = (".navmesh", ".basis.navmesh")  # habitat's navmesh beside the mesh, in order of preference
EXPECTED = "<id>.glb (or .basis.glb / .gltf / .ply / .obj), optionally <id>.semantic.glb + <id>.semantic.txt"


def _short_id(scene_id: str) -> str:
    """File stem of a scene: the part after the dash of "00012-aB3dE5fG7hJ"."""
    return scene_id.split("-", 1)[1] if re.match(r"^\d+-.+", scene_id) else scene_id


def _stem_of(path: Path) -> str:
    name = path.name
    for suf in _SUFFIXES:
        if name.lower().endswith(suf):
            return name[: -len(suf)]
    return path.stem


def _is_mesh(p: Path) -> bool:
    n = p.name.lower()
    return not p.name.startswith("._") and p.is_file() and n.endswith(MESH_SUFFIXES) and not n.endswith(".semantic.glb")


def find_scene_files(path: str | Path) -> dict[str, Any]:
    """Locate the files of one scene given its folder or any of its files.

    Returns {"folder", "scene_id", "stem", "visual", "semantic", "semantic_txt", "sidecar", "navmesh",
    "stage_config", "dataset_config"}; optional entries are None when absent. Given a mesh file, that
    file is the visual mesh; given a folder or an annotation file, the plain `.glb` is preferred.
    """
    p = Path(path)
    if not p.exists():
        raise FileNotFoundError(
            f"scene path {p} does not exist (expected a scene folder holding {EXPECTED}, or one of those files)"
        )
    visual: Path | None = None
    if p.is_dir():
        folder = p
        txts = sorted(q for q in folder.glob("*.semantic.txt") if not q.name.startswith("._"))
        meshes = sorted(q for q in folder.iterdir() if _is_mesh(q))
        candidates = list(dict.fromkeys([_stem_of(q) for q in txts] or [_stem_of(q) for q in meshes]))
        if not candidates:
            raise FileNotFoundError(f"no scene in {folder}: expected {EXPECTED}")
        short = folder.name.split("-", 1)[-1]
        stem = short if short in candidates else candidates[0]
    else:
        folder = p.parent
        stem = _stem_of(p)
        if _is_mesh(p):
            visual = p

    def opt(suffix: str) -> Path | None:
        q = folder / f"{stem}{suffix}"
        return q if q.is_file() else None

    if visual is None:
        visual = next((q for s in MESH_SUFFIXES if (q := opt(s)) is not None), None)
    if visual is None:
        raise FileNotFoundError(
            f"scene {stem} in {folder}: no visual mesh {stem}.glb (or .basis.glb / .gltf / "
            f".ply / .obj) next to its other files"
        )
    scene_id = folder.name if folder.name.endswith(f"-{stem}") or folder.name == stem else stem
    return {
        "folder": folder,
        "scene_id": scene_id,
        "stem": stem,
        "visual": visual,
        "semantic": opt(".semantic.glb"),
        "semantic_txt": opt(".semantic.txt"),
        "sidecar": opt(".ovon.json"),
        "navmesh": next((q for s in NAVMESH_SUFFIXES if (q := opt(s)) is not None), None),
        "stage_config": _stage_config(folder, stem, visual),
        "dataset_config": _dataset_config(folder),
    }


def _stage_config(folder: Path, stem: str, visual: Path) -> Path | None:
    """`<stem>.stage_config.json`, else a stage config in the folder whose render_asset is this mesh."""
    own = folder / f"{stem}.stage_config.json"
    if own.is_file():
        return own
    import json

    for q in sorted(folder.glob("*.stage_config.json")):
        try:
            asset = json.loads(q.read_text()).get("render_asset", "")
        except (OSError, ValueError, AttributeError):
            continue
        if isinstance(asset, str) and Path(asset).name == visual.name:
            return q
    return None


def _dataset_config(folder: Path, levels: int = 3) -> Path | None:
    """The nearest `*.scene_dataset_config.json` in the folder or up to `levels` parents (HM3D keeps it
    beside the split folders)."""
    d = folder
    for _ in range(levels + 1):
        found = sorted(d.glob("*.scene_dataset_config.json"))
        if found:
            return found[0]
        if d.parent == d:
            break
        d = d.parent
    return None


def list_scenes(dataset_dir: str | Path, split: str | None = None) -> list[Path]:
    """Scene folders of a tree `DATASET_DIR/<split>/<NNNNN-id>/<id>.glb` (HM3D's `hm3d/` layout); any
    folder holding a mesh of a supported format counts."""
    root = Path(dataset_dir)
    if not root.is_dir():
        raise FileNotFoundError(f"dataset folder {root} does not exist (expected <dir>/<split>/<NNNNN-id>/)")
    if split is not None:
        split_dirs = [root / split]
        if not split_dirs[0].is_dir():
            have = sorted(d.name for d in root.iterdir() if d.is_dir() and not d.name.startswith("."))
            raise FileNotFoundError(f"split folder {split_dirs[0]} does not exist; splits found: {have}")
    else:
        split_dirs = sorted(d for d in root.iterdir() if d.is_dir() and not d.name.startswith("."))
    out: list[Path] = []
    for sd in split_dirs:
        for d in sorted(sd.iterdir()):
            if d.is_dir() and not d.name.startswith((".", "_")) and any(_is_mesh(q) for q in d.iterdir()):
                out.append(d)
    return out
