"""Stretch-like agent kinematics on the navigability grid: the six actions (docs/spec.md#actions), collisions,
optional sliding, actuation noise, and odometry relative to the start pose.

Collision model: forward motion is checked against the navigable (radius-eroded) grid by sampling the
segment at half-cell steps (`ovon.sim.collision.free_prefix`, shared with the experts). Without sliding
the agent stops at the last navigable sample before the obstacle (Habitat's `tryStepNoSliding` stops at
the contact too); with sliding the agent ends at the navigable point nearest to the target among the
cells it can reach around the move (`ovon.sim.collision.slide_point`, Detour's moveAlongSurface on the
grid: the target projected onto the wall it hits).
Either way the step reports `collided=True`.

On a scene read from a habitat navmesh, every move (forward, and a noisy turn's drift) follows the navmesh's
polygons instead (`surface`): with sliding `PathFinder.try_step`, Detour's moveAlongSurface as habitat runs
it (it reproduces habitat's golden 57-step trajectory to under a micrometre); without, `try_step_no_sliding`,
straight along the move to the first wall. It collided when it moved less than asked (habitat-lab's rule:
squared distances, 1e-5 slack).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ovon.config.sim import AgentConfig
from ovon.geometry import heading_vector, wrap_angle
from ovon.sim.collision import forward_delta, free_prefix, slide_point
from ovon.sim.noise import ActuationNoise, OdometryNoise
from ovon.sim.types import AgentState

STOP, MOVE_FORWARD, TURN_LEFT, TURN_RIGHT, LOOK_UP, LOOK_DOWN = range(6)
ACTION_NAMES = ("stop", "move_forward", "turn_left", "turn_right", "look_up", "look_down")


@dataclass
class StepResult:
    state: AgentState
    collided: bool


class Kinematics:
    """Applies actions to the true state on one floor's `NavGrid`."""

    def __init__(self, grid, cfg: AgentConfig, actuation: ActuationNoise | None = None, surface=None):  # noqa: ANN001
        self.grid = grid
        self.cfg = cfg
        self.actuation = actuation
        self.surface = surface  # a navmesh PathFinder: moves follow its polygons
        self._navigable = np.ascontiguousarray(grid.navigable, dtype=np.bool_)

    def step(self, state: AgentState, action: int, rng: np.random.Generator | None = None) -> StepResult:
        s = state.copy()
        cfg = self.cfg
        if action == STOP:
            return StepResult(s, False)
        if action in (LOOK_UP, LOOK_DOWN):
            delta = math.radians(cfg.look_angle_deg) * (1 if action == LOOK_UP else -1)
            s.pitch = float(np.clip(s.pitch + delta, math.radians(cfg.min_pitch_deg), math.radians(cfg.max_pitch_deg)))
            return StepResult(s, False)
        if action in (TURN_LEFT, TURN_RIGHT):
            sign = 1.0 if action == TURN_LEFT else -1.0
            s.yaw = wrap_angle(s.yaw + sign * math.radians(cfg.turn_angle_deg))
            if self.actuation is not None and rng is not None:
                fwd, lat, dyaw = self.actuation.sample(rng, is_turn=True, turn_sign=sign)
                s.yaw = wrap_angle(s.yaw + dyaw)
                d = self._local_to_world(s.yaw, fwd, lat)
                s.position, collided = self._move(s.position, float(d[0]), float(d[2]))
                return StepResult(s, collided)
            return StepResult(s, False)
        if action == MOVE_FORWARD:
            dx, dz = forward_delta(s.yaw, cfg.forward_step)  # the experts predict collisions with this too
            dyaw = 0.0
            if self.actuation is not None and rng is not None:
                nf, nl, dyaw = self.actuation.sample(rng, is_turn=False)
                noise = self._local_to_world(s.yaw, nf, nl)
                dx, dz = dx + float(noise[0]), dz + float(noise[2])
            s.position, collided = self._move(s.position, dx, dz)
            s.yaw = wrap_angle(s.yaw + dyaw)
            return StepResult(s, collided)
        raise ValueError(f"unknown action {action!r}; valid actions are 0..5 ({', '.join(ACTION_NAMES)})")

    @staticmethod
    def _local_to_world(yaw: float, forward: float, lateral: float) -> np.ndarray:
        f = heading_vector(yaw)
        right = np.array([-f[2], 0.0, f[0]])  # forward rotated -90 deg about +y
        return f * forward + right * lateral

    def _free_prefix(self, start: np.ndarray, dx: float, dz: float) -> tuple[np.ndarray, bool]:
        """Last navigable sample along the move and whether the whole move was free."""
        g = self.grid
        k, n = free_prefix(
            self._navigable,
            float(g.origin[0]),
            float(g.origin[1]),
            float(g.cell_size),
            float(start[0]),
            float(start[2]),
            dx,
            dz,
        )
        f = k / n
        return np.array([start[0] + dx * f, start[1], start[2] + dz * f], dtype=np.float64), k == n

    def _move(self, start: np.ndarray, dx: float, dz: float) -> tuple[np.ndarray, bool]:
        if self.surface is not None:
            target = np.array([start[0] + dx, start[1], start[2] + dz], dtype=np.float64)
            step = self.surface.try_step if self.cfg.allow_sliding else self.surface.try_step_no_sliding
            out = step(start, target)
            asked, moved = float(((target - start) ** 2).sum()), float(((out - start) ** 2).sum())
            return out, moved + 1e-5 < asked
        reached, free = self._free_prefix(start, dx, dz)
        if not free and self.cfg.allow_sliding:
            g = self.grid
            px, pz = slide_point(
                self._navigable,
                float(g.origin[0]),
                float(g.origin[1]),
                float(g.cell_size),
                float(start[0]),
                float(start[2]),
                dx,
                dz,
            )
            reached = np.array([px, start[1], pz], dtype=np.float64)
        out = reached
        r, c = self.grid.world_to_cell(out)
        h = float(self.grid.heights[r, c])
        if math.isfinite(h):
            out[1] = h
        return out, not free


class Odometry:
    """Pose relative to the start (forward, left, dyaw in the start frame); the true pose is never changed.

    `mode="bounded"` (the paper's model, arXiv 2409.14296 Sec. "noise"): every reading is the true relative
    pose plus a fresh uniform error, so the error never exceeds the noise bounds. `mode="drift"`: dead
    reckoning, each step's body-frame motion (forward, left, turn) plus the error is integrated along the
    *estimated* heading, so heading error bends every later translation, as real wheel odometry drifts.
    """

    MODES = ("bounded", "drift")

    def __init__(self, noise: OdometryNoise | None = None, mode: str = "bounded"):
        if mode not in self.MODES:
            raise ValueError(f"odometry mode {mode!r}: expected one of {', '.join(self.MODES)}")
        self.noise = noise
        self.mode = mode
        self._start: AgentState | None = None
        self._prev_true: AgentState | None = None
        self._estimate = np.zeros(3)

    def reset(self, start: AgentState) -> np.ndarray:
        self._start = start.copy()
        self._prev_true = start.copy()
        self._estimate = np.zeros(3)
        return self._estimate.copy()

    def relative(self, state: AgentState) -> np.ndarray:
        """True pose relative to the start: forward (m), left (m), dyaw (rad)."""
        assert self._start is not None
        d = state.position - self._start.position
        f = heading_vector(self._start.yaw)
        left = np.array([f[2], 0.0, -f[0]])
        return np.array([float(d @ f), float(d @ left), wrap_angle(state.yaw - self._start.yaw)], dtype=np.float64)

    def update(self, state: AgentState, rng: np.random.Generator | None = None) -> np.ndarray:
        assert self._prev_true is not None
        noisy = self.noise is not None and rng is not None
        if self.mode == "bounded":
            self._estimate = self.relative(state)
            if noisy:
                self._estimate = self._estimate + self.noise.sample(rng)
        else:
            self._estimate = self._dead_reckon(state, rng if noisy else None)
        self._estimate[2] = wrap_angle(self._estimate[2])
        self._prev_true = state.copy()
        return self._estimate.copy()

    def _dead_reckon(self, state: AgentState, rng: np.random.Generator | None) -> np.ndarray:
        """Integrate the true step, measured in the agent's previous body frame, along the estimated heading."""
        prev = self._prev_true
        d = state.position - prev.position
        f = heading_vector(prev.yaw)
        left = np.array([f[2], 0.0, -f[0]])
        step = np.array([float(d @ f), float(d @ left), wrap_angle(state.yaw - prev.yaw)])
        if rng is not None and np.any(step != 0):
            step = step + self.noise.sample(rng)
        est = self._estimate.copy()
        c, s = math.cos(est[2]), math.sin(est[2])  # body frame -> start frame (forward, left)
        est[0] += c * step[0] - s * step[1]
        est[1] += s * step[0] + c * step[1]
        est[2] += step[2]
        return est
