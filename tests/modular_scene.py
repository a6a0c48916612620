"""A hand-made two-room house for the modular-agent tests (Habitat frame, y up, metres).

Interior [0, 8] x [0, 4] (x, z), walls 2.5 m high, a partition at x = 4 with a doorway for z in [1.6, 2.6].
Room A (x < 4): a chair (id 3, 0.9 m high) at x 1.0-1.5, z 0.3-0.8. Room B (x > 4): a couch (id 1, 0.8 m)
at x 6.6-7.8, z 0.2-0.9, a sofa (id 2, 0.8 m) at x 6.6-7.8, z 3.1-3.8 and a toaster (id 4, 0.6 m) at
x 4.4-4.8, z 3.3-3.7. The agent starts in room A at (1.5, 2.5), where the partition hides room B.
"""

from __future__ import annotations

import numpy as np

from ovon.config.sim import AgentConfig, CameraConfig, SimConfig
from ovon.scenes.model import Mesh, ObjectInstance, Scene
from tests.meshes import box, room_boxes, wall_x_with_gap

OBJECTS = {
    1: ("couch", ((6.6, 0.0, 0.2), (7.8, 0.8, 0.9))),
    2: ("sofa", ((6.6, 0.0, 3.1), (7.8, 0.8, 3.8))),
    3: ("chair", ((1.0, 0.0, 0.3), (1.5, 0.9, 0.8))),
    4: ("toaster", ((4.4, 0.0, 3.3), (4.8, 0.6, 3.7))),
}
START = (1.5, 0.0, 2.5)


def _instance(iid: int, label: str, lo, hi) -> ObjectInstance:
    lo_a, hi_a = np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)
    return ObjectInstance(
        id=iid,
        raw_label=label,
        category=label,
        aabb_min=lo_a,
        aabb_max=hi_a,
        obb_center=(lo_a + hi_a) / 2,
        obb_half_extents=(hi_a - lo_a) / 2,
        obb_rotation=np.eye(3),
    )


def two_room_scene(scene_id: str = "two-rooms") -> Scene:
    parts = [(b, 0) for b in room_boxes(0.0, 0.0, 8.0, 4.0)]
    parts += [(b, 0) for b in wall_x_with_gap(4.0, 0.0, 4.0, 1.6, 2.6)]
    parts += [(boxes, iid) for iid, (_, boxes) in OBJECTS.items()]
    verts, faces, inst, cols = [], [], [], []
    off = 0
    rng = np.random.default_rng(0)
    for (lo, hi), iid in parts:
        v, f = box(lo, hi)
        verts.append(v)
        faces.append(f + off)
        inst.append(np.full(len(f), iid, dtype=np.int32))
        cols.append(np.tile(rng.integers(60, 220, 3).astype(np.uint8), (len(f), 1)))
        off += len(v)
    mesh = Mesh(
        vertices=np.concatenate(verts).astype(np.float32),
        faces=np.concatenate(faces).astype(np.int32),
        face_colors=np.concatenate(cols),
        face_instance=np.concatenate(inst),
    )
    objects = [_instance(i, name, *b) for i, (name, b) in OBJECTS.items()]
    return Scene(scene_id=scene_id, mesh=mesh, objects=objects, floor_heights=[0.0], source="test")


def portrait_sim(width: int = 48, height: int = 64, hfov: float = 60.0) -> SimConfig:
    """A small portrait camera that sees the floor from about 1 m."""
    return SimConfig(agent=AgentConfig(), camera=CameraConfig(width=width, height=height, hfov_deg=hfov))
