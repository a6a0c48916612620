"""Agent kinematics (collisions, sliding, pitch), noise statistics and odometry."""

import math

import numpy as np
import pytest

from ovon.config.sim import AgentConfig
from ovon.sim.agent import LOOK_DOWN, LOOK_UP, MOVE_FORWARD, STOP, TURN_LEFT, TURN_RIGHT, Kinematics, Odometry
from ovon.sim.noise import LOCOBOT_PRESETS, ActuationNoise, OdometryNoise, truncated_normal
from ovon.sim.types import AgentState


class BoxGrid:
    """Navigable rectangle x in [0, 4], z in [0, 2] at 0.05 m cells (a stand-in NavGrid)."""

    cell_size = 0.05

    def __init__(self):
        self.origin = np.array([0.0, 0.0])
        self.navigable = np.ones((40, 80), dtype=bool)
        self.heights = np.zeros((40, 80), dtype=np.float32)

    def world_to_cell(self, p):
        return int(math.floor((p[2] - self.origin[1]) / self.cell_size)), int(
            math.floor((p[0] - self.origin[0]) / self.cell_size)
        )

    def is_navigable(self, p):
        r, c = self.world_to_cell(p)
        return 0 <= r < self.navigable.shape[0] and 0 <= c < self.navigable.shape[1] and bool(self.navigable[r, c])


def state(x, z, yaw_deg):
    return AgentState(np.array([x, 0.0, z]), math.radians(yaw_deg))


def test_forward_moves_along_minus_z_at_yaw_zero():
    k = Kinematics(BoxGrid(), AgentConfig())
    r = k.step(state(1.0, 1.5, 0), MOVE_FORWARD)
    assert not r.collided
    np.testing.assert_allclose(r.state.position, [1.0, 0.0, 1.25], atol=1e-9)


def test_turns_and_stop():
    k = Kinematics(BoxGrid(), AgentConfig())
    s = k.step(state(1, 1, 0), TURN_LEFT).state
    assert s.yaw == pytest.approx(math.radians(30))
    s = k.step(s, TURN_RIGHT).state
    assert s.yaw == pytest.approx(0.0)
    assert k.step(s, STOP).state.position.tolist() == s.position.tolist()
    # positive yaw turns left: after 90 deg left the agent looks along -x
    r = k.step(state(2.0, 1.0, 90), MOVE_FORWARD)
    np.testing.assert_allclose(r.state.position, [1.75, 0.0, 1.0], atol=1e-9)


def test_pitch_is_clamped():
    k = Kinematics(BoxGrid(), AgentConfig(min_pitch_deg=-60, max_pitch_deg=60))
    s = state(1, 1, 0)
    for _ in range(5):
        s = k.step(s, LOOK_UP).state
    assert s.pitch == pytest.approx(math.radians(60))
    for _ in range(5):
        s = k.step(s, LOOK_DOWN).state
    assert s.pitch == pytest.approx(math.radians(-60))


def test_collision_without_sliding_stops_at_the_wall():
    k = Kinematics(BoxGrid(), AgentConfig(allow_sliding=False))
    r = k.step(state(1.0, 0.1, 30), MOVE_FORWARD)  # wall at z = 0, heading mostly -z
    assert r.collided
    assert r.state.position[2] >= 0.0
    assert r.state.position[2] <= 0.1
    # no sliding: x moved only as far as the straight-line prefix allows
    assert abs(r.state.position[0] - 1.0) < 0.1


def test_sliding_moves_along_the_wall():
    cfg = AgentConfig(allow_sliding=True)
    k = Kinematics(BoxGrid(), cfg)
    s0 = state(1.0, 0.03, 45)  # heading (-x, -z): blocked in z, free in x
    r = k.step(s0, MOVE_FORWARD)
    assert r.collided
    slid = 1.0 - r.state.position[0]
    blocked = 1.0 - Kinematics(BoxGrid(), AgentConfig(allow_sliding=False)).step(s0, MOVE_FORWARD).state.position[0]
    assert slid > blocked + 0.1
    assert BoxGrid().is_navigable(r.state.position)


def test_truncated_normal_statistics():
    rng = np.random.default_rng(0)
    x = truncated_normal(rng, 0.5, 2.0, size=(200_000,))
    assert np.all(np.abs(x - 0.5) <= 6.0 + 1e-9)
    assert x.mean() == pytest.approx(0.5, abs=0.02)
    # a 3-sigma truncated Gaussian has std ~0.9866 sigma
    assert x.std() == pytest.approx(2.0 * 0.9866, rel=0.01)


def test_actuation_noise_matches_configured_mean_and_std():
    model = LOCOBOT_PRESETS["ilqr"]
    noise = ActuationNoise(model)
    rng = np.random.default_rng(1)
    samples = np.array([noise.sample(rng, is_turn=False) for _ in range(20_000)])
    assert samples[:, 0].mean() == pytest.approx(0.014, abs=0.003)
    assert samples[:, 1].mean() == pytest.approx(0.009, abs=0.003)
    assert samples[:, 0].std() == pytest.approx(0.077 * 0.9866, rel=0.05)
    assert samples[:, 2].std() == pytest.approx(0.063 * 0.9866, rel=0.05)
    assert samples[:, 2].mean() == pytest.approx(0.008, abs=0.003)


def test_actuation_noise_changes_motion_and_is_seeded():
    k = Kinematics(BoxGrid(), AgentConfig(), ActuationNoise(LOCOBOT_PRESETS["ilqr"]))
    a = k.step(state(2, 1, 0), MOVE_FORWARD, np.random.default_rng(3)).state
    b = k.step(state(2, 1, 0), MOVE_FORWARD, np.random.default_rng(3)).state
    assert a.position.tolist() == b.position.tolist()
    assert not np.allclose(a.position, [2.0, 0.0, 0.75])


def test_unknown_noise_name_is_a_clear_error():
    with pytest.raises(ValueError, match="unknown actuation noise"):
        ActuationNoise.from_name("wobbly")


def test_odometry_relative_to_start_and_noise_bounded():
    k = Kinematics(BoxGrid(), AgentConfig())
    s = state(1.0, 1.5, 90)  # looking along -x
    clean, noisy = Odometry(), Odometry(OdometryNoise(0.007, 2.0))
    clean.reset(s)
    noisy.reset(s)
    rng = np.random.default_rng(0)
    s = k.step(s, MOVE_FORWARD).state
    est = clean.update(s)
    np.testing.assert_allclose(est, [0.25, 0.0, 0.0], atol=1e-9)
    n = noisy.update(s, rng)
    assert np.all(np.abs(n[:2] - est[:2]) <= 0.007 + 1e-12)
    assert abs(n[2] - est[2]) <= math.radians(2.0) + 1e-12
    s = k.step(s, TURN_LEFT).state
    np.testing.assert_allclose(clean.update(s), [0.25, 0.0, math.radians(30)], atol=1e-9)


def _walk(k, s, actions):
    for a in actions:
        s = k.step(s, a).state
        yield s


def test_bounded_odometry_error_never_accumulates():
    """The paper's model: each reading is the truth plus a fresh error within the bounds, at any step."""
    k = Kinematics(BoxGrid(), AgentConfig(allow_sliding=True))
    s0 = state(2.0, 2.0, 0)
    clean, noisy = Odometry(), Odometry(OdometryNoise(0.007, 2.0))
    clean.reset(s0)
    noisy.reset(s0)
    rng = np.random.default_rng(1)
    actions = [TURN_LEFT, MOVE_FORWARD, MOVE_FORWARD, TURN_RIGHT, MOVE_FORWARD] * 100
    for s in _walk(k, s0, actions):
        e = clean.update(s)
        n = noisy.update(s, rng)
        assert np.all(np.abs(n[:2] - e[:2]) <= 0.007 + 1e-12)
        assert abs(math.remainder(n[2] - e[2], 2 * math.pi)) <= math.radians(2.0) + 1e-12


def test_drift_odometry_integrates_along_the_estimated_heading():
    """Dead reckoning: a heading error bends later translation, so the position error outgrows one step's bound."""
    k = Kinematics(BoxGrid(), AgentConfig(allow_sliding=True))
    s0 = state(2.0, 2.0, 0)
    clean, drift = Odometry(mode="drift"), Odometry(OdometryNoise(0.007, 2.0), mode="drift")
    truth = Odometry()
    for o in (clean, drift, truth):
        o.reset(s0)
    rng = np.random.default_rng(0)
    worst = 0.0
    actions = [TURN_LEFT, MOVE_FORWARD, MOVE_FORWARD, TURN_RIGHT, MOVE_FORWARD, TURN_RIGHT] * 80
    for s in _walk(k, s0, actions):
        t = truth.update(s)
        np.testing.assert_allclose(clean.update(s), t, atol=1e-9)  # noiseless dead reckoning is exact
        d = drift.update(s, rng)
        worst = max(worst, float(np.hypot(*(d[:2] - t[:2]))))
    assert worst > 0.05  # many times the 7 mm bound of one reading


def test_unknown_odometry_mode_is_a_clear_error():
    with pytest.raises(ValueError, match="odometry mode 'wobbly'"):
        Odometry(mode="wobbly")


def test_noise_option_picks_the_odometry_mode():
    from ovon.config.base import ConfigError
    from ovon.evaluate.config import parse_noise

    assert parse_noise("odometry").odometry_mode == "bounded"
    assert parse_noise("actuation,odometry:drift").odometry_mode == "drift"
    with pytest.raises(ConfigError, match="odometry\\[:bounded\\|drift\\]"):
        parse_noise("odometry:wobbly")
