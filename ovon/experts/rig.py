"""What the experts must know of the agent and the task, derived from the sim/task config.

Why derived: the experts predict the effect of their own actions (turn angle, forward step), explore
what the camera sees (its horizontal FOV) and stop inside the success radius. If these were copies in
the expert's own config, `--set sim.agent.turn_angle_deg=15` would leave a DAgger labeller assuming
30 deg without a word; here there is one source.
"""

from __future__ import annotations

from dataclasses import dataclass

from ovon.config.sim import SimConfig
from ovon.config.task import TaskConfig


@dataclass(frozen=True)
class Embodiment:
    turn_angle_deg: float  # one TURN_LEFT / TURN_RIGHT (sim.agent.turn_angle_deg)
    forward_step_m: float  # one MOVE_FORWARD (sim.agent.forward_step)
    fov_deg: float  # horizontal field of view of the camera (sim.camera.hfov_deg)
    stop_distance_m: float  # success radius around a viewpoint (task.success_distance)

    @classmethod
    def of(cls, sim: SimConfig | None = None, task: TaskConfig | None = None) -> Embodiment:
        sim, task = sim or SimConfig(), task or TaskConfig()
        return cls(
            float(sim.agent.turn_angle_deg),
            float(sim.agent.forward_step),
            float(sim.camera.hfov_deg),
            float(task.success_distance),
        )
