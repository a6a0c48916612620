"""The privileged experts as agents: the shortest-path oracle and the frontier-exploration expert."""

from __future__ import annotations

from ovon.experts.config import FrontierExpertConfig


class _ExpertAgent:
    privileged = True

    def __init__(self, expert):
        self.expert = expert
        self._needs_reset = True

    def reset(self, episode_info: dict) -> None:
        self._needs_reset = True

    def act(self, observation: dict) -> int:
        p = observation["privileged"]
        if self._needs_reset:
            self.expert.reset(p.grid, [(v.position, v.yaw) for v in p.viewpoints], p.state)
            self._needs_reset = False
        return int(self.expert.act(p.state))


class ShortestPathAgent(_ExpertAgent):
    def __init__(self, **kwargs):
        from ovon.experts.shortest_path import ShortestPathExpert

        super().__init__(ShortestPathExpert(FrontierExpertConfig(**kwargs)))


class FrontierAgent(_ExpertAgent):
    def __init__(self, **kwargs):
        from ovon.experts.frontier_expert import FrontierExpert

        super().__init__(FrontierExpert(FrontierExpertConfig(**kwargs)))
