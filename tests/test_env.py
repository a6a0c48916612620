"""The Gymnasium environment: registration, the env checker, observations, episode end, odometry,
noise vs ground truth, random and given starts (hand-built room of test_env_scene; one procedural house)."""

from __future__ import annotations

import dataclasses
import math

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import ovon  # noqa: F401  (registers the env)
from ovon.config.sim import NoiseConfig
from ovon.config.task import TaskConfig
from ovon.sim.agent import LOOK_UP, MOVE_FORWARD, STOP, TURN_LEFT, TURN_RIGHT
from ovon.sim.env import ObjectNavEnv
from ovon.task.episode import EpisodeSpec, GoalViewpoint
from tests.test_env_scene import objects_scene, small_sim

SCENE = objects_scene()


def make(**kw) -> ObjectNavEnv:
    kw.setdefault("sim", small_sim())
    return ObjectNavEnv(scene=SCENE, goal=kw.pop("goal", "couch"), **kw)


def given(start=(3.0, 0.0, 2.0), yaw_deg=0.0, **kw) -> dict:
    spec = EpisodeSpec("given", SCENE.scene_id, "couch", start_position=np.array(start, dtype=np.float64),
                       start_yaw=math.radians(yaw_deg), **kw)
    return {"episode": spec}


def test_gym_make_registered():
    env = gym.make("ovon/ObjectNav-v0", scene=SCENE, goal="couch", sim=small_sim())
    obs, info = env.reset(seed=0)
    assert obs["goal"] == "couch"
    assert env.observation_space.contains(obs)
    obs, reward, term, trunc, info = env.step(TURN_LEFT)
    assert isinstance(reward, float) and not term and not trunc
    env.close()


def test_check_env():
    env = make(privileged=True)
    check_env(env)
    env.close()


def test_observations_and_privileged_semantic():
    env = make()
    obs, info = env.reset(seed=1)
    assert set(obs) == {"rgb", "depth", "odometry", "goal", "collided"}
    assert obs["collided"] == 0
    assert obs["rgb"].shape == (48, 64, 3) and obs["rgb"].dtype == np.uint8
    assert obs["depth"].shape == (48, 64) and obs["depth"].dtype == np.float32
    assert obs["odometry"].dtype == np.float32
    env.close()
    env = make(privileged=True)
    obs, _ = env.reset(seed=1)
    assert obs["semantic"].shape == (48, 64) and obs["semantic"].dtype == np.int32
    assert env.observation_space.contains(obs)
    env.close()


def test_info_has_true_pose_and_reset_is_deterministic():
    env = make()
    _, a = env.reset(seed=7)
    _, b = env.reset(seed=7)
    _, c = env.reset(seed=8)
    for info in (a, b):
        assert info["position"].shape == (3,) and "yaw" in info and "pitch" in info
    np.testing.assert_array_equal(a["position"], b["position"])
    assert a["yaw"] == b["yaw"]
    assert not np.array_equal(a["position"], c["position"])
    env.close()


def test_stop_ends_episode_with_metrics():
    env = make()
    env.reset(options=given())
    _, _, term, trunc, info = env.step(STOP)
    assert term and not trunc
    m = info["metrics"]
    assert m["called_stop"] and m["steps"] == 1 and not m["success"]
    with pytest.raises(RuntimeError):
        env.step(TURN_LEFT)
    env.close()


def test_max_steps_truncates():
    env = make(task=TaskConfig(max_steps=3))
    env.reset(options=given())
    outs = [env.step(TURN_LEFT) for _ in range(3)]
    assert [o[3] for o in outs] == [False, False, True]
    assert not any(o[2] for o in outs)
    assert outs[-1][4]["metrics"]["steps"] == 3 and "metrics" not in outs[0][4]
    env.close()


def test_odometry_starts_at_zero_and_tracks_motion():
    env = make()
    obs, _ = env.reset(options=given((3.0, 0.0, 3.0), yaw_deg=90.0))  # facing -x
    np.testing.assert_array_equal(obs["odometry"], np.zeros(3, np.float32))
    obs, *_ = env.step(MOVE_FORWARD)
    np.testing.assert_allclose(obs["odometry"], [0.25, 0.0, 0.0], atol=1e-5)
    obs, *_ = env.step(TURN_LEFT)
    np.testing.assert_allclose(obs["odometry"], [0.25, 0.0, math.radians(30)], atol=1e-5)
    obs, _, _, _, info = env.step(MOVE_FORWARD)
    # 30 deg left of the start heading: forward cos30, left sin30 in the start frame
    np.testing.assert_allclose(obs["odometry"][:2], [0.25 + 0.25 * math.cos(math.radians(30)),
                                                     0.25 * math.sin(math.radians(30))], atol=1e-5)
    # start frame: forward = -x, left = +z (yaw 90 deg looks along -x)
    np.testing.assert_allclose(info["position"][[0, 2]], [3.0 - obs["odometry"][0], 3.0 + obs["odometry"][1]],
                               atol=1e-5)
    obs, *_ = env.step(LOOK_UP)
    np.testing.assert_allclose(obs["odometry"][2], math.radians(30), atol=1e-5)
    env.close()


def _walk(env: ObjectNavEnv, actions: list[int]) -> tuple[list[dict], list[np.ndarray]]:
    infos, odos = [], []
    for a in actions:
        obs, _, _, _, info = env.step(a)
        infos.append(info)
        odos.append(obs["odometry"])
    return infos, odos


def test_actuation_noise_moves_true_pose_and_metrics_follow_it():
    actions = [MOVE_FORWARD, MOVE_FORWARD, TURN_RIGHT, MOVE_FORWARD, STOP]
    clean = make()
    clean.reset(seed=0, options=given((3.0, 0.0, 3.0)))
    ci, _ = _walk(clean, actions)
    sim = small_sim()
    noisy = make(sim=dataclasses.replace(sim, noise=NoiseConfig(actuation="ilqr")))
    _, i0 = noisy.reset(seed=0, options=given((3.0, 0.0, 3.0)))
    ni, _ = _walk(noisy, actions)
    assert not np.allclose(ci[-1]["position"], ni[-1]["position"])
    # metrics are computed from the true (noisy) pose: path length and distance match info
    path = [i0["position"]] + [i["position"] for i in ni]
    length = sum(float(np.linalg.norm(b - a)) for a, b in zip(path[:-1], path[1:], strict=True))
    m = ni[-1]["metrics"]
    assert m["path_length"] == pytest.approx(length)
    assert m["distance_to_goal"] == pytest.approx(noisy.privileged().goal_field.distance(ni[-1]["position"]))
    assert m["distance_to_goal"] == pytest.approx(ni[-1]["distance_to_goal"])
    clean.close()
    noisy.close()


def test_odometry_noise_leaves_true_pose_alone():
    actions = [MOVE_FORWARD, TURN_LEFT, MOVE_FORWARD, MOVE_FORWARD]
    clean = make()
    clean.reset(seed=0, options=given((3.0, 0.0, 3.0)))
    ci, co = _walk(clean, actions)
    sim = small_sim()
    noisy = make(sim=dataclasses.replace(sim, noise=NoiseConfig(odometry=True)))
    noisy.reset(seed=0, options=given((3.0, 0.0, 3.0)))
    ni, no = _walk(noisy, actions)
    for a, b in zip(ci, ni, strict=True):
        np.testing.assert_array_equal(a["position"], b["position"])
        assert a["distance_to_goal"] == b["distance_to_goal"]
    err = np.abs(no[-1] - co[-1])
    assert err.max() > 0
    assert np.all(err[:2] <= 4 * 0.007 + 1e-6) and err[2] <= 4 * math.radians(2.0) + 1e-6
    clean.close()
    noisy.close()


def test_random_start_is_navigable_and_connected():
    env = make()
    for seed in range(10):
        _, info = env.reset(seed=seed)
        priv = env.privileged()
        assert priv.grid.is_navigable(info["position"])
        assert math.isfinite(info["distance_to_goal"]) and info["distance_to_goal"] > 0.25
        assert -math.pi <= info["yaw"] <= math.pi
    env.close()


def test_reset_with_episode_start_and_viewpoints():
    env = make()
    vp = GoalViewpoint(np.array([1.0, 0.0, 1.5]), 0.0)
    obs, info = env.reset(options=given((5.0, 0.0, 3.0), yaw_deg=45.0, viewpoints=[vp]))
    np.testing.assert_allclose(info["position"], [5.0, 0.0, 3.0])
    assert info["yaw"] == pytest.approx(math.radians(45.0))
    # geodesic = straight line in the empty middle of the room
    assert info["distance_to_goal"] == pytest.approx(math.hypot(4.0, 1.5), abs=0.1)
    assert env.privileged().viewpoints == [vp]
    env.close()


def test_too_long_goal_is_rejected():
    env = make(goal="x" * 100)
    with pytest.raises(ValueError):
        env.reset(seed=0)
    env.close()


def test_procedural_house_smoke():
    from ovon.config.sim import cpu_sim_config
    from ovon.scenes.procedural import generate_house

    cat = generate_house(0).categories[0]
    env = gym.make("ovon/ObjectNav-v0", scene="procedural:0", goal=cat, sim=cpu_sim_config())
    obs, info = env.reset(seed=0)
    assert obs["rgb"].shape == (120, 160, 3) and math.isfinite(info["distance_to_goal"])
    for a in (MOVE_FORWARD, TURN_LEFT, MOVE_FORWARD):
        obs, *_ = env.step(a)
    assert obs["rgb"].std() > 0
    env.close()


@pytest.mark.parametrize("shared_memory", [True, False])
def test_vector_env_two_workers(shared_memory):
    from ovon.sim.vector import make_vector_env

    kw = [dict(scene=SCENE, goal="couch", sim=small_sim(), task=TaskConfig(max_steps=3)),
          dict(scene=SCENE, goal="toaster", sim=small_sim(), task=TaskConfig(max_steps=3))]
    vec = make_vector_env(2, kw, shared_memory=shared_memory)
    try:
        obs, info = vec.reset(seed=0)
        assert obs["goal"] == ("couch", "toaster")
        assert obs["rgb"].shape == (2, 48, 64, 3) and obs["depth"].shape == (2, 48, 64)
        assert vec.observation_space.contains(obs)
        pos0 = info["position"].copy()
        ends = 0
        for _ in range(4):
            obs, reward, term, trunc, info = vec.step(np.array([MOVE_FORWARD, TURN_LEFT]))
            assert obs["goal"] == ("couch", "toaster") and reward.shape == (2,)
            ends += int(trunc.sum())
        assert ends == 2  # both truncated at step 3; step 4 was the auto-reset (NextStep mode)
        obs, info = vec.reset(seed=0)
        np.testing.assert_array_equal(info["position"], pos0)  # seeded resets repeat
    finally:
        vec.close()


def test_cli_sim_view_and_bench(tmp_path, capsys):
    from PIL import Image

    from ovon.cli.main import main

    out = tmp_path / "frame.png"
    assert main(["sim", "view", "procedural:0", "--width", "40", "--height", "30", "--out", str(out)]) == 0
    assert Image.open(out).size == (120, 30)
    out2 = tmp_path / "posed.png"
    assert main(["sim", "view", "procedural:0", "--pose", "2.4,0,4.3,-90", "--pitch", "-30", "--width", "40",
                 "--height", "30", "--hfov", "90", "--backend", "embree", "--out", str(out2)]) == 0
    assert main(["sim", "view", "procedural:0", "--pose", "1,2", "--out", str(out2)]) == 2
    capsys.readouterr()
    assert main(["sim", "bench", "--width", "40", "--height", "30", "--steps", "30"]) == 0
    last = capsys.readouterr().out.strip().splitlines()[-1]
    value, unit = last.split(" ", 1)
    assert unit == "steps/s" and float(value) > 0


def test_collision_flag_in_the_observation():
    """Walking straight into the room's wall: the flag is 0 while free, 1 once MOVE_FORWARD is blocked,
    and it agrees with info["collided"]."""
    env = make()
    obs, _ = env.reset(options=given())
    flags, infos = [], []
    for _ in range(40):
        obs, _, term, trunc, info = env.step(MOVE_FORWARD)
        flags.append(obs["collided"])
        infos.append(info["collided"])
        assert env.observation_space.contains(obs)
        if term or trunc:
            break
    assert flags[0] == 0 and flags[-1] == 1
    assert flags == [int(c) for c in infos]
