"""Labelled frames for pretraining and evaluating perception: RGB from the task camera, labels from the
semantic sensor.

Why two kinds of pose: random navigable poses give the frame statistics an agent meets (mostly walls and
floor), poses 0.5-2.5 m from an object facing it give enough pixels of small and rare categories. Each
house's frames are one seeded draw, cached as one `.npz` per house (written atomically), so an interrupted
render resumes where it stopped and the same seed gives the same arrays whatever the order of houses.

Per frame: `rgb` (H, W, 3) uint8, `cells` (GH, GW) int16 category index per grid cell (-1: wall, floor,
ceiling, nothing), and per visible instance one row of `inst`: frame, category index, frame share (fraction
of pixels), box (x0, y0, x1, y1), instance id.
"""

from __future__ import annotations

import math
import zlib
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ovon.atomic import atomic_write_with
from ovon.config.sim import SimConfig, cpu_sim_config
from ovon.scenes.model import Scene

STRIDE = 4  # pixels per grid cell: frames 128 high x 72 wide give a grid of 32 rows x 18 columns
FACING_RANGE = (0.5, 2.5)  # metres from a facing pose to its object's centre
RANDOM_PITCHES = (0.0, 0.0, 0.0, 0.0, -30.0, 30.0, -60.0)  # degrees, drawn uniformly


@dataclass
class HouseFrames:
    scene_id: str
    rgb: np.ndarray  # (N, H, W, 3) uint8
    cells: np.ndarray  # (N, GH, GW) int16
    inst: np.ndarray  # (M, 8) float32: frame, category, share, x0, y0, x1, y1, instance id
    house_cats: np.ndarray  # (C,) int: category indices of every object of the house (visible or not)

    def save(self, path: Path) -> None:
        atomic_write_with(
            path,
            lambda fh: np.savez(
                fh, scene_id=self.scene_id, rgb=self.rgb, cells=self.cells, inst=self.inst, house_cats=self.house_cats
            ),
        )

    @classmethod
    def load(cls, path: Path) -> HouseFrames:
        with np.load(path) as z:
            return cls(str(z["scene_id"]), z["rgb"], z["cells"], z["inst"], z["house_cats"])


def category_index(names: Sequence[str]) -> dict[str, int]:
    return {n: i for i, n in enumerate(names)}


def _rng(seed: int, scene_id: str) -> np.random.Generator:
    return np.random.default_rng([int(seed), zlib.crc32(scene_id.encode())])


def _facing_pose(world, obj, rng: np.random.Generator, cam_h: float) -> tuple[np.ndarray, float, float] | None:
    """A navigable point 0.5-2.5 m from the object's centre on its floor, looking at it."""
    centre = (np.asarray(obj.aabb_min) + np.asarray(obj.aabb_max)) / 2
    grid = world.nav.grid_for(centre)
    rows, cols = np.nonzero(grid.navigable)
    if len(rows) == 0:
        return None
    xs = grid.origin[0] + (cols + 0.5) * grid.cell_size
    zs = grid.origin[1] + (rows + 0.5) * grid.cell_size
    dist = np.hypot(xs - centre[0], zs - centre[2])
    ok = np.flatnonzero((dist >= FACING_RANGE[0]) & (dist <= FACING_RANGE[1]))
    if len(ok) == 0:
        return None
    k = ok[int(rng.integers(len(ok)))]
    pos = grid.cell_to_world(int(rows[k]), int(cols[k]))
    dx, dz = centre[0] - pos[0], centre[2] - pos[2]
    yaw = math.atan2(-dx, -dz) + float(rng.normal(0.0, 0.15))
    pitch = math.atan2(centre[1] - (pos[1] + cam_h), max(math.hypot(dx, dz), 1e-3))
    return pos, yaw, float(np.clip(pitch, -math.radians(60), math.radians(60)))


def render_house(
    scene: Scene | str, n_frames: int, seed: int, names: Sequence[str], sim: SimConfig | None = None
) -> HouseFrames:
    """`n_frames` labelled frames of one scene: half from random navigable poses, half facing objects."""
    from ovon.sim.world import build_world

    sim = sim or cpu_sim_config()
    world = build_world(scene, sim)
    try:
        return _render(world, n_frames, seed, category_index(names), sim)
    finally:
        world.close()


def _render(world, n_frames: int, seed: int, index: dict[str, int], sim: SimConfig) -> HouseFrames:
    scene = world.scene
    rng = _rng(seed, scene.scene_id or str(scene.source))
    cam_h = float(sim.camera.camera_height)
    cat_of = np.full(len(scene.objects) + 2, -1, dtype=np.int32)
    for o in scene.objects:
        if o.category is not None and o.category in index and o.id < len(cat_of):
            cat_of[o.id] = index[o.category]
    goals = [o for o in scene.objects if o.category is not None and o.category in index]
    floors = [g for g in world.nav.floors if g.navigable.any()]
    if not floors:
        raise ValueError(f"scene {scene.scene_id or scene.source}: no navigable floor to render frames from")
    H, W = sim.camera.height, sim.camera.width
    rgbs, cells, inst = [], [], []
    attempts = 0
    while len(rgbs) < n_frames and attempts < 4 * n_frames:
        attempts += 1
        pose = None
        if goals and rng.random() < 0.5:
            pose = _facing_pose(world, goals[int(rng.integers(len(goals)))], rng, cam_h)
        if pose is None:
            grid = floors[int(rng.integers(len(floors)))]
            pos = grid.random_point(rng)
            pose = (pos, float(rng.uniform(-math.pi, math.pi)), math.radians(float(rng.choice(RANDOM_PITCHES))))
        pos, yaw, pitch = pose
        frame = world.renderer.render(np.asarray(pos) + np.array([0.0, cam_h, 0.0]), yaw, pitch)
        sem = np.asarray(frame.semantic)
        sem = np.where((sem >= 0) & (sem < len(cat_of)), sem, 0)
        cat = cat_of[sem]
        f = len(rgbs)
        rgbs.append(np.asarray(frame.rgb, dtype=np.uint8))
        cells.append(cat[STRIDE // 2 :: STRIDE, STRIDE // 2 :: STRIDE].astype(np.int16))
        ids, counts = np.unique(sem[cat >= 0], return_counts=True)
        for iid, cnt in zip(ids.tolist(), counts.tolist()):
            ys, xs = np.nonzero(sem == iid)
            box = (xs.min(), ys.min(), xs.max() + 1, ys.max() + 1)
            inst.append((f, cat_of[iid], cnt / (H * W), *box, iid))
    if not rgbs:
        raise ValueError(f"scene {scene.scene_id or scene.source}: no frame could be rendered")
    return HouseFrames(
        scene.scene_id,
        np.stack(rgbs),
        np.stack(cells),
        np.asarray(inst, dtype=np.float32).reshape(-1, 8),
        np.unique(cat_of[cat_of >= 0]).astype(np.int32),
    )
