"""The privileged experts as agents: the shortest-path oracle and the frontier-exploration expert.

Both read only `observation["privileged"]` (true pose, true map, goal viewpoints); their embodiment (turn
angle, step, FOV, success radius) comes from the episode's own sim/task config."""

from __future__ import annotations

from typing import Any

from ovon.config.base import from_dict, values_from_option
from ovon.experts import FrontierExpertConfig, ShortestPathExpertConfig
from ovon.experts.factory import make_expert
from ovon.experts.rig import Embodiment


class _ExpertAgent:
    privileged = True
    servable = False  # `ovon serve`: the navigation grid they plan on does not travel
    servable_reason = "it plans on the navigation grid, which the remote protocol does not carry"

    def __init__(self, name: str, cfg) -> None:
        self.name, self.cfg = name, cfg
        self.expert = None
        self._needs_reset = True
        self._last_action: int | None = None

    def reset(self, episode_info: dict) -> None:
        self._needs_reset = True
        self._last_action = None

    def act(self, observation: dict) -> int:
        p = observation["privileged"]
        if self._needs_reset:
            if self.expert is None or self.expert.body != Embodiment.of(p.sim, p.task):
                self.expert = make_expert(self.name, self.cfg, p.sim, p.task)
            self.expert.reset(p.grid, [(v.position, v.yaw) for v in p.viewpoints], p.state)
            self._needs_reset = False
        action = int(self.expert.act(p.state, self._last_action))
        self._last_action = action
        return action


def expert_config(cls: type, kwargs: dict[str, Any]) -> Any:
    """The expert config of these keyword arguments (`--agent-arg KEY=VALUE`) through `from_dict`: the
    declared domains, an unknown key named with the valid ones, one ConfigError line naming the argument.
    Why not `cls(**kwargs)`: it checks nothing, so `stop_margin_m=x` failed mid-episode (a TypeError after
    the run folder existed) and `no_frontier_behaviour=fly` or `lookahead_m=-1` ran."""
    with values_from_option("--agent-arg"):
        return from_dict(cls, kwargs)


class ShortestPathAgent(_ExpertAgent):
    def __init__(self, **kwargs: Any) -> None:
        """`kwargs`: `ShortestPathExpertConfig` fields, checked against their declared domains."""
        super().__init__("shortest-path", expert_config(ShortestPathExpertConfig, kwargs))


class FrontierAgent(_ExpertAgent):
    def __init__(self, **kwargs: Any) -> None:
        """`kwargs`: `FrontierExpertConfig` fields, checked against their declared domains."""
        super().__init__("frontier", expert_config(FrontierExpertConfig, kwargs))
