"""The modular agents end to end in a hand-made scene (VLFM finds the couch in the other room; DAgRL+OD
hands over to bee-lining when the detector fires), their parts (value map, frontier choice, point-goal
navigation) and the command line."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from ovon.agents import make_agent
from ovon.agents.modular import DAgRLODAgent, VLFMAgent, VLFMConfig, modular_config
from ovon.agents.modular.config import MapConfig, NavigatorConfig, ValueMapConfig
from ovon.agents.modular.frontier_choice import FrontierChooser
from ovon.agents.modular.maps import AgentMaps
from ovon.agents.modular.navigation import GeometricNavigator, NavRequest
from ovon.agents.modular.sensors import Pose2D, Sensors
from ovon.agents.modular.value_map import ValueMap
from ovon.config.base import ConfigError
from ovon.env import make_objectnav
from ovon.evaluate.runner import run_episode
from ovon.sim.agent import LOOK_DOWN, LOOK_UP, MOVE_FORWARD, STOP, TURN_LEFT, TURN_RIGHT
from ovon.task.episode import EpisodeSpec
from tests.modular_scene import START, portrait_sim, two_room_scene


@pytest.fixture(scope="module")
def env():
    e = make_objectnav(scene=two_room_scene(), goal="couch", sim=portrait_sim(), privileged=True)
    yield e
    e.close()


def couch_episode(start=START, yaw=math.pi / 2) -> EpisodeSpec:
    return EpisodeSpec(
        "couch-1", "two-rooms", "couch", start_position=np.array(start, dtype=np.float64), start_yaw=yaw, split="test"
    )


class Recording:
    """Wraps an agent and keeps its actions and modes."""

    def __init__(self, agent):
        self.agent = agent
        self.privileged = agent.privileged
        self.actions: list[int] = []
        self.modes: list[str] = []

    def reset(self, info):
        self.agent.reset(info)

    def act(self, obs):
        a = self.agent.act(obs)
        self.actions.append(a)
        beeline = getattr(self.agent, "beelining", False)
        self.modes.append(getattr(self.agent, "mode", "beeline" if beeline else "policy"))
        return a


def test_vlfm_finds_the_couch_in_the_other_room(env):
    """Spin, explore through the doorway by value, detect the couch, bee-line, STOP: success, and never a
    LOOK action. The oracle-vl value is the default."""
    agent = Recording(VLFMAgent())
    assert agent.privileged and agent.agent.name == "VLFM, oracle detection, oracle-vl value"
    rec = run_episode(env, agent, couch_episode(), seed=0)
    assert rec["success"], rec
    assert agent.actions[:12] == [TURN_LEFT] * 12 and agent.actions[-1] == STOP
    assert not {LOOK_UP, LOOK_DOWN} & set(agent.actions)
    assert "explore" in agent.modes and agent.modes[-1] == "navigate"


def test_vlfm_does_not_stop_at_the_sofa_with_a_perfect_detector_but_can_with_a_noisy_one(env):
    """Started in room B between the sofa and the couch (facing the sofa): the perfect detector ignores the
    sofa; with false positives certain for similar categories it stops at the sofa (wrong object)."""
    spec = couch_episode(start=(6.0, 0.0, 2.0), yaw=0.0 - math.pi)  # facing +z, the sofa
    ok = run_episode(env, VLFMAgent(**{"value.scorer.kind": "constant"}), spec, seed=0)
    assert ok["success"]
    fooled = VLFMAgent(
        **{"value.scorer.kind": "constant", "detector.fp_rate": 1.0, "detector.fp_min_similarity": 0.5, "spin_steps": 0}
    )
    rec = run_episode(env, fooled, spec, seed=0)
    assert not rec["success"] and rec["failure"] == "stop_wrong_object"


def test_dagrl_od_switches_to_beelining_when_the_detector_fires(env, tmp_path):
    """A real (tiny, random) policy checkpoint loads; its actions are replaced by a scripted explorer that
    only turns left. The agent follows it until the couch comes into view, then bee-lines and STOPs."""
    from ovon.models.config import EncoderConfig, policy_preset
    from ovon.models.policy import build_policy

    enc = EncoderConfig(oracle_grid=1, oracle_global=False)
    build_policy(policy_preset("tiny"), 384, 384, enc).save(tmp_path / "policy.pt")
    agent = make_agent("dagrl-od", checkpoint=str(tmp_path / "policy.pt"))
    assert isinstance(agent, DAgRLODAgent) and agent.privileged
    assert agent.name == "DAgRL+OD, policy: oracle perception, oracle detection"
    policy_calls: list[int] = []

    def explorer(obs):
        policy_calls.append(1)
        return TURN_LEFT

    agent.policy.act = explorer
    rec_agent = Recording(agent)
    start = (5.0, 0.0, 2.0)  # room B, facing +z (away from the couch)
    rec = run_episode(env, rec_agent, couch_episode(start=start, yaw=-math.pi), seed=0)
    assert agent.switch_step is not None and 1 < agent.switch_step <= 12
    assert len(policy_calls) == agent.switch_step - 1
    assert rec_agent.actions[: agent.switch_step - 1] == [TURN_LEFT] * (agent.switch_step - 1)
    assert MOVE_FORWARD in rec_agent.actions[agent.switch_step - 1 :]
    assert rec["success"], rec


def test_value_map_confidence_and_fusion():
    sim = portrait_sim(hfov=60.0)
    maps = AgentMaps(MapConfig(size_m=12.0), Sensors(sim.camera, sim.agent))
    maps.reset()
    vm = ValueMap(ValueMapConfig(), maps)
    r, c = maps.cell(0.0, 0.0)
    half = math.radians(30.0)
    # on the axis 1, at the cone's edge min_confidence, cos^2 in between
    rows = np.array([r - 10, r - 10, r - 10])
    cols = np.array([c, c + int(round(10 * math.tan(half))), c + int(round(10 * math.tan(half / 2)))])
    conf = vm.cone_confidence(rows, cols, r, c, 0.0)
    assert conf[0] == pytest.approx(1.0)
    assert conf[1] == pytest.approx(0.25, abs=0.03)
    theta = math.atan2(cols[2] - c, 10)
    assert conf[2] == pytest.approx(0.25 + 0.75 * math.cos(theta / half * math.pi / 2) ** 2, abs=1e-5)
    pose = Pose2D(0.0, 0.0, 0.0)
    vm.update(0.8, pose)
    vm.update(0.2, pose)  # same cone, same confidences: the mean, confidence unchanged
    on_axis = (r - 10, c)
    assert vm.value[on_axis] == pytest.approx(0.5) and vm.confidence[on_axis] == pytest.approx(1.0)
    fv = vm.frontier_values(np.array([r - 10, r + 30]), np.array([c, c]))
    assert fv[0] == pytest.approx(0.5) and fv[1] == -1.0  # behind the agent: never seen


def test_frontier_choice_hysteresis_and_anti_cycling():
    ch = FrontierChooser(ValueMapConfig(hysteresis=0.01, keep_radius_m=0.5), 0.05)
    rows, cols = np.array([0, 100]), np.array([0, 0])
    assert ch.choose(rows, cols, np.array([0.50, 0.40]), (50, 50)) == 0
    # the other frontier is better by less than the hysteresis: keep
    assert ch.choose(rows, cols, np.array([0.50, 0.505]), (50, 50)) == 0
    # better by more: switch, and frontier 0 is abandoned from this spot
    assert ch.choose(rows, cols, np.array([0.50, 0.52]), (50, 50)) == 1
    ch.drop_target(blacklist=False)
    # back at the same spot, frontier 0 is not re-picked though it is now the best...
    assert ch.choose(rows, cols, np.array([0.60, 0.52]), (50, 50)) == 1
    # ...from another spot it is
    ch.drop_target(blacklist=False)
    assert ch.choose(rows, cols, np.array([0.60, 0.52]), (51, 50)) == 0
    # a blacklisted frontier is not chosen while others exist; when all are blacklisted, all are retried
    ch.drop_target(blacklist=True)
    assert ch.choose(rows, cols, np.array([0.9, 0.1]), (52, 50)) == 1
    ch.drop_target(blacklist=True)
    assert ch.choose(rows, cols, np.array([0.9, 0.1]), (52, 50)) == 0 and ch.cleared == 1 and not ch.blacklist
    assert ch.choose(rows[:0], cols[:0], np.array([]), (52, 50)) is None


def test_geometric_navigator_replans_around_new_obstacles_and_stops_near_the_goal():
    sim = portrait_sim()
    maps = AgentMaps(MapConfig(size_m=12.0), Sensors(sim.camera, sim.agent))
    maps.reset()
    nav = GeometricNavigator(NavigatorConfig(), maps, maps.sensors)
    nav.reset()
    pose = Pose2D(0.0, 0.0, 0.0)  # facing -z
    goal = (0.0, -4.0)
    assert nav.act({}, NavRequest(pose, goal, "goal", maps)) == MOVE_FORWARD
    # a wall appears across the straight line: the plan goes around it
    xs = np.linspace(-1.0, 1.5, 60)
    maps.add_obstacle_points(np.stack([xs, np.full_like(xs, -2.0)], 1))
    nav.act({}, NavRequest(pose, goal, "goal", maps))
    pr, pc = nav.path
    assert maps.navigable[pr, pc].all()
    assert (pc > maps.cell(1.6, 0.0)[1]).any() or (pc < maps.cell(-1.1, 0.0)[1]).any()
    assert nav.act({}, NavRequest(Pose2D(0.0, -3.2, 0.0), goal, "goal", maps)) == STOP  # 0.8 m < 0.9 m
    # enclosed goal: no path
    ring = np.array([[math.cos(a) * 0.3, -4.0 + math.sin(a) * 0.3] for a in np.linspace(0, 2 * math.pi, 200)])
    maps.add_obstacle_points(ring)
    far = (0.0, -4.0)
    assert nav.act({}, NavRequest(Pose2D(3.0, 3.0, 0.0), far, "frontier", maps)) is None


def _step(pose: Pose2D, action: int, step: float = 0.25, turn: float = math.radians(30.0)) -> Pose2D:
    """The simulator's kinematics without obstacles (yaw 0 looks along -z, positive yaw turns left)."""
    if action == MOVE_FORWARD:
        return Pose2D(pose.x - math.sin(pose.yaw) * step, pose.z - math.cos(pose.yaw) * step, pose.yaw)
    if action == TURN_LEFT:
        return Pose2D(pose.x, pose.z, pose.yaw + turn)
    if action == TURN_RIGHT:
        return Pose2D(pose.x, pose.z, pose.yaw - turn)
    return pose


def _navigator(**cfg) -> tuple[GeometricNavigator, AgentMaps]:
    sim = portrait_sim()
    maps = AgentMaps(MapConfig(size_m=12.0), Sensors(sim.camera, sim.agent))
    maps.reset()
    nav = GeometricNavigator(NavigatorConfig(**cfg), maps, maps.sensors)
    nav.reset()
    return nav, maps


@pytest.mark.parametrize("yaw_deg", [0.0, 90.0, 150.0, -120.0])
def test_final_approach_heads_for_the_goal_point_and_stops_inside_the_radius(yaw_deg):
    """0.95 m from the goal point (just outside the 0.9 m stop radius) and facing anywhere: the smallest turn
    toward a heading whose one step lands inside the radius, one MOVE_FORWARD, STOP; never the ring-cell
    circling that overshoots."""
    nav, maps = _navigator()
    goal = (0.0, -0.95)
    pose = Pose2D(0.0, 0.0, math.radians(yaw_deg))
    actions = []
    for _ in range(10):
        a = nav.act({}, NavRequest(pose, goal, "goal", maps))
        actions.append(a)
        if a == STOP:
            break
        pose = _step(pose, a)
    assert actions[-1] == STOP and actions.count(MOVE_FORWARD) == 1, actions
    assert len(actions) <= 1 + 1 + 3  # at most 3 turns (90 deg either way suffices at this distance), 1 step
    assert math.hypot(pose.x - goal[0], pose.z - goal[1]) < 0.9


def test_navigator_settles_when_no_step_gets_inside_the_stop_radius():
    """The goal point inside an obstacle whose inflated edge lies just outside the stop radius: no step lands
    inside it, so after `settle_steps` steps without getting closer the agent STOPs where it is."""
    nav, maps = _navigator(settle_steps=5)
    goal = (0.0, -1.0)
    ring = [
        (goal[0] + r * math.cos(a), goal[1] + r * math.sin(a))
        for r in np.arange(0.0, 0.78, 0.02)
        for a in np.linspace(0, 2 * math.pi, 120)
    ]
    maps.add_obstacle_points(np.array(ring))
    pose = Pose2D(0.0, 0.0, 0.0)
    assert nav.final_approach(pose, goal) is None
    seen = [nav.act({}, NavRequest(pose, goal, "goal", maps)) for _ in range(6)]
    assert STOP not in seen[:5] and seen[5] == STOP, seen
    nav.reset()
    assert nav.act({}, NavRequest(pose, goal, "goal", maps)) != STOP  # the count starts again per episode


def test_lifting_skips_depth_clamped_at_the_sensor_minimum():
    """A pixel at the camera's minimum depth is clamped (the surface is nearer): it lifts to no point."""
    from ovon.agents.modular.config import LiftConfig
    from ovon.agents.modular.lifting import GoalMemory
    from ovon.agents.modular.sensors import DepthProjector
    from ovon.models.detectors.base import Detection

    cam = portrait_sim().camera
    depth = np.full((cam.height, cam.width), 2.0, np.float32)
    mask = np.zeros(depth.shape, bool)
    mask[20:40, 10:30] = True
    depth[20:30, 10:30] = cam.min_depth  # the upper half of the object is too close to measure
    memory = GoalMemory(LiftConfig(mask_erode_px=0), DepthProjector(cam))
    det = Detection(box=(10, 20, 30, 40), score=1.0, label="couch", mask=mask)
    assert memory.add([det], depth, Pose2D(0.0, 0.0, 0.0)) == 200  # the 10 x 20 measured pixels only
    assert np.allclose(-memory.points[:, 2], 2.0, atol=1e-4)  # at z-depth 2 m ahead (yaw 0 looks along -z)


def test_debug_frame_draws_the_agents_beliefs(env):
    """After an episode: two panels (maps, value map) of the requested height, with the lifted goal points
    (red) and the agent (orange) on them; None before the first reset."""
    from ovon.agents.modular.debug import AGENT, GOAL

    agent = VLFMAgent()
    assert agent.debug_frame(120) is None
    run_episode(env, agent, couch_episode(), seed=0)
    img = agent.debug_frame(120)
    assert img.dtype == np.uint8 and img.shape == (120, 242, 3)
    left = img[:, :120]
    for colour in (GOAL, AGENT):
        assert (left == np.array(colour, np.uint8)).all(axis=2).sum() >= 4, colour
    assert len(np.unique(img[16:, 122:].reshape(-1, 3), axis=0)) > 8  # the value map has a colour scale


def test_config_presets_overrides_and_errors():
    cfg = modular_config(VLFMConfig, "paper")
    assert (cfg.maps.obstacle_min_height_m, cfg.maps.obstacle_max_height_m) == (0.6, 0.9)
    assert cfg.detector.kind == "owlv2" and cfg.value.scorer.kind == "siglip" and cfg.spin_steps == 12
    assert cfg.navigator.stop_distance_m == 0.9 and cfg.value.hysteresis == 0.01
    cfg = modular_config(VLFMConfig, "cpu", {"detector": "noisy", "detector.miss_rate": 0.1, "maps": {"size_m": 30}})
    assert cfg.detector.fp_rate > 0 and cfg.detector.miss_rate == 0.1 and cfg.maps.size_m == 30
    with pytest.raises(ConfigError, match="valid keys"):
        VLFMAgent(**{"detector.mis_rate": 0.1})
    with pytest.raises(ConfigError, match="unknown modular preset"):
        VLFMAgent(preset="fast")
    with pytest.raises(ConfigError, match="obstacle_max_height_m"):
        VLFMAgent(**{"maps.obstacle_max_height_m": 0.1})
    with pytest.raises(ValueError, match="--checkpoint"):
        DAgRLODAgent()
    assert VLFMAgent.describe(detector="noisy") == "VLFM, oracle detection (miss 0.3, fp 0.3), oracle-vl value"
    # the command line passes dotted keys through (--agent-arg navigator.stop_distance_m=0.6)
    from ovon.agents import check_agent
    from ovon.evaluate.config import parse_agent_args

    kwargs = parse_agent_args(["navigator.stop_distance_m=0.6", "preset=cpu"], None)
    assert kwargs == {"navigator.stop_distance_m": 0.6, "preset": "cpu"}
    check_agent("vlfm", kwargs)
    assert VLFMAgent(**kwargs).cfg.navigator.stop_distance_m == 0.6
    with pytest.raises(ConfigError, match="stop_distance_m"):  # the config's own line, not wrapped
        check_agent("vlfm", parse_agent_args(["navigator.stop_distanc=0.6"], None))


def test_cli_evaluate_vlfm_and_report_row_names(tiny_dataset, tiny_scenes, tmp_path, capsys):
    import json

    from ovon.cli.main import main as ovon

    run = tmp_path / "vlfm"
    assert (
        ovon(
            [
                "evaluate",
                "--agent",
                "vlfm",
                "--data",
                str(tiny_dataset),
                "--scenes",
                str(tiny_scenes),
                "--splits",
                "val_seen",
                "--episodes",
                "2",
                "--workers",
                "1",
                "--no-progress",
                "--set",
                "task.max_steps=60",
                "--out",
                str(run),
            ]
        )
        == 0
    )
    noisy = tmp_path / "vlfm_noisy"
    assert (
        ovon(
            [
                "evaluate",
                "--agent",
                "vlfm",
                "--data",
                str(tiny_dataset),
                "--scenes",
                str(tiny_scenes),
                "--splits",
                "val_seen",
                "--episodes",
                "2",
                "--workers",
                "1",
                "--no-progress",
                "--noise",
                "actuation,odometry",
                "--set",
                "task.max_steps=60",
                "--out",
                str(noisy),
            ]
        )
        == 0
    )
    assert ovon(["report", str(run), str(noisy), "--out", str(tmp_path / "rep")]) == 0
    md = (tmp_path / "rep" / "report.md").read_text()
    assert "| VLFM, oracle detection, oracle-vl value |" in md
    assert "| VLFM, oracle detection, oracle-vl value [noise: actuation:ilqr, odometry] |" in md
    assert "## Noise" in md and "| VLFM, oracle detection, oracle-vl value | ✓ actuation:ilqr, odometry |" in md
    assert "| VLFM, oracle detection, oracle-vl value | – |" in md
    for name in ("sr_vs_distance.png", "failures_vlfm_vlfm.png", "failures_vlfm_vlfm_noisy.png"):
        assert Path(tmp_path / "rep" / name).stat().st_size > 0
    # the video has a fourth panel with what the agent believes; --no-agent-view leaves it out
    import imageio.v2 as imageio

    from ovon.evaluate.results import read_records

    ep = read_records(run)[0]
    where = [
        "--run",
        str(run),
        "--episode",
        ep["episode_id"],
        "--split",
        ep["split"],
        "--scene",
        Path(ep["scene"]).parent.name,
    ]
    assert ovon(["video", *where, "--out", str(tmp_path / "beliefs.mp4")]) == 0
    assert ovon(["video", *where, "--no-agent-view", "--out", str(tmp_path / "truth.mp4")]) == 0
    with_view = imageio.get_reader(tmp_path / "beliefs.mp4").get_data(0)
    without = imageio.get_reader(tmp_path / "truth.mp4").get_data(0)
    assert with_view.shape[0] == without.shape[0] and with_view.shape[1] >= without.shape[1] + 2 * 240
    assert "chose another action" not in capsys.readouterr().err  # the fresh agent replays the record
    # a record the agent would not have made (its 4th turn reversed): the panel stops there, with a warning
    lines = (run / "episodes.jsonl").read_text().splitlines()
    first = json.loads(lines[0])
    assert first["actions"][3] == TURN_LEFT
    first["actions"][3] = TURN_RIGHT
    (run / "episodes.jsonl").write_text("\n".join([json.dumps(first, sort_keys=True), *lines[1:]]) + "\n")
    where = [
        "--run",
        str(run),
        "--episode",
        first["episode_id"],
        "--split",
        first["split"],
        "--scene",
        Path(first["scene"]).parent.name,
    ]
    assert ovon(["video", *where, "--out", str(tmp_path / "edited.mp4")]) == 0
    assert "chose another action than the record after step 3" in capsys.readouterr().err


@pytest.mark.slow
def test_demo_runs_the_vlfm_row(tmp_path):
    """`ovon demo` at its smallest: the report has the VLFM row; deterministic agents ran one seed."""
    import json

    from ovon.cli.main import main as ovon

    root = tmp_path / "demo"
    assert (
        ovon(
            [
                "demo",
                "--root",
                str(root),
                "--train-scenes",
                "1",
                "--val-scenes",
                "1",
                "--episodes",
                "1",
                "--seeds",
                "0,1",
                "--workers",
                "1",
            ]
        )
        == 0
    )
    md = (root / "runs" / "report" / "report.md").read_text()
    assert "| VLFM, oracle detection, oracle-vl value |" in md
    seeds = {a: json.loads((root / "runs" / a / "run.json").read_text())["seeds"] for a in ("random", "vlfm")}
    assert seeds == {"random": [0, 1], "vlfm": [0]}
