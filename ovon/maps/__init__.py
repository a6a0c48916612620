"""Top-down map code shared by the privileged experts (true map) and the modular agents (their own map):
the explored map (view cone with exact line of sight), incremental frontiers with the pocket rule and the
grid planner (`ovon.maps.planner`: line-of-sight lookahead, steering with detours, multi-target A*)."""

from ovon.maps.frontiers import FrontierMap, Frontiers
from ovon.maps.visibility import ExploredMap, cone_bbox, cone_params

__all__ = ["ExploredMap", "FrontierMap", "Frontiers", "cone_bbox", "cone_params"]
