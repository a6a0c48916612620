"""The privileged experts as agents: the shortest-path oracle and the frontier-exploration expert.

Both read only `observation["privileged"]` (true pose, true map, goal viewpoints)."""

from __future__ import annotations

from ovon.experts import FrontierExpert, FrontierExpertConfig, ShortestPathExpert, ShortestPathExpertConfig


class _ExpertAgent:
    privileged = True

    def __init__(self, expert):
        self.expert = expert
        self._needs_reset = True
        self._last_action: int | None = None

    def reset(self, episode_info: dict) -> None:
        self._needs_reset = True
        self._last_action = None

    def act(self, observation: dict) -> int:
        p = observation["privileged"]
        if self._needs_reset:
            self.expert.reset(p.grid, [(v.position, v.yaw) for v in p.viewpoints], p.state)
            self._needs_reset = False
        action = int(self.expert.act(p.state, self._last_action))
        self._last_action = action
        return action


class ShortestPathAgent(_ExpertAgent):
    def __init__(self, **kwargs):
        super().__init__(ShortestPathExpert(ShortestPathExpertConfig(**kwargs)))


class FrontierAgent(_ExpertAgent):
    def __init__(self, **kwargs):
        super().__init__(FrontierExpert(FrontierExpertConfig(**kwargs)))
