"""What a modular agent believes, drawn for `ovon video` (the agents' `debug_frame`): its own maps in its
episodic frame (start pose at the origin, start heading up), as VLFM's debug videos show them.

Left panel: unknown (dark), explored free space (light), obstacles (black) and their inflation by the
agent's radius (grey), frontier cells (cyan) with one waypoint each (cyan dots), the chosen frontier
(magenta ring), lifted goal points (red), the goal point with the stop radius around it (red ring), the
navigator's plan (yellow) and the agent (orange arrow). Right panel (VLFM): the language value map where
it has confidence (colour scale from the lowest to the highest stored value), obstacles, frontier
waypoints and the agent. Both panels show the same window: everything the agent has mapped, with a 1 m
margin, at least 6 m wide.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

UNKNOWN = (55, 55, 60)
FREE = (215, 215, 210)
INFLATED = (150, 150, 150)
OBSTACLE = (20, 20, 20)
FRONTIER = (0, 190, 230)
GOAL = (225, 30, 30)
TARGET = (220, 0, 220)
PATH = (235, 200, 0)
AGENT = (255, 120, 0)
MARGIN_M = 1.0
MIN_SIDE_M = 6.0


def _window(maps, extra_cells: list[tuple[int, int]]) -> tuple[int, int, int]:
    """(row0, col0, side) of the square window around everything mapped (and the given cells)."""
    rr, cc = np.nonzero(maps.explored | maps.obstacle)
    rows = np.concatenate([rr, [r for r, _ in extra_cells]]).astype(np.int64)
    cols = np.concatenate([cc, [c for _, c in extra_cells]]).astype(np.int64)
    n = maps.shape[0]
    if rows.size == 0:
        rows = cols = np.array([n // 2])
    pad = int(round(MARGIN_M / maps.cell_size))
    r0, r1 = int(rows.min()) - pad, int(rows.max()) + pad + 1
    c0, c1 = int(cols.min()) - pad, int(cols.max()) + pad + 1
    side = max(r1 - r0, c1 - c0, int(round(MIN_SIDE_M / maps.cell_size)))
    side = min(side, n)
    r0 = min(max(0, (r0 + r1 - side) // 2), n - side)
    c0 = min(max(0, (c0 + c1 - side) // 2), n - side)
    return r0, c0, side


class _Canvas:
    """A cropped map window scaled to `size` pixels, with map cells -> pixel centres."""

    def __init__(self, base: np.ndarray, r0: int, c0: int, side: int, size: int) -> None:
        self.r0, self.c0, self.scale = r0, c0, size / side
        self.img = cv2.resize(base, (size, size), interpolation=cv2.INTER_NEAREST)

    def px(self, row: float, col: float) -> tuple[int, int]:
        return int((col - self.c0 + 0.5) * self.scale), int((row - self.r0 + 0.5) * self.scale)


def _agent_arrow(canvas: _Canvas, maps, pose) -> None:
    r, c = maps.cell(pose.x, pose.z)
    x, y = canvas.px(r, c)
    k = max(8, int(0.5 / maps.cell_size * canvas.scale))  # 0.5 m long
    tip = (int(x - k * math.sin(pose.yaw)), int(y - k * math.cos(pose.yaw)))
    cv2.arrowedLine(canvas.img, (x, y), tip, AGENT, 2, tipLength=0.4)
    cv2.circle(canvas.img, (x, y), 3, AGENT, -1)


def _label(img: np.ndarray, text: str) -> None:
    cv2.rectangle(img, (0, 0), (img.shape[1], 16), (255, 255, 255), -1)
    cv2.putText(img, text, (4, 12), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (0, 0, 0), 1, cv2.LINE_AA)


def draw_beliefs(
    core,
    size: int,
    value_map=None,
    frontier_target: tuple[int, int] | None = None,
    title: str = "",
) -> np.ndarray:
    """(size, size or 2 * size, 3) uint8: the map panel, plus the value panel when `value_map` is given."""
    maps, memory, pose = core.maps, core.memory, core.pose
    cells: list[tuple[int, int]] = [maps.cell(pose.x, pose.z)]
    pts = memory.points if memory is not None else np.zeros((0, 3), np.float32)
    pr = np.floor((pts[:, 2] - maps.origin[1]) / maps.cell_size).astype(np.int64)
    pc = np.floor((pts[:, 0] - maps.origin[0]) / maps.cell_size).astype(np.int64)
    cells += list(zip(pr.tolist(), pc.tolist(), strict=True))
    r0, c0, side = _window(maps, cells)
    win = (slice(r0, r0 + side), slice(c0, c0 + side))
    explored, obstacle, navigable = maps.explored[win], maps.obstacle[win], maps.navigable[win]

    base = np.empty((side, side, 3), np.uint8)
    base[:] = UNKNOWN
    base[explored] = FREE
    base[~navigable] = INFLATED
    base[obstacle] = OBSTACLE
    fm = maps.frontier_map
    fr, fc = fm.frontier_rows - r0, fm.frontier_cols - c0
    ok = (fr >= 0) & (fr < side) & (fc >= 0) & (fc < side)
    base[fr[ok], fc[ok]] = FRONTIER
    inside = (pr >= r0) & (pr < r0 + side) & (pc >= c0) & (pc < c0 + side)
    base[pr[inside] - r0, pc[inside] - c0] = GOAL
    canvas = _Canvas(base, r0, c0, side, size)
    img = canvas.img
    waypoints = maps.frontiers()
    for r, c in zip(waypoints.rows.tolist(), waypoints.cols.tolist(), strict=True):
        cv2.circle(img, canvas.px(r, c), 3, FRONTIER, -1)
    if frontier_target is not None:
        cv2.circle(img, canvas.px(*frontier_target), 7, TARGET, 2)
    path = getattr(core.navigator, "path", None)
    if path is not None and len(path[0]) > 1:
        line = np.array([canvas.px(r, c) for r, c in zip(path[0].tolist(), path[1].tolist(), strict=True)], np.int32)
        cv2.polylines(img, [line], False, PATH, 1)
    goal = core.goal_point() if memory is not None else None
    if goal is not None:
        g = canvas.px(*maps.cell(*goal))
        stop = getattr(core.cfg.navigator, "stop_distance_m", 0.0)
        cv2.circle(img, g, max(2, int(stop / maps.cell_size * canvas.scale)), GOAL, 1)
        cv2.circle(img, g, 4, GOAL, -1)
    _agent_arrow(canvas, maps, pose)
    _label(img, title or "agent map")
    if value_map is None:
        return img

    conf = value_map.confidence[win] > 0
    val = value_map.value[win]
    vbase = np.empty((side, side, 3), np.uint8)
    vbase[:] = UNKNOWN
    if conf.any():
        lo, hi = float(val[conf].min()), float(val[conf].max())
        norm = np.zeros(val.shape, np.uint8)
        norm[conf] = np.clip(255.0 * (val[conf] - lo) / max(hi - lo, 1e-6), 0, 255).astype(np.uint8)
        colours = cv2.applyColorMap(norm, cv2.COLORMAP_INFERNO)[..., ::-1]
        vbase[conf] = colours[conf]
        vtitle = f"value map {lo:.2f}..{hi:.2f}"
    else:
        vtitle = "value map (empty)"
    vbase[obstacle] = OBSTACLE
    vcanvas = _Canvas(vbase, r0, c0, side, size)
    for r, c in zip(waypoints.rows.tolist(), waypoints.cols.tolist(), strict=True):
        cv2.circle(vcanvas.img, vcanvas.px(r, c), 3, FRONTIER, -1)
    if frontier_target is not None:
        cv2.circle(vcanvas.img, vcanvas.px(*frontier_target), 7, TARGET, 2)
    _agent_arrow(vcanvas, maps, pose)
    _label(vcanvas.img, vtitle)
    sep = np.full((size, 2, 3), 255, np.uint8)
    return np.concatenate([img, sep, vcanvas.img], axis=1)
