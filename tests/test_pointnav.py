"""PointNav: sampled episodes, the goal vector, the success radius, PPO end to end with exact resume,
evaluation on held-out houses and the learned navigator inside VLFM."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest
import torch

torch.set_num_threads(1)

from ovon.config.task import TaskConfig  # noqa: E402
from ovon.env.core import ObjectNavEnv  # noqa: E402
from ovon.task.episode import EpisodeSpec, GoalViewpoint  # noqa: E402
from ovon.task.pointgoal import POINT_GOAL, goal_vector, point_goal_vector, pointnav_specs  # noqa: E402
from ovon.train.config import train_preset  # noqa: E402

SCENE = "procedural:0"


@pytest.fixture(scope="module")
def tiny_cfg():
    return train_preset("tiny", "pointnav")


def _env(cfg, task: TaskConfig | None = None) -> ObjectNavEnv:
    return ObjectNavEnv(episodes=pointnav_specs([SCENE]), sim=cfg.sim, task=task or cfg.task)


# ----- episodes and observations ---------------------------------------------------------------------
def test_episodes_sample_within_the_distance_range(tiny_cfg) -> None:
    task = dataclasses.replace(tiny_cfg.task, point_min_distance_m=2.0, point_max_distance_m=3.0)
    env = _env(tiny_cfg, task)
    d0s = []
    for seed in range(12):
        obs, _ = env.reset(seed=seed, options={"episode": pointnav_specs([SCENE])[0]})
        d0 = env.tracker.d0
        assert 2.0 <= d0 <= 3.0
        # rho (straight line) is never longer than the geodesic distance
        assert obs["pointgoal"][0] <= d0 + 0.05  # the grid's geodesic is a few mm off the straight line
        assert "pointgoal" in env.observation_space.spaces and obs["goal"] == POINT_GOAL
        d0s.append(d0)
    assert len(set(np.round(d0s, 4))) > 6  # different pairs per seed
    env.reset(seed=3, options={"episode": pointnav_specs([SCENE])[0]})
    again = env.tracker.d0
    env.reset(seed=3, options={"episode": pointnav_specs([SCENE])[0]})
    assert env.tracker.d0 == again  # the seed fixes the pair
    env.close()


def test_an_impossible_range_is_refused(tiny_cfg) -> None:
    task = dataclasses.replace(tiny_cfg.task, point_min_distance_m=500.0, point_max_distance_m=600.0)
    env = _env(tiny_cfg, task)
    with pytest.raises(ValueError, match="point_min_distance_m"):
        env.reset(seed=0, options={"episode": pointnav_specs([SCENE])[0]})
    env.close()
    from ovon.config.base import ConfigError, validate

    with pytest.raises(ConfigError, match="point_min_distance_m"):
        validate(dataclasses.replace(tiny_cfg.task, point_min_distance_m=4.0, point_max_distance_m=2.0))


def test_goal_vector_by_hand() -> None:
    # turned 90 deg left after 1 m forward: a goal 1 m forward and 2 m left of the start is 2 m straight ahead
    np.testing.assert_allclose(
        point_goal_vector(np.array([1.0, 0.0, math.pi / 2]), np.array([1.0, 2.0])), [2.0, 1.0, 0.0], atol=1e-6
    )
    # at the start: a goal 1 m to the left is at theta = +90 deg
    np.testing.assert_allclose(point_goal_vector(np.zeros(3), np.array([0.0, 1.0])), [1.0, 0.0, 1.0], atol=1e-6)
    # behind and to the right
    v = point_goal_vector(np.array([0.0, 0.0, 0.0]), np.array([-3.0, -3.0]))
    np.testing.assert_allclose(v, [math.sqrt(18), math.cos(-3 * math.pi / 4), math.sin(-3 * math.pi / 4)], atol=1e-6)


def test_goal_vector_agrees_with_the_navigators_request() -> None:
    """The env's goal vector (odometry) and the one the learned navigator builds from `NavRequest.rho/.theta`
    (the episodic frame of the modular agents) are the same numbers."""
    from ovon.agents.modular.navigation import NavRequest
    from ovon.agents.modular.sensors import pose_from_odometry

    rng = np.random.default_rng(0)
    for _ in range(20):
        odo = np.array([rng.uniform(-3, 3), rng.uniform(-3, 3), rng.uniform(-math.pi, math.pi)])
        goal_fl = rng.uniform(-4, 4, size=2)
        req = NavRequest(pose_from_odometry(odo), (-goal_fl[1], -goal_fl[0]), "goal", None)
        np.testing.assert_allclose(goal_vector(req.rho, req.theta), point_goal_vector(odo, goal_fl), atol=1e-5)


def test_goal_vector_follows_the_true_pose_without_noise(tiny_cfg) -> None:
    """rho shrinks as the agent drives at the goal: after each step the observed vector is the true goal
    position relative to the true pose (no odometry noise)."""
    from ovon.geometry import heading_vector

    env = _env(tiny_cfg)
    obs, _ = env.reset(seed=5, options={"episode": pointnav_specs([SCENE])[0]})
    goal = env.privileged().viewpoints[0].position
    for a in (1, 2, 1, 3, 1):
        obs, *_ = env.step(a)
        s = env.privileged().state
        d = goal - s.position
        f = heading_vector(s.yaw)
        fwd, left = float(d @ f), float(d @ np.array([f[2], 0.0, -f[0]]))
        np.testing.assert_allclose(
            obs["pointgoal"], goal_vector(math.hypot(fwd, left), math.atan2(left, fwd)), atol=1e-4
        )
    env.close()


@pytest.mark.parametrize(("radius", "success"), [(0.36, True), (0.25, False)])
def test_success_radius(tiny_cfg, radius: float, success: bool) -> None:
    """STOP 0.3 m (geodesic) from the goal succeeds with a 0.36 m radius and fails with 0.25 m."""
    from ovon.sim.world import acquire_world
    from ovon.task.pointgoal import sample_point_goal

    task = dataclasses.replace(tiny_cfg.task, success_distance=radius)
    world = acquire_world(SCENE, tiny_cfg.sim)
    grid, _, goal, field = sample_point_goal(world.nav.floors, np.random.default_rng(0), task)
    rows, cols = np.nonzero(grid.navigable & (np.abs(field.dist - 0.3) < 0.02))
    start = grid.cell_to_world(int(rows[0]), int(cols[0]))
    spec = EpisodeSpec(
        "fixed", SCENE, POINT_GOAL, start_position=start, start_yaw=0.0, viewpoints=[GoalViewpoint(goal, 0.0)]
    )
    env = _env(tiny_cfg, task)
    env.reset(seed=0, options={"episode": spec})
    assert abs(env.tracker.d0 - 0.3) < 0.05
    _, reward, terminated, _, info = env.step(0)
    assert terminated and info["metrics"]["success"] is success
    assert info["metrics"]["failure"] == (None if success else "stop_too_far")
    r = task.reward
    assert reward == pytest.approx(r.dense_success if success else r.dense_failed_stop + r.dense_slack)
    env.close()


# ----- training ----------------------------------------------------------------------------------------
def test_pointnav_config_is_checked() -> None:
    from ovon.config.base import ConfigError, validate

    cfg = train_preset("tiny", "pointnav")
    with pytest.raises(ConfigError, match="task.kind"):
        validate(dataclasses.replace(cfg, algo="dagger"))
    with pytest.raises(ConfigError, match="depth-grid"):
        validate(dataclasses.replace(cfg, encoder=dataclasses.replace(cfg.encoder, image="oracle-vl")))
    with pytest.raises(KeyError, match="unknown task"):
        train_preset("tiny", "imagenav")


def test_tiny_training_runs_and_resumes_exactly(tmp_path: Path) -> None:
    from ovon.models.policy import ActorCritic
    from ovon.train import train
    from ovon.train.logging import read_metrics

    specs = pointnav_specs([SCENE, "procedural:1"])
    cfg = train_preset("tiny", "pointnav", num_envs=2, rollout_steps=8, max_updates=4, checkpoint_every=1)
    train(cfg, specs, tmp_path / "straight")
    train(dataclasses.replace(cfg, max_updates=2), specs, tmp_path / "split")
    train(cfg, specs, tmp_path / "split", resume=True)
    a, b = read_metrics(tmp_path / "straight"), read_metrics(tmp_path / "split")
    assert len(a) == 4 and [r["loss"] for r in a] == [r["loss"] for r in b]
    assert sum(r["episode/count"] for r in a) > 0
    pa, pb = ActorCritic.load(tmp_path / "straight" / "policy.pt"), ActorCritic.load(tmp_path / "split" / "policy.pt")
    assert pa.text_dim == 3 and pa.encoder_cfg.image == "depth-grid"
    assert pa.checkpoint_extra["task"]["kind"] == "pointnav" and not pa.checkpoint_extra["text_table"]
    for (_, x), (_, y) in zip(pa.state_dict().items(), pb.state_dict().items()):
        assert torch.equal(x, y)


@pytest.fixture(scope="module")
def tiny_policy(tmp_path_factory) -> Path:
    """A tiny PointNav policy trained through the CLI (two updates)."""
    from ovon.cli.main import main

    out = tmp_path_factory.mktemp("pointnav") / "run"
    assert (
        main(
            [
                "train",
                "--algo",
                "ppo",
                "--task",
                "pointnav",
                "--preset",
                "tiny",
                "--procedural",
                "0-1",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    return out / "policy.pt"


def test_cli_refuses_pointnav_without_houses_or_with_an_expert(tmp_path: Path, capsys) -> None:
    from ovon.cli.main import main

    assert main(["train", "--algo", "ppo", "--task", "pointnav", "--preset", "tiny", "--out", str(tmp_path / "a")]) == 2
    assert "--procedural" in capsys.readouterr().err
    assert (
        main(
            [
                "train",
                "--algo",
                "dagger",
                "--task",
                "pointnav",
                "--preset",
                "tiny",
                "--procedural",
                "0",
                "--out",
                str(tmp_path / "b"),
            ]
        )
        == 2
    )
    assert "ppo" in capsys.readouterr().err


def test_evaluate_pointnav_on_held_out_houses(tmp_path: Path, tiny_policy: Path, capsys) -> None:
    import json

    from ovon.cli.main import main

    args = [
        "evaluate",
        "--task",
        "pointnav",
        "--procedural",
        "80000",
        "--episodes",
        "2",
        "--agent",
        "policy",
        "--checkpoint",
        str(tiny_policy),
        "--workers",
        "1",
        "--no-progress",
    ]
    assert main([*args, "--out", str(tmp_path / "a")]) == 0
    recs = [json.loads(x) for x in (tmp_path / "a" / "episodes.jsonl").read_text().splitlines()]
    assert len(recs) == 2 and {r["scene"] for r in recs} == {"procedural:80000"} and recs[0]["split"] == "val"
    task = json.loads((tmp_path / "a" / "run.json").read_text())["task"]
    assert (
        task["kind"] == "pointnav"
        and task["success_distance"] == train_preset("tiny", "pointnav").task.success_distance
    )
    # the same episodes for another agent: same start distances
    assert main([*args[:7], "--agent", "random", "--workers", "1", "--no-progress", "--out", str(tmp_path / "b")]) == 0
    recs_b = [json.loads(x) for x in (tmp_path / "b" / "episodes.jsonl").read_text().splitlines()]
    assert [r["start_distance"] for r in recs] == [r["start_distance"] for r in recs_b]
    capsys.readouterr()
    assert main([*args, "--data", str(tmp_path), "--out", str(tmp_path / "c")]) == 2
    assert "--procedural" in capsys.readouterr().err


def test_pointnav_is_a_task_of_the_one_harness(tmp_path: Path) -> None:
    """The Python API and the CLI write the same run folder; each task refuses the other's episode source
    before any work."""
    from ovon.cli.main import main
    from ovon.config.base import ConfigError
    from ovon.evaluate.config import EvalConfig, checkpoint_task, pointnav_config
    from ovon.evaluate.harness import evaluate

    task = dataclasses.replace(checkpoint_task(None), max_steps=20)
    cfg = pointnav_config(agent="random", procedural="80001", episodes=2, workers=1, task=task)
    assert evaluate(cfg, tmp_path / "py", progress=False)["splits"]["val"]["episodes"] == 2
    cli = ["evaluate", "--task", "pointnav", "--procedural", "80001", "--episodes", "2", "--agent", "random",
           "--workers", "1", "--set", "task.max_steps=20", "--no-progress", "--out", str(tmp_path / "cli")]  # fmt: skip
    assert main(cli) == 0
    for name in ("episodes.jsonl", "summary.json", "run.json", "run_identity.json"):
        assert (tmp_path / "py" / name).read_bytes() == (tmp_path / "cli" / name).read_bytes(), name
    bad = {
        "needs --procedural": pointnav_config(agent="random", procedural=""),
        "drop --data": pointnav_config(agent="random", data=str(tmp_path)),
        "one split": pointnav_config(agent="random", splits=("val_seen",)),
        "house seeds are for --task pointnav": EvalConfig(
            agent="random", data=str(tmp_path), scenes=str(tmp_path), procedural="1"
        ),
        "--data = ''": EvalConfig(agent="random", data="", scenes=str(tmp_path)),
    }
    for i, (message, c) in enumerate(bad.items()):
        with pytest.raises(ConfigError, match=message):
            evaluate(c, tmp_path / f"bad{i}", progress=False)
        assert not (tmp_path / f"bad{i}").exists()


# ----- the learned navigator -----------------------------------------------------------------------------
def test_learned_navigator_acts_inside_vlfm(tiny_policy: Path) -> None:
    """`navigator=learned` + `navigator.checkpoint` (as `--agent-arg` passes them) drive VLFM's exploration
    and bee-lining with the PointNav policy; the camera it was trained with is checked."""
    from ovon.agents.modular.learned_navigator import LearnedNavigator
    from ovon.agents.modular.vlfm import VLFMAgent
    from ovon.config.sim import CameraConfig, SimConfig
    from ovon.evaluate.runner import run_episode
    from ovon.train.episodes import adhoc_specs

    agent = VLFMAgent(navigator="learned", **{"navigator.checkpoint": str(tiny_policy), "detector": "perfect"})
    assert "learned navigator" in agent.name
    sim = SimConfig(camera=CameraConfig(width=36, height=64))  # the tiny preset's camera (HFOV and aspect)
    env = ObjectNavEnv(episodes=adhoc_specs([0], categories=["bed"]), sim=sim, task=TaskConfig(max_steps=40))
    from ovon.env.privileged import PrivilegedInfo

    env = PrivilegedInfo(env)
    spec = adhoc_specs([0], categories=["bed"])[0]
    rec = run_episode(env, agent, spec, 0)
    assert isinstance(agent.core.navigator, LearnedNavigator)
    assert rec["steps"] > agent.cfg.spin_steps and all(0 <= a <= 3 for a in rec["actions"])
    # a camera of another aspect ratio is refused in one line
    wide = PrivilegedInfo(
        ObjectNavEnv(
            episodes=[spec], sim=SimConfig(camera=CameraConfig(width=64, height=36)), task=TaskConfig(max_steps=5)
        )
    )
    with pytest.raises(ValueError, match="camera"):
        run_episode(wide, VLFMAgent(navigator="learned", **{"navigator.checkpoint": str(tiny_policy)}), spec, 0)
    env.close()
    wide.close()


def test_learned_navigator_refuses_bad_checkpoints(tmp_path: Path) -> None:
    from ovon.agents.modular.vlfm import VLFMAgent
    from ovon.config.base import ConfigError

    with pytest.raises((ConfigError, ValueError), match="navigator.checkpoint"):
        VLFMAgent(navigator="learned")
    with pytest.raises((ConfigError, ValueError), match="navigator.checkpoint"):
        VLFMAgent(navigator="learned", **{"navigator.checkpoint": str(tmp_path / "missing.pt")})


def _learned(policy: Path, **cfg):
    """A learned navigator on an empty 12 m map (the tiny preset's camera)."""
    from ovon.agents.modular.config import MapConfig, NavigatorConfig
    from ovon.agents.modular.learned_navigator import LearnedNavigator
    from ovon.agents.modular.maps import AgentMaps
    from ovon.agents.modular.sensors import Sensors
    from ovon.config.sim import AgentConfig, CameraConfig

    sensors = Sensors(CameraConfig(width=36, height=64), AgentConfig())
    maps = AgentMaps(MapConfig(size_m=24.0), sensors)
    maps.reset()
    return LearnedNavigator(NavigatorConfig(kind="learned", checkpoint=str(policy), **cfg), maps, sensors), maps


def test_learned_navigator_stops_at_the_callers_radius(tiny_policy: Path) -> None:
    from ovon.agents.modular.navigation import NavRequest
    from ovon.agents.modular.sensors import Pose2D

    nav, maps = _learned(tiny_policy)
    obs = {"depth": np.full((64, 36), 2.0, np.float32), "collided": 0}
    assert nav.act(obs, NavRequest(Pose2D(0, 0, 0), (0.0, -0.5), "goal", maps)) == 0  # within 0.9 m
    far = NavRequest(Pose2D(0, 0, 0), (0.0, -3.0), "goal", maps)
    acts = [nav.act(obs, far) for _ in range(8)]
    assert set(acts) <= {1, 2, 3}  # never STOPs on its own further away (the caller's radius decides)
    nav.reset()
    assert [nav.act(obs, far) for _ in range(8)] == acts  # sampled, but seeded per episode


def test_learned_navigator_heads_for_a_point_on_the_route_within_its_training_range(tiny_policy: Path) -> None:
    """A frontier 10 m away behind a wall: the policy is given the point `subgoal_m` (default: the
    checkpoint's point_max_distance_m) along the map's route, on free space around the wall; a near frontier
    is given as it is; a goal point on an obstacle becomes the free cell where its route ends, within the
    stop distance; no route, None."""
    from ovon.agents.modular.navigation import NavRequest
    from ovon.agents.modular.sensors import Pose2D
    from ovon.train.config import train_preset

    nav, maps = _learned(tiny_policy)
    train_max = train_preset("tiny", task="pointnav").task.point_max_distance_m
    assert nav.subgoal_m == train_max
    pose = Pose2D(0.0, 0.0, 0.0)
    xs = np.linspace(-2.0, 1.0, 80)
    maps.add_obstacle_points(np.stack([xs, np.full_like(xs, -1.5)], 1))  # a wall across the straight line
    far = NavRequest(pose, (0.0, -10.0), "frontier", maps)
    sub = nav.subgoal(far)
    assert sub is not None and maps.navigable[maps.cell(*sub)]
    assert math.hypot(*sub) <= train_max + 0.1 and sub[0] > 1.0  # around the wall's open end, not through it
    obs = {"depth": np.full((64, 36), 2.0, np.float32), "collided": 0}
    assert nav.act(obs, far) in (1, 2, 3)
    assert nav.target == sub
    near = NavRequest(pose, (1.5, 0.5), "frontier", maps)
    assert nav.subgoal(near) == (1.5, 0.5)
    _learned_short, _ = _learned(tiny_policy, subgoal_m=2.0)
    assert _learned_short.subgoal_m == 2.0
    ring = np.array([[3.0 + r * math.cos(a), r * math.sin(a)] for r in (0.2, 0.3) for a in np.linspace(0, 6.3, 90)])
    maps.add_obstacle_points(ring)  # the goal object
    g = nav.subgoal(NavRequest(pose, (3.0, 0.0), "goal", maps))
    assert g is not None and maps.navigable[maps.cell(*g)] and math.hypot(g[0] - 3.0, g[1]) < 0.9
    box = [(6.0 + r * math.cos(a), 6.0 + r * math.sin(a)) for r in (0.6, 0.7) for a in np.linspace(0, 6.3, 200)]
    maps.add_obstacle_points(np.array(box))  # an enclosed frontier: no route
    assert nav.act(obs, NavRequest(pose, (6.0, 6.0), "frontier", maps)) is None


def test_learned_navigator_keeps_its_route_point_while_it_is_far(tiny_policy: Path) -> None:
    """A frontier 10 m down an open map, the agent walking toward it: with `waypoint_keep_m` the point given
    to the policy stays where it was chosen (the policy's memory runs on) until the agent is that close to
    it; with 0 the point slides ahead with the agent and its memory restarts on every slide over
    retarget_m. A new target replaces the kept point at once."""
    from ovon.agents.modular.navigation import NavRequest
    from ovon.agents.modular.sensors import Pose2D

    obs = {"depth": np.full((64, 36), 2.0, np.float32), "collided": 0}

    def walk(nav, maps, target=(0.0, -10.0)) -> list:
        points = []
        for i in range(12):  # 0.25 m per step along -z, facing the target
            nav.act(obs, NavRequest(Pose2D(0.0, -0.25 * i, 0.0), target, "frontier", maps))
            points.append(nav.target)
        return points

    kept, maps = _learned(tiny_policy, waypoint_keep_m=1.0, stuck_steps=0)
    points = walk(kept, maps)
    assert len(set(points)) == 1  # 12 steps = 2.75 m: still more than 1 m from a point ~subgoal_m ahead
    sliding, maps2 = _learned(tiny_policy, stuck_steps=0)
    points2 = walk(sliding, maps2)
    assert len(set(points2)) > 1 and points2[0] == points[0]
    kept.act(obs, NavRequest(Pose2D(0.0, -3.0, 0.0), (4.0, -3.0), "frontier", maps))  # a new frontier
    assert kept.target == (4.0, -3.0)
    with pytest.raises(ValueError, match="waypoint_keep_m"):
        _learned(tiny_policy, waypoint_keep_m=-1.0)


def test_learned_navigator_never_walks_where_its_map_is_blocked_with_map_checked_forward(tiny_policy: Path) -> None:
    """A policy that always wants MOVE_FORWARD, facing a wall on its map with the frontier behind it: with
    `map_checked_forward` (the default) the geometric navigator takes over for `stuck_steps` steps (its
    detour) and the policy restarts afterwards; without it the forward is taken (into the wall)."""
    from ovon.agents.modular.navigation import NavRequest
    from ovon.agents.modular.sensors import Pose2D
    from ovon.sim.agent import MOVE_FORWARD

    def forward_loving(nav):
        act_step = nav.policy.act_step

        def wrapped(*args, **kwargs):
            logits, value, state = act_step(*args, **kwargs)
            logits = logits.clone()
            logits[:, MOVE_FORWARD] += 50.0
            return logits, value, state

        nav.policy.act_step = wrapped
        return nav

    obs = {"depth": np.full((64, 36), 2.0, np.float32), "collided": 0}
    xs = np.linspace(-1.0, 1.0, 60)
    for checked in (False, True):
        nav, maps = _learned(tiny_policy, map_checked_forward=checked, handover_m=0.0)
        forward_loving(nav)
        maps.add_obstacle_points(np.stack([xs, np.full_like(xs, -0.35)], 1))  # a wall 0.35 m ahead (-z)
        pose = Pose2D(0.0, 0.0, 0.0)
        assert maps.navigable[maps.cell(0.0, 0.0)] and not nav.planner.steering.free(pose.position, pose.yaw)
        action = nav.act(obs, NavRequest(pose, (0.0, -4.0), "frontier", maps))
        if checked:
            assert action != MOVE_FORWARD and nav.rescue == nav.cfg.stuck_steps - 1 and nav.target is None
        else:
            assert action == MOVE_FORWARD and nav.rescue == 0


def test_learned_navigator_hands_the_final_approach_and_getting_unstuck_to_the_geometric_one(
    tiny_policy: Path,
) -> None:
    """Within stop_distance_m + handover_m of a goal point the geometric navigator acts (its final approach:
    one step lands inside the radius); after `stuck_steps` policy steps without a forward step of motion and
    with a bump it drives the next `stuck_steps` steps; with both off the policy acts throughout."""
    from ovon.agents.modular.navigation import GeometricNavigator, NavRequest
    from ovon.agents.modular.sensors import Pose2D
    from ovon.config.base import ConfigError

    nav, maps = _learned(tiny_policy)
    geo = GeometricNavigator(nav.cfg, maps, maps.sensors)
    obs = {"depth": np.full((64, 36), 2.0, np.float32), "collided": 0}
    pose = Pose2D(0.0, 0.0, math.radians(90.0))  # facing -x; the goal point 1.05 m ahead along -z
    req = NavRequest(pose, (0.0, -1.05), "goal", maps)
    assert nav.act(obs, req) == geo.act(obs, req) == 3  # TURN_RIGHT toward it, then one step lands inside
    # stuck: the same pose with a bump, stuck_steps times
    frontier = NavRequest(Pose2D(0.0, 0.0, 0.0), (0.0, -4.0), "frontier", maps)
    bumped = {**obs, "collided": 1}
    for _ in range(nav.cfg.stuck_steps - 1):
        nav.act(bumped, frontier)
        assert nav.rescue == 0
    nav.act(bumped, frontier)
    assert nav.rescue == nav.cfg.stuck_steps - 1  # the geometric navigator took this step and drives 7 more
    assert nav.target is None  # the policy restarts afterwards
    nav.reset()
    assert nav.rescue == 0
    off, _ = _learned(tiny_policy, stuck_steps=0, handover_m=0.0)
    for _ in range(20):
        off.act(bumped, frontier)
        assert off.rescue == 0 and off.target is not None
    with pytest.raises((ConfigError, ValueError), match="stuck_steps"):
        _learned(tiny_policy, stuck_steps=-1)
    with pytest.raises((ConfigError, ValueError), match="handover_m"):
        _learned(tiny_policy, handover_m=-0.5)


def test_curve_png_from_metrics(tmp_path: Path, tiny_policy: Path, capsys) -> None:
    from ovon.cli.main import main
    from ovon.reports.plots import learning_curve

    run = tiny_policy.parent
    assert main(["curve", str(run), "--out", str(tmp_path / "c.png")]) == 0
    assert (tmp_path / "c.png").read_bytes()[:4] == b"\x89PNG"
    assert main(["curve", str(run), "--metric", "nope", "--out", str(tmp_path / "d.png")]) == 2
    assert "nope" in capsys.readouterr().err
    rows = [
        {"step": 10, "episode/success": 1.0, "episode/count": 1.0},
        {"step": 20, "episode/success": 0.0, "episode/count": 3.0},
    ]
    assert learning_curve(rows, window=2) == ([10, 20], [1.0, 0.25])  # episode-weighted


def test_learned_navigator_samples_with_the_episodes_seed(tiny_policy: Path) -> None:
    """The same seed repeats an episode's draws; another seed (another evaluation seed) changes them."""
    from ovon.agents.modular.navigation import NavRequest
    from ovon.agents.modular.sensors import Pose2D

    nav, maps = _learned(tiny_policy, stuck_steps=0, handover_m=0.0)
    obs = {"depth": np.full((64, 36), 2.0, np.float32), "collided": 0}
    request = NavRequest(Pose2D(0.0, 0.0, 0.0), (0.0, -4.0), "frontier", maps)

    def draws(seed: int) -> list[int]:
        nav.reset(seed)
        return [nav.act(obs, request) for _ in range(40)]

    assert draws(3) == draws(3)
    assert draws(3) != draws(4)


def test_checkpoint_task_evaluates_with_every_stop_ending_the_episode(tmp_path: Path, tiny_policy: Path) -> None:
    """A policy trained with task.failed_stop_ends=false is evaluated under the task's rule, not refused."""
    from ovon.evaluate.config import checkpoint_task

    saved = torch.load(tiny_policy, map_location="cpu", weights_only=True)
    saved["extra"]["task"]["failed_stop_ends"] = False
    path = tmp_path / "policy.pt"
    torch.save(saved, path)
    task = checkpoint_task(str(path))
    assert task.failed_stop_ends and task.max_steps == checkpoint_task(str(tiny_policy)).max_steps
