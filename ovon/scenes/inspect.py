"""A scene at a glance: counts a person checks before trusting a scene (floors, rooms, categories, how
many annotated objects survived label cleaning). The navigable area per floor comes from the simulator
layer above (`ovon.sim.navsummary`); `print_summary` prints it when the summary holds it."""

from __future__ import annotations

from collections import Counter
from pathlib import Path
from typing import Any

from ovon.scenes.model import Scene


def summarize(scene: Scene) -> dict[str, Any]:
    """Plain-data summary of a scene (JSON-serialisable)."""
    lo, hi = scene.mesh.bounds() if scene.mesh.num_faces else (None, None)
    kept = [o for o in scene.objects if o.category]
    dropped = [o for o in scene.objects if not o.category]
    cats = Counter(o.category for o in kept)
    rooms = []
    for r in scene.regions:
        area = None
        if r.bounds is not None:
            area = round(float((r.bounds[2] - r.bounds[0]) * (r.bounds[3] - r.bounds[1])), 2)
        n_obj = sum(1 for o in kept if o.region_id == r.id)
        rooms.append({"id": r.id, "name": r.name, "floor": r.floor, "area_m2": area, "objects": n_obj})
    mesh = scene.mesh
    return {
        "scene_id": scene.scene_id,
        "source": scene.source,
        "triangles": mesh.num_faces,
        "vertices": int(len(mesh.vertices)),
        "semantic_triangles": scene.semantic_mesh.num_faces if scene.semantic_mesh is not None else None,
        "textured": mesh.texture is not None,
        "bounds_min": None if lo is None else [round(float(v), 3) for v in lo],
        "bounds_max": None if hi is None else [round(float(v), 3) for v in hi],
        "floors": [round(float(h), 3) for h in scene.floor_heights],
        "rooms": rooms,
        "annotations": "none: " + scene.semantics_missing if scene.semantics_missing else "HM3DSem",
        "objects_total": len(scene.objects),
        "objects_kept": len(kept),
        "objects_dropped": len(dropped),
        "dropped_labels": dict(Counter(o.raw_label for o in dropped).most_common()),
        "categories": dict(sorted(cats.items(), key=lambda kv: (-kv[1], kv[0]))),
    }


def print_summary(summary: dict[str, Any], console: Any = None, max_categories: int = 60) -> None:
    """Rich tables: overview, rooms, objects per category."""
    from rich.console import Console
    from rich.table import Table

    console = console or Console()
    over = Table(title=f"Scene {summary['scene_id']}", show_header=False)
    over.add_column("key", style="bold")
    over.add_column("value")
    over.add_row("source", str(summary["source"]))
    tri = f"{summary['triangles']:,}"
    if summary["semantic_triangles"] is not None:
        tri += f" (semantic mesh: {summary['semantic_triangles']:,})"
    over.add_row("triangles", tri)
    over.add_row("textured", "yes" if summary["textured"] else "no")
    over.add_row("bounds", f"{summary['bounds_min']} .. {summary['bounds_max']}")
    over.add_row(
        "floors (y, m)",
        ", ".join(f"{h:.2f}" for h in summary["floors"])
        or "none found (no upward horizontal face: is the up axis right? see --up)",
    )
    over.add_row("annotations", summary["annotations"])
    over.add_row("rooms", str(len(summary["rooms"])))
    over.add_row(
        "objects",
        f"{summary['objects_total']} annotated: {summary['objects_kept']} kept, "
        f"{summary['objects_dropped']} dropped by cleaning",
    )
    over.add_row("categories", str(len(summary["categories"])))
    if summary["dropped_labels"]:
        top = ", ".join(f"{k} ({v})" for k, v in list(summary["dropped_labels"].items())[:8])
        over.add_row("dropped labels", top)
    for f in summary.get("navigation", []):
        over.add_row(
            f"floor {f['floor']} navigable",
            f"{f['navigable_m2']:.1f} m² at y={f['height']:.2f} in "
            f"{f['islands']} islands; {f['start_area_m2']:.1f} m² on islands big enough for starts; "
            f"{f['narrow_removed_m2']:.1f} m² of strips too narrow to drive removed"
            + (f" (from {Path(f['source']).name})" if f.get("source", "mesh") != "mesh" else ""),
        )
    console.print(over)

    if summary["rooms"]:
        rooms = Table(title="Rooms")
        for col in ("id", "name", "floor", "area m²", "objects"):
            rooms.add_column(col, justify="right" if col != "name" else "left")
        for r in summary["rooms"]:
            area = "-" if r["area_m2"] is None else f"{r['area_m2']:.1f}"
            rooms.add_row(str(r["id"]), r["name"], str(r["floor"]), area, str(r["objects"]))
        console.print(rooms)

    cats = list(summary["categories"].items())
    if cats:
        shown = cats[:max_categories]
        table = Table(title=f"Objects per category ({len(cats)} categories)")
        ncol = 3
        for _ in range(ncol):
            table.add_column("category")
            table.add_column("n", justify="right")
        rows = (len(shown) + ncol - 1) // ncol
        for i in range(rows):
            cells: list[str] = []
            for j in range(ncol):
                k = j * rows + i
                cells += [shown[k][0], str(shown[k][1])] if k < len(shown) else ["", ""]
            table.add_row(*cells)
        console.print(table)
        if len(cats) > len(shown):
            console.print(f"... and {len(cats) - len(shown)} more categories")
