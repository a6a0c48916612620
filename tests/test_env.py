"""The Gymnasium environment: registration, the env checker, observations, the privileged channel,
episode end, odometry, noise vs ground truth, random and given starts, the vector env (hand-built room of
test_env_scene; one procedural house)."""

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
from ovon.env import ObjectNavEnv, make_objectnav
from ovon.sim.agent import LOOK_UP, MOVE_FORWARD, STOP, TURN_LEFT, TURN_RIGHT
from ovon.task.episode import EpisodeSpec, GoalViewpoint
from tests.test_env_scene import objects_scene, small_sim

SCENE = objects_scene()


def make(**kw) -> ObjectNavEnv:
    """The env; with privileged=True wrapped so that info["privileged"] holds the ground truth."""
    kw.setdefault("sim", small_sim())
    return make_objectnav(scene=SCENE, goal=kw.pop("goal", "couch"), **kw)


def truth(info: dict):
    return info["privileged"]


def given(start=(3.0, 0.0, 2.0), yaw_deg=0.0, **kw) -> dict:
    spec = EpisodeSpec(
        "given",
        SCENE.scene_id,
        "couch",
        start_position=np.array(start, dtype=np.float64),
        start_yaw=math.radians(yaw_deg),
        **kw,
    )
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
    for privileged in (False, True):
        env = make(privileged=privileged)
        check_env(env.unwrapped)
        env.close()


def test_observations_hold_no_ground_truth():
    """A plain env's observation and info carry nothing an agent could cheat with; the wrapper adds
    the one privileged channel."""
    env = make()
    obs, info = env.reset(seed=1)
    assert set(obs) == {"rgb", "depth", "odometry", "goal", "collided"}
    assert set(info) == {"episode_id"}
    assert obs["collided"] == 0
    assert obs["rgb"].shape == (48, 64, 3) and obs["rgb"].dtype == np.uint8
    assert obs["depth"].shape == (48, 64) and obs["depth"].dtype == np.float32
    assert obs["odometry"].dtype == np.float32
    for a in (MOVE_FORWARD, TURN_LEFT, STOP):
        obs, _, term, _, info = env.step(a)
        assert set(obs) == {"rgb", "depth", "odometry", "goal", "collided"}
        assert set(info) <= {"episode_id", "metrics"} and ("metrics" in info) == term
    env.close()
    env = make(privileged=True)
    obs, info = env.reset(seed=1)
    assert set(obs) == {"rgb", "depth", "odometry", "goal", "collided"}
    p = truth(info)
    assert p.frame.semantic.shape == (48, 64) and p.frame.semantic.dtype == np.int32
    assert p.state.position.shape == (3,) and math.isfinite(p.distance_to_goal)
    assert p.sim.camera.width == 64 and p.task.success_distance == 0.25
    assert env.observation_space.contains(obs)
    env.close()


def test_rgb_can_be_skipped():
    sim = small_sim()
    env = make(sim=dataclasses.replace(sim, camera=dataclasses.replace(sim.camera, rgb=False)), privileged=True)
    obs, info = env.reset(seed=1)
    assert "rgb" not in obs and "rgb" not in env.observation_space.spaces
    ref = make(privileged=True)
    _, ref_info = ref.reset(seed=1)
    np.testing.assert_array_equal(truth(info).frame.semantic, truth(ref_info).frame.semantic)
    np.testing.assert_array_equal(truth(info).frame.depth, truth(ref_info).frame.depth)
    env.close()
    ref.close()


def test_reset_is_deterministic():
    env = make(privileged=True)
    a = truth(env.reset(seed=7)[1]).state
    b = truth(env.reset(seed=7)[1]).state
    c = truth(env.reset(seed=8)[1]).state
    np.testing.assert_array_equal(a.position, b.position)
    assert a.yaw == b.yaw
    assert not np.array_equal(a.position, c.position)
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


def test_a_failed_stop_goes_on_when_training_says_so():
    """task.failed_stop_ends=false: a STOP far from the goal costs and the episode continues."""
    env = make(task=TaskConfig(failed_stop_ends=False, max_steps=3))
    env.reset(options=given())
    _, _, term, trunc, info = env.step(STOP)
    assert not term and not trunc and "metrics" not in info and env.tracker.failed_stops == 1
    env.step(TURN_LEFT)
    _, _, term, trunc, info = env.step(STOP)
    assert trunc and not term and not info["metrics"]["called_stop"]
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
    env = make(privileged=True)
    obs, _ = env.reset(options=given((3.0, 0.0, 3.0), yaw_deg=90.0))  # facing -x
    np.testing.assert_array_equal(obs["odometry"], np.zeros(3, np.float32))
    obs, *_ = env.step(MOVE_FORWARD)
    np.testing.assert_allclose(obs["odometry"], [0.25, 0.0, 0.0], atol=1e-5)
    obs, *_ = env.step(TURN_LEFT)
    np.testing.assert_allclose(obs["odometry"], [0.25, 0.0, math.radians(30)], atol=1e-5)
    obs, _, _, _, info = env.step(MOVE_FORWARD)
    # 30 deg left of the start heading: forward cos30, left sin30 in the start frame
    np.testing.assert_allclose(
        obs["odometry"][:2], [0.25 + 0.25 * math.cos(math.radians(30)), 0.25 * math.sin(math.radians(30))], atol=1e-5
    )
    # start frame: forward = -x, left = +z (yaw 90 deg looks along -x)
    np.testing.assert_allclose(
        truth(info).state.position[[0, 2]], [3.0 - obs["odometry"][0], 3.0 + obs["odometry"][1]], atol=1e-5
    )
    obs, *_ = env.step(LOOK_UP)
    np.testing.assert_allclose(obs["odometry"][2], math.radians(30), atol=1e-5)
    env.close()


def _walk(env, actions: list[int]) -> tuple[list[dict], list[np.ndarray]]:
    infos, odos = [], []
    for a in actions:
        obs, _, _, _, info = env.step(a)
        infos.append(info)
        odos.append(obs["odometry"])
    return infos, odos


def test_actuation_noise_moves_true_pose_and_metrics_follow_it():
    actions = [MOVE_FORWARD, MOVE_FORWARD, TURN_RIGHT, MOVE_FORWARD, STOP]
    clean = make(privileged=True)
    clean.reset(seed=0, options=given((3.0, 0.0, 3.0)))
    ci, _ = _walk(clean, actions)
    sim = small_sim()
    noisy = make(sim=dataclasses.replace(sim, noise=NoiseConfig(actuation="ilqr")), privileged=True)
    _, i0 = noisy.reset(seed=0, options=given((3.0, 0.0, 3.0)))
    ni, _ = _walk(noisy, actions)
    assert not np.allclose(truth(ci[-1]).state.position, truth(ni[-1]).state.position)
    # metrics are computed from the true (noisy) pose: path length and distance match the ground truth
    path = [truth(i0).state.position] + [truth(i).state.position for i in ni]
    length = sum(float(np.linalg.norm(b - a)) for a, b in zip(path[:-1], path[1:], strict=True))
    m = ni[-1]["metrics"]
    last = truth(ni[-1])
    assert m["path_length"] == pytest.approx(length)
    assert m["distance_to_goal"] == pytest.approx(last.goal_field.distance(last.state.position))
    assert m["distance_to_goal"] == pytest.approx(last.distance_to_goal)
    clean.close()
    noisy.close()


def test_odometry_noise_leaves_true_pose_alone():
    actions = [MOVE_FORWARD, TURN_LEFT, MOVE_FORWARD, MOVE_FORWARD]
    clean = make(privileged=True)
    clean.reset(seed=0, options=given((3.0, 0.0, 3.0)))
    ci, co = _walk(clean, actions)
    sim = small_sim()
    noisy = make(sim=dataclasses.replace(sim, noise=NoiseConfig(odometry=True)), privileged=True)
    noisy.reset(seed=0, options=given((3.0, 0.0, 3.0)))
    ni, no = _walk(noisy, actions)
    for a, b in zip(ci, ni, strict=True):
        np.testing.assert_array_equal(truth(a).state.position, truth(b).state.position)
        assert truth(a).distance_to_goal == truth(b).distance_to_goal
    err = np.abs(no[-1] - co[-1])
    assert err.max() > 0
    assert np.all(err[:2] <= 4 * 0.007 + 1e-6) and err[2] <= 4 * math.radians(2.0) + 1e-6
    clean.close()
    noisy.close()


def test_random_start_is_navigable_and_connected():
    env = make(privileged=True)
    for seed in range(10):
        _, info = env.reset(seed=seed)
        p = truth(info)
        assert p.grid.is_navigable(p.state.position)
        assert math.isfinite(p.distance_to_goal) and p.distance_to_goal > 0.25
        assert -math.pi <= p.state.yaw <= math.pi
    env.close()


def test_adhoc_viewpoints_are_built_once_and_equal_the_goal_band():
    """An ad-hoc episode's viewpoints (navigable cells within 1 m of the goal objects) are cached per goal
    set: every reset gets the same values, and the same shared objects (no rebuild per reset)."""
    from ovon.task.goals import points_near_objects

    env = make(privileged=True)
    _, info = env.reset(seed=0)
    first = truth(info)
    _, info = env.reset(seed=1)
    again = truth(info)
    assert again.viewpoints[0] is first.viewpoints[0] and len(again.viewpoints) == len(first.viewpoints)
    goals = [o for o in SCENE.objects if o.id in first.goal_ids]
    expected = points_near_objects(first.grid, goals)
    np.testing.assert_array_equal(np.stack([v.position for v in again.viewpoints]), expected)
    assert all(v.yaw == 0.0 for v in again.viewpoints)
    env.close()


def test_reset_with_episode_start_and_viewpoints():
    env = make(privileged=True)
    vp = GoalViewpoint(np.array([1.0, 0.0, 1.5]), 0.0)
    obs, info = env.reset(options=given((5.0, 0.0, 3.0), yaw_deg=45.0, viewpoints=[vp]))
    p = truth(info)
    np.testing.assert_allclose(p.state.position, [5.0, 0.0, 3.0])
    assert p.state.yaw == pytest.approx(math.radians(45.0))
    # geodesic = straight line in the empty middle of the room
    assert p.distance_to_goal == pytest.approx(math.hypot(4.0, 1.5), abs=0.1)
    assert p.viewpoints == [vp]
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
    env = gym.make("ovon/ObjectNav-v0", scene="procedural:0", goal=cat, sim=cpu_sim_config(), privileged=True)
    obs, info = env.reset(seed=0)
    assert obs["rgb"].shape == (128, 72, 3) and math.isfinite(truth(info).distance_to_goal)  # CPU portrait
    for a in (MOVE_FORWARD, TURN_LEFT, MOVE_FORWARD):
        obs, *_ = env.step(a)
    assert obs["rgb"].std() > 0
    env.close()


def _vector_trace(workers: int) -> np.ndarray:
    import functools

    from ovon.env.stack import EnvRecipe, build_env
    from ovon.env.vector import ObjectNavVectorEnv

    recipes = [
        EnvRecipe(sim=small_sim(), task=TaskConfig(max_steps=3), scene=SCENE, goal=g, privileged=True)
        for g in ("couch", "toaster", "couch")
    ]
    vec = ObjectNavVectorEnv([functools.partial(build_env, r) for r in recipes], workers=workers)
    try:
        obs, info = vec.reset(seed=0)
        assert obs["goal"] == ("couch", "toaster", "couch")
        assert obs["rgb"].shape == (3, 48, 64, 3) and obs["depth"].shape == (3, 48, 64)
        assert vec.observation_space.contains(obs)
        assert "privileged" not in info
        first = obs["depth"].copy()
        trace = [first]
        for t in range(4):
            obs, reward, term, trunc, info = vec.step(np.array([MOVE_FORWARD, TURN_LEFT, TURN_RIGHT]))
            assert obs["goal"] == ("couch", "toaster", "couch") and reward.shape == (3,)
            assert "privileged" not in info and "privileged" not in info.get("final_info", {})
            trace.append(obs["depth"].copy())
            if t == 2:  # all truncated at step 3, and the same step already returns the next episode
                assert trunc.all() and info["_final_info"].all()
                assert info["final_info"]["metrics"]["steps"].tolist() == [3, 3, 3]
            else:
                assert "final_info" not in info
        obs, info = vec.reset(seed=0)
        np.testing.assert_array_equal(obs["depth"], first)  # seeded resets repeat
        assert vec.call("render")[0].shape == (48, 64, 3)
    finally:
        vec.close()
    return np.stack(trace)


def test_vector_env_hosts_several_envs_per_worker():
    """Same-step autoreset, text goals, final_info with metrics, no ground truth crossing processes,
    and the same observations whether the envs run in this process or on 1 or 2 workers."""
    ref = _vector_trace(0)
    for workers in (1, 2):
        np.testing.assert_array_equal(_vector_trace(workers), ref)


def test_cli_sim_view_and_bench(tmp_path, capsys):
    from PIL import Image

    from ovon.cli.main import main

    out = tmp_path / "frame.png"
    assert main(["sim", "view", "procedural:0", "--width", "40", "--height", "30", "--out", str(out)]) == 0
    assert Image.open(out).size == (120, 30)
    out2 = tmp_path / "posed.png"
    assert (
        main(
            [
                "sim",
                "view",
                "procedural:0",
                "--pose",
                "2.4,0,4.3,-90",
                "--pitch",
                "-30",
                "--width",
                "40",
                "--height",
                "30",
                "--hfov",
                "90",
                "--backend",
                "embree",
                "--out",
                str(out2),
            ]
        )
        == 0
    )
    assert main(["sim", "view", "procedural:0", "--pose", "1,2", "--out", str(out2)]) == 2
    capsys.readouterr()
    for workers in ("0", "1"):
        assert (
            main(
                [
                    "sim",
                    "bench",
                    "--width",
                    "40",
                    "--height",
                    "30",
                    "--steps",
                    "30",
                    "--workers",
                    workers,
                    "--envs-per-worker",
                    "2",
                    "--no-rgb",
                ]
            )
            == 0
        )
        last = capsys.readouterr().out.strip().splitlines()[-1]
        value, unit = last.split(" ", 1)
        assert unit == "steps/s" and float(value) > 0
    assert main(["sim", "bench", "--workers", "-1"]) == 2


def test_collision_flag_in_the_observation():
    """Walking straight into the room's wall: the flag is 0 while free, 1 once MOVE_FORWARD is blocked,
    and it agrees with the tracker's collision count."""
    env = make()
    obs, _ = env.reset(options=given())
    flags, infos = [], []
    for _ in range(40):
        before = env.unwrapped.tracker.collisions
        obs, _, term, trunc, info = env.step(MOVE_FORWARD)
        flags.append(obs["collided"])
        infos.append(env.unwrapped.tracker.collisions > before)
        assert env.observation_space.contains(obs)
        if term or trunc:
            break
    assert flags[0] == 0 and flags[-1] == 1
    assert flags == [int(c) for c in infos]
