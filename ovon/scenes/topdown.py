"""Top-down picture of a scene for a person to look at: rooms, walls and objects, one panel per floor.

Walls are drawn as a horizontal cut through the mesh 1 m above each floor (like an architectural
plan), so the same code works for procedural houses and real scans.
"""

from __future__ import annotations

import zlib
from collections import Counter
from pathlib import Path

import numpy as np

from ovon.scenes.model import Scene

CUT_HEIGHT = 1.0  # metres above the floor where walls are cut
_ROOM_COLORS = {
    "living room": "#f4d6a0",
    "kitchen": "#c9e4c5",
    "dining room": "#f7c8b5",
    "bedroom": "#c5d5f0",
    "bathroom": "#b8e6ec",
    "office": "#e3d0f0",
    "hallway": "#e6e6e6",
    "laundry room": "#d8eadb",
    "garage": "#d0cbc5",
    "closet": "#eee3c8",
    "entryway": "#f0e0e8",
    "playroom": "#fbe5a6",
    "gym": "#d5e8f5",
}


def _room_color(name: str) -> str:
    if name in _ROOM_COLORS:
        return _ROOM_COLORS[name]
    import matplotlib

    rng = np.random.default_rng(zlib.crc32(name.encode()))  # stable across processes
    return matplotlib.colors.to_hex(0.75 + 0.25 * rng.random(3))


def slice_mesh(vertices: np.ndarray, faces: np.ndarray, y: float) -> np.ndarray:
    """Segments (K, 2, 2) in (x, z) where triangles cross the plane at height `y`."""
    tri = vertices[faces].astype(np.float64)  # (M, 3, 3)
    d = tri[:, :, 1] - y
    above = d > 0
    crossing = above.any(axis=1) & (~above).any(axis=1)
    tri, d = tri[crossing], d[crossing]
    segs = []
    for i, j in ((0, 1), (1, 2), (2, 0)):
        di, dj = d[:, i], d[:, j]
        cross = (di > 0) != (dj > 0)
        t = np.where(cross, di / np.where(cross, di - dj, 1.0), 0.0)
        p = tri[:, i] + t[:, None] * (tri[:, j] - tri[:, i])
        segs.append((cross, p[:, [0, 2]]))
    masks = np.stack([s[0] for s in segs], axis=1)
    pts = np.stack([s[1] for s in segs], axis=1)  # (M, 3, 2)
    two = masks.sum(axis=1) == 2
    return pts[two][masks[two]].reshape(-1, 2, 2)  # row-major: the two crossing edges of each triangle


def _obb_footprint(o) -> np.ndarray:
    c = np.asarray(o.obb_center, dtype=np.float64)
    h = np.asarray(o.obb_half_extents, dtype=np.float64)
    r = np.asarray(o.obb_rotation, dtype=np.float64)
    corners = [c + r @ (h * np.array([sx, 0.0, sz])) for sx, sz in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
    return np.array(corners)[:, [0, 2]]


def render_topdown(
    scene: Scene, out_png: str | Path, floor: int | None = None, legend_size: int = 15, dpi: int = 110
) -> Path:
    """Write a PNG with one panel per floor (or only `floor`)."""
    import matplotlib
    from matplotlib.collections import LineCollection, PolyCollection
    from matplotlib.figure import Figure  # no pyplot: the caller's backend stays as it is
    from matplotlib.patches import Patch, Rectangle

    heights = scene.floor_heights or [float(scene.mesh.vertices[:, 1].min())]
    floors = list(range(len(heights))) if floor is None else [floor]
    if floor is not None and not 0 <= floor < len(heights):
        raise ValueError(f"floor {floor} does not exist; scene {scene.scene_id} has floors 0..{len(heights) - 1}")
    kept = [o for o in scene.objects if o.category]
    common = [c for c, _ in Counter(o.category for o in kept).most_common(legend_size)]
    palette = [matplotlib.colormaps["tab20"](i) for i in range(20) if i not in (14, 15)]  # greys mean "other"
    cat_color = {c: palette[i % len(palette)] for i, c in enumerate(common)}
    other = (0.55, 0.55, 0.55, 1.0)
    mesh = scene.mesh
    n = len(floors)
    fig = Figure(figsize=(7.5 * n + 2.0, 7.5))
    axes = fig.subplots(1, n, squeeze=False)
    for ax, fl in zip(axes[0], floors):
        h = heights[fl]
        top = heights[fl + 1] if fl + 1 < len(heights) else np.inf
        # floor surface: upward faces near this floor's height
        v = mesh.vertices
        tri = v[mesh.faces]
        nrm = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        up = (nrm[:, 1] > 0.9 * np.linalg.norm(nrm, axis=1)) & (np.abs(tri[:, :, 1].mean(axis=1) - h) < 0.15)
        if up.any():
            ax.add_collection(PolyCollection(tri[up][:, :, [0, 2]], facecolors="#f2f2f2", edgecolors="none", zorder=0))
        for r in scene.regions:
            if r.floor != fl or r.bounds is None:
                continue
            x0, z0, x1, z1 = r.bounds
            ax.add_patch(Rectangle((x0, z0), x1 - x0, z1 - z0, facecolor=_room_color(r.name), alpha=0.6, zorder=1))
            ax.text(
                (x0 + x1) / 2,
                (z0 + z1) / 2,
                r.name,
                ha="center",
                va="center",
                fontsize=8,
                zorder=5,
                color="#333333",
                alpha=0.9,
            )
        segs = slice_mesh(v, mesh.faces, h + CUT_HEIGHT) if h + CUT_HEIGHT < top else np.zeros((0, 2, 2))
        if len(segs):
            ax.add_collection(LineCollection(segs, colors="#222222", linewidths=1.2, zorder=3))
        # large footprints first so small objects stay visible on top of rugs and tables
        objs = sorted(
            (o for o in kept if o.floor == fl),
            key=lambda o: -float(o.obb_half_extents[0]) * float(o.obb_half_extents[2]),
        )
        polys = [_obb_footprint(o) for o in objs]
        if polys:
            colors = [cat_color.get(o.category, other) for o in objs]
            ax.add_collection(
                PolyCollection(polys, facecolors=colors, edgecolors="k", linewidths=0.3, alpha=0.85, zorder=4)
            )
        ax.autoscale_view()
        ax.set_aspect("equal")
        ax.invert_yaxis()  # seen from above with x to the right, +z points down the page
        ax.set_xlabel("x (m)")
        ax.set_ylabel("z (m)")
        ax.set_title(f"{scene.scene_id} floor {fl} (y = {h:.2f} m): {len(objs)} objects")
    handles = [Patch(color=cat_color[c], label=c) for c in common]
    if len(cat_color) < len({o.category for o in kept}):
        handles.append(Patch(color=other, label="other"))
    if handles:
        axes[0, -1].legend(handles=handles, loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize=8,
                           title="categories")  # fmt: skip
    fig.tight_layout()
    out = Path(out_png)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=dpi)
    return out
