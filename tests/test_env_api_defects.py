"""API robustness of the env and the vector env: bad arguments are refused in one line before any work
(seeds, options, actions, configs, starts, render modes), and a refused or failed vector call leaves the
worker pipes in step (hand-built room of test_env_scene, tiny cameras)."""

from __future__ import annotations

import math
import os
import signal

import gymnasium as gym
import numpy as np
import pytest

from ovon.config.base import ConfigError
from ovon.config.sim import CameraConfig, SimConfig
from ovon.config.task import TaskConfig
from ovon.env.core import ObjectNavEnv
from ovon.env.stack import EnvRecipe, make_vector_env
from ovon.env.vector import VectorEnvClosedError, WorkerError
from ovon.sim.agent import MOVE_FORWARD, TURN_LEFT, TURN_RIGHT
from ovon.task.episode import EpisodeSpec
from tests.test_env_scene import objects_scene, small_sim

SCENE = objects_scene()


def make(**kw) -> ObjectNavEnv:
    kw.setdefault("sim", small_sim())
    return ObjectNavEnv(scene=kw.pop("scene", SCENE), goal=kw.pop("goal", "couch"), **kw)


def vector(workers: int):
    recipe = EnvRecipe(sim=small_sim(), task=TaskConfig(max_steps=20), scene=SCENE, goal="couch")
    return make_vector_env(recipe, 2, workers=workers)


def one_line(e: pytest.ExceptionInfo) -> str:
    msg = str(e.value)
    assert "\n" not in msg and "fix:" in msg, msg
    return msg


# -- defect 1: seeds, options and actions of the vector env; the pipes stay in step ------------------------
BAD_SEEDS = ([5], [1, 2, 3], "x", 1.5, -1, [0, "a"], True)
BAD_ACTIONS = ([TURN_LEFT], [1.7, 1], [1, 9], [-1, 1], ["a", "b"], None, [True, False], np.zeros((2, 1), int))


def test_vector_env_refuses_bad_seeds_and_actions_before_sending_and_stays_in_step():
    vec = vector(workers=2)
    try:
        obs, _ = vec.reset(seed=[3, 4])
        ref = obs["depth"].copy()
        for seed in BAD_SEEDS:
            with pytest.raises(ValueError, match="seed") as e:
                vec.reset(seed=seed)
            assert repr(seed)[:5] in one_line(e)
        for actions in BAD_ACTIONS:
            with pytest.raises(ValueError, match=r"actions = .*expected 2 integers in 0\.\.5") as e:
                vec.step(actions)
            one_line(e)
        with pytest.raises(ValueError, match="options"):
            vec.reset(seed=0, options=["episode"])
        # every refused call sent nothing: the next step gets its own replies
        obs, reward, term, trunc, _ = vec.step(np.array([TURN_LEFT, TURN_RIGHT]))
        assert reward.shape == (2,) and obs["depth"].shape == ref.shape and not term.any() and not trunc.any()
        # an env that raises in the first worker: the second worker's reply is read too
        with pytest.raises(WorkerError, match="action"):
            vec.call_each("step", [(99,), (TURN_LEFT,)])
        # an option the env refuses: raised by every worker, read from every worker
        with pytest.raises(WorkerError, match="options"):
            vec.reset(options={"episod": None})
        obs, reward, *_ = vec.step([MOVE_FORWARD, TURN_LEFT])
        assert reward.shape == (2,) and obs["goal"] == ("couch", "couch")
        obs, _ = vec.reset(seed=np.array([3, 4]))  # a numpy array of seeds is one per env
        np.testing.assert_array_equal(obs["depth"], ref)
        # a dead worker: said once, then every later call says the env is unusable
        os.kill(vec.worker_pids[1], signal.SIGKILL)
        with pytest.raises(WorkerError, match="died"):
            vec.step([TURN_LEFT, TURN_LEFT])
        with pytest.raises(WorkerError, match="unusable"):
            vec.reset(seed=0)
    finally:
        vec.close()


def test_vector_env_interrupted_between_send_and_reply_refuses_later_calls(monkeypatch):
    """Ctrl-C while a worker still owes a reply: the next call must not read that stale reply."""
    vec = vector(workers=2)
    try:
        vec.reset(seed=0)

        def interrupted(conn):
            raise KeyboardInterrupt

        monkeypatch.setattr(vec, "_recv", interrupted)
        with pytest.raises(KeyboardInterrupt):
            vec.step([TURN_LEFT, TURN_LEFT])
        monkeypatch.undo()
        with pytest.raises(WorkerError, match="unusable: a step call was interrupted") as e:
            vec.step([TURN_LEFT, TURN_LEFT])
        one_line(e)
    finally:
        vec.close()


def test_vector_env_in_process_refuses_bad_seeds():
    """workers=0 used to reset only env 0 for seed=[5] and ignore the rest of a too-long list."""
    vec = vector(workers=0)
    try:
        for seed in BAD_SEEDS:
            with pytest.raises(ValueError, match="seed"):
                vec.reset(seed=seed)
        obs, _ = vec.reset(seed=[7, None])
        assert obs["depth"].shape == (2, 48, 64)
        with pytest.raises(ValueError, match="actions"):
            vec.step([1.7, 1])
    finally:
        vec.close()


# -- defect 2: a closed vector env says so ----------------------------------------------------------------
def test_closed_vector_env_says_it_is_closed():
    vec = vector(workers=0)
    vec.reset(seed=0)
    vec.close()
    for call in (
        lambda: vec.step([1, 1]),
        lambda: vec.reset(),
        lambda: vec.call("render"),
        lambda: vec.set_state([None, None]),
    ):
        with pytest.raises(VectorEnvClosedError, match="the vector env is closed") as e:
            call()
        assert isinstance(e.value, ValueError) and isinstance(e.value, gym.error.ClosedEnvironmentError)
    vec.close()  # closing twice is fine


# -- defect 3: sim= / task= configs passed from Python are validated --------------------------------------
def _camera(**kw) -> SimConfig:
    return SimConfig(camera=CameraConfig(**{"width": 64, "height": 48, **kw}))


@pytest.mark.parametrize(
    ("kw", "key"),
    [
        ({"task": TaskConfig(success_distance=-1.0)}, "task.success_distance = -1.0"),
        ({"sim": _camera(min_depth=6.0, max_depth=5.0)}, "sim.camera.min_depth < sim.camera.max_depth"),
        ({"sim": _camera(width=-1)}, "sim.camera.width = -1"),
        ({"sim": _camera(hfov_deg=0.0)}, "sim.camera.hfov_deg = 0.0"),
        ({"sim": {"camera": {"widht": 64}}}, "sim.camera.widht"),
        ({"sim": 3}, "sim = 3: expected a SimConfig"),
        ({"task": SimConfig()}, "task = SimConfig"),
        ({"overrides": ["camera.width=64"]}, "unknown group"),
        ({"overrides": "sim.camera.width=64"}, "overrides = 'sim.camera.width=64'"),
    ],
)
def test_env_validates_its_configs_before_any_work(kw, key):
    with pytest.raises(ConfigError) as e:
        ObjectNavEnv(scene="no-such-scene", goal="couch", **kw)  # refused before the scene is looked up
    assert key in one_line(e) and "--set" not in str(e.value)


def test_env_accepts_a_mapping_of_config_fields():
    env = make(sim={"camera": {"width": 32, "height": 24, "hfov_deg": 60.0}}, task={"max_steps": 3})
    obs, _ = env.reset(seed=0)
    assert obs["depth"].shape == (24, 32) and env.task_cfg.max_steps == 3
    env.close()


# -- defect 4: a start off the map, NaN or with an infinite yaw ---------------------------------------------
def test_start_off_the_navigable_map_is_refused():
    env = make(start=(1000.0, 0.0, 1000.0, 0.0))
    with pytest.raises(ValueError, match=r"start \[1000.0, 0.0, 1000.0\] is not on the navigable map"):
        env.reset(seed=0)
    with pytest.raises(ValueError, match="start"):
        env.reset(
            seed=0,
            options={
                "episode": EpisodeSpec("high", SCENE.scene_id, "couch", start_position=np.array([3.0, 50.0, 2.0]))
            },
        )
    with pytest.raises(ValueError, match="start yaw = inf"):
        env.reset(
            seed=0,
            options={
                "episode": EpisodeSpec(
                    "yaw", SCENE.scene_id, "couch", start_position=np.array([3.0, 0.0, 2.0]), start_yaw=math.inf
                )
            },
        )
    with pytest.raises(gym.error.ResetNeeded):  # a failed reset leaves no episode to step
        env.step(TURN_LEFT)
    env.close()
    env = make(start=(3.0, 0.0, 2.0, 90.0))  # on the floor: accepted
    env.reset(seed=0)
    assert math.isfinite(env.privileged().distance_to_goal)
    env.close()


@pytest.mark.parametrize(
    "start", [(math.nan, 0.0, 2.0, 0.0), (3.0, 0.0, 2.0, math.inf), (3.0, 0.0, 2.0), ("3", 0, 2, 0), 5]
)
def test_start_that_is_not_four_finite_numbers_is_refused_at_construction(start):
    with pytest.raises(ValueError, match="start = .*expected 4 finite numbers") as e:
        make(start=start)
    one_line(e)


def test_pointnav_start_without_a_goal_point_is_refused():
    env = make(task=TaskConfig(kind="pointnav"), start=(3.0, 0.0, 2.0, 0.0))
    with pytest.raises(ValueError, match="needs its goal point"):
        env.reset(seed=0)
    env.close()


# -- defect 5: actions as Gymnasium's Discrete takes them ---------------------------------------------------
@pytest.mark.parametrize("action", [1.7, "1", None, np.array([1]), True, np.float64(1.0), 6, -1, np.bool_(True)])
def test_step_refuses_what_discrete_refuses(action):
    env = make()
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"action = .*Discrete\(6\)") as e:
        env.step(action)
    one_line(e)
    env.close()


def test_step_takes_ints_numpy_integers_and_0d_arrays():
    env = make()
    env.reset(seed=0)
    for action in (TURN_LEFT, np.int64(TURN_LEFT), np.array(TURN_RIGHT), env.action_space.sample() * 0 + 2):
        _, reward, *_ = env.step(action)
        assert isinstance(reward, float)
    env.close()


def test_step_before_reset_and_bad_reset_options_are_refused():
    env = make()
    with pytest.raises(gym.error.ResetNeeded, match="reset"):
        env.step(TURN_LEFT)
    for options in ({"episod": None}, {"episode": "couch"}, ["episode"]):
        with pytest.raises(ValueError, match="options"):
            env.reset(options=options)
    env.close()


# -- defect 6: render modes -----------------------------------------------------------------------------
@pytest.mark.parametrize("mode", ["human", "bogus", "RGB_ARRAY"])
def test_unknown_render_mode_is_refused(mode):
    with pytest.raises(ValueError, match=f"render_mode = '{mode}': expected None or one of") as e:
        make(render_mode=mode)
    one_line(e)


def test_known_render_modes_are_accepted():
    for mode in (None, "rgb_array"):
        env = make(render_mode=mode)
        assert env.render_mode == mode
        env.close()


def test_vector_env_refuses_bad_construction_arguments_before_starting_workers():
    recipe = EnvRecipe(sim=small_sim(), task=TaskConfig(success_distance=-1.0), scene=SCENE, goal="couch")
    with pytest.raises(ConfigError, match="task.success_distance = -1.0"):
        make_vector_env(recipe, 2, workers=2)
    ok = EnvRecipe(sim=small_sim(), scene=SCENE, goal="couch")
    for kw, key in (
        ({"num_envs": 0}, "num_envs = 0"),
        ({"num_envs": 2, "workers": -1}, "workers = -1"),
        ({"num_envs": 2, "workers": 1.5}, "workers = 1.5"),
    ):
        with pytest.raises(ValueError, match=key) as e:
            make_vector_env(ok, **kw)
        one_line(e)
