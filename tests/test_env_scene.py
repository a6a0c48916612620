"""Failure analysis through the real environment: scripted trajectories in a hand-built room with a
"couch" goal and a "toaster" distractor, each label of docs/spec.md#failure-labels checked from `info["metrics"]`.

Room interior [0, 6] x [0, 4] (x, z), floor y = 0, walls 2.5 m. Couch box x 0.3-1.5, z 0.2-0.9 (0.8 m
high) in the -z/-x corner; toaster box x 4.8-5.5, z 0.2-0.8 (0.6 m high) in the -z/+x corner. Yaw 0 looks
along -z (towards both objects), yaw pi along +z (towards the empty back wall).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from ovon.config.sim import AgentConfig, CameraConfig, SimConfig
from ovon.config.task import TaskConfig
from ovon.env import ObjectNavEnv
from ovon.scenes.model import Mesh, ObjectInstance, Scene
from ovon.sim.agent import LOOK_DOWN, LOOK_UP, MOVE_FORWARD, STOP, TURN_LEFT, TURN_RIGHT
from ovon.task.episode import EpisodeSpec
from tests.meshes import box, room_boxes

COUCH_ID, TOASTER_ID = 1, 2
COUCH_BOX = ((0.3, 0.0, 0.2), (1.5, 0.8, 0.9))
TOASTER_BOX = ((4.8, 0.0, 0.2), (5.5, 0.6, 0.8))


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


def objects_scene(scene_id: str = "couch-room") -> Scene:
    """The room above as a `Scene`: walls/floor have instance 0, the couch 1, the toaster 2."""
    parts: list[tuple[tuple, int, tuple[int, int, int]]] = [
        (b, 0, (200, 200, 190)) for b in room_boxes(0.0, 0.0, 6.0, 4.0)
    ]
    parts += [(COUCH_BOX, COUCH_ID, (120, 40, 40)), (TOASTER_BOX, TOASTER_ID, (90, 90, 200))]
    verts, faces, inst, cols = [], [], [], []
    off = 0
    for (lo, hi), iid, col in parts:
        v, f = box(lo, hi)
        verts.append(v)
        faces.append(f + off)
        inst.append(np.full(len(f), iid, dtype=np.int32))
        cols.append(np.tile(np.array(col, dtype=np.uint8), (len(f), 1)))
        off += len(v)
    mesh = Mesh(
        vertices=np.concatenate(verts).astype(np.float32),
        faces=np.concatenate(faces).astype(np.int32),
        face_colors=np.concatenate(cols),
        face_instance=np.concatenate(inst),
    )
    objects = [_instance(COUCH_ID, "couch", *COUCH_BOX), _instance(TOASTER_ID, "toaster", *TOASTER_BOX)]
    return Scene(scene_id=scene_id, mesh=mesh, objects=objects, floor_heights=[0.0], source="test")


def small_sim(backend: str = "auto") -> SimConfig:
    """64x48 frames, 60 deg HFOV: every scripted view below is unambiguous at this size."""
    return SimConfig(agent=AgentConfig(), camera=CameraConfig(width=64, height=48, hfov_deg=60.0, backend=backend))


@pytest.fixture(scope="module")
def env():
    e = ObjectNavEnv(scene=objects_scene(), goal="couch", sim=small_sim(), task=TaskConfig(max_steps=40))
    yield e
    e.close()


def run(
    env: ObjectNavEnv, start: tuple[float, float, float], yaw_deg: float, actions: list[int], max_steps: int = 40
) -> dict:
    """Reset at a given pose and play `actions`; returns the final info (must end the episode)."""
    env.task_cfg = TaskConfig(max_steps=max_steps)
    spec = EpisodeSpec(
        "scripted",
        "couch-room",
        "couch",
        start_position=np.array(start, dtype=np.float64),
        start_yaw=math.radians(yaw_deg),
    )
    env.reset(seed=0, options={"episode": spec})
    info: dict = {}
    for i, a in enumerate(actions):
        _, _, term, trunc, info = env.step(a)
        if term or trunc:
            assert i == len(actions) - 1, f"episode ended early at step {i}"
            break
    assert "metrics" in info, "scripted episode did not end"
    return info


F, L, R, S = MOVE_FORWARD, TURN_LEFT, TURN_RIGHT, STOP


def test_success(env):
    # from z=3.5 straight towards the couch; its 1 m viewpoint band starts at z=1.9
    info = run(env, (0.9, 0.0, 3.5), 0.0, [F] * 6 + [S])
    m = info["metrics"]
    assert m["success"] and m["failure"] is None
    assert m["goal_seen"] and m["spl"] > 0.9 and m["steps"] == 7
    # ends at z = 2.0, facing the couch: 1.1 m from its footprint (z 0.2-0.9), the couch in the last frame
    assert m["distance_to_object"] == pytest.approx(1.1, abs=0.02) and m["goal_in_view"]


def test_stop_wrong_object(env):
    # straight at the toaster (the couch is ~70 deg off-axis, out of the 60 deg view), 0.7 m from it; the
    # toaster (0.6 m high) is below the level camera's view there, so look down before the STOP: only an
    # object in view at the STOP makes it a wrong-object STOP
    info = run(env, (5.15, 0.0, 3.5), 0.0, [F] * 8 + [LOOK_DOWN, S])
    m = info["metrics"]
    assert not m["success"] and not m["goal_seen"]
    assert m["failure"] == "stop_wrong_object"
    # the STOP pose (5.15, 1.5) to the couch footprint's corner (1.5, 0.9); the couch is not in view
    assert m["distance_to_object"] == pytest.approx(math.hypot(3.65, 0.6), abs=0.02) and not m["goal_in_view"]


def test_stop_next_to_an_object_out_of_view_is_not_wrong_object(env):
    # the same walk without looking down: at 0.7 m the toaster has left the view, so the STOP says nothing
    # about it (it was seen on the way)
    info = run(env, (5.15, 0.0, 3.5), 0.0, [F] * 8 + [S])
    assert info["metrics"]["failure"] == "stop_never_saw_goal"


def test_stop_never_saw_goal(env):
    # facing the empty back wall, STOP in the middle of the room
    info = run(env, (3.0, 0.0, 2.0), 180.0, [S])
    assert info["metrics"]["failure"] == "stop_never_saw_goal"


def test_stop_too_far(env):
    # sees the couch from the back of the room and stops there
    info = run(env, (0.9, 0.0, 3.5), 0.0, [S])
    m = info["metrics"]
    assert m["goal_seen"] and m["failure"] == "stop_too_far"
    assert m["distance_to_object"] == pytest.approx(2.6) and m["goal_in_view"]


def test_timeout_missed_goal(env):
    # bumping into the back wall, looking up and down, until max_steps
    info = run(env, (3.0, 0.0, 3.0), 180.0, [F, F, F, F, LOOK_UP, LOOK_DOWN], max_steps=6)
    m = info["metrics"]
    assert not m["called_stop"] and not m["goal_seen"] and m["collisions"] >= 1
    assert m["failure"] == "timeout_missed_goal"


def test_timeout_ignored_goal(env):
    # sees the couch at reset, then turns away and spins in place
    info = run(env, (0.9, 0.0, 3.5), 0.0, [L] * 8, max_steps=8)
    m = info["metrics"]
    assert m["goal_seen"] and m["failure"] == "timeout_ignored_goal"


def test_timeout_left_goal(env):
    # walks into the success region, turns around and walks back out
    info = run(env, (0.9, 0.0, 3.5), 0.0, [F] * 6 + [L] * 6 + [F] * 3, max_steps=15)
    assert info["metrics"]["failure"] == "timeout_left_goal"


def test_stop_left_goal(env):
    info = run(env, (0.9, 0.0, 3.5), 0.0, [F] * 6 + [R] * 6 + [F] * 3 + [S])
    assert info["metrics"]["failure"] == "stop_left_goal"
