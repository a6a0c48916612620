"""Configs of the modular agents (VLFM, DAgRL+OD): every number of docs/spec.md#baselines is a config value.

Built by `modular_config(cls, preset, overrides)`: a preset ("cpu", the default, or "paper"), then dotted
overrides such as `detector.miss_rate=0.2` (from `--agent-arg detector.miss_rate=0.2`); a wrong key fails
with the list of valid ones. Camera intrinsics and the agent's radius are not copied here: they come from
the simulator config the episode runs with (`episode_info["camera"]` / `["embodiment"]`, else the
`SimConfig` defaults), like the calibration a real robot knows about itself.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any, Literal, TypeVar

from ovon.config.base import ConfigError, merge
from ovon.models.detectors.config import DetectorConfig, detector_preset
from ovon.models.scorers import ScorerConfig


@dataclass(frozen=True)
class MapConfig:
    """The agent's own top-down maps, from depth + odometry only."""

    cell_size_m: float = 0.05  # 5 cm cells
    size_m: float = 50.0  # square map centred on the start pose (VLFM: 1000 x 1000 cells)
    # depth points whose height above the floor lies in [min, max] are obstacles; None = the agent's height
    obstacle_min_height_m: float = 0.15
    obstacle_max_height_m: float | None = None
    inflation_radius_m: float | None = None  # None = the agent's radius
    view_range_m: float = 5.0  # explored area: the camera cone up to this range, with line of sight
    pocket_area_m2: float = 1.5  # unexplored pockets smaller than this count as explored
    min_frontier_m: float = 0.15  # frontiers shorter than this are ignored
    pixel_stride: int = 1  # back-project every n-th pixel (rows and columns)
    bump_obstacles: bool = True  # a blocked MOVE_FORWARD (the `collided` bump sensor) marks the cell ahead

    def __post_init__(self) -> None:
        _positive(self, "maps", ("cell_size_m", "size_m", "view_range_m", "pocket_area_m2"))
        if self.pixel_stride < 1:
            raise ValueError(f"maps.pixel_stride = {self.pixel_stride!r} must be >= 1")
        top = self.obstacle_max_height_m
        if top is not None and top <= self.obstacle_min_height_m:
            raise ValueError(
                f"maps.obstacle_max_height_m = {top!r} must be above maps.obstacle_min_height_m = "
                f"{self.obstacle_min_height_m!r}"
            )


@dataclass(frozen=True)
class LiftConfig:
    """Detections -> 3D goal points (depth + odometry pose)."""

    mask_erode_px: int = 1  # erode masks (edge pixels mix object and background depth); VLFM: 5 at 640x480
    box_shrink: float = 0.5  # box-only detections: keep the central part (fraction removed)
    max_points: int = 2000  # stored goal points per episode (oldest dropped first)
    points_per_detection: int = 256  # evenly spaced subset of a detection's pixels (bounds the cost)
    min_range_m: float = 0.0  # ignore lifted points closer than this to the camera
    max_range_fraction: float = 0.95  # ignore points beyond this fraction of the depth range (no hit / far)

    def __post_init__(self) -> None:
        if self.mask_erode_px < 0 or self.max_points < 1 or self.points_per_detection < 1:
            raise ValueError("lifting.mask_erode_px must be >= 0, max_points and points_per_detection >= 1")
        if not 0.0 <= self.box_shrink < 1.0 or not 0.0 < self.max_range_fraction <= 1.0:
            raise ValueError("lifting.box_shrink must be in [0, 1) and lifting.max_range_fraction in (0, 1]")


@dataclass(frozen=True)
class NavigatorConfig:
    """Point-goal navigation (bee-lining to the goal point, driving to frontiers)."""

    # geometric (A* on the agent's own obstacle map) | learned (a PointNav policy: `checkpoint`) |
    # package.module:Class
    kind: str = "geometric"
    stop_distance_m: float = 0.9  # STOP when the goal point is this close (planar distance)
    turn_threshold_deg: float = 30.0  # turn when the next waypoint is more than this off the heading
    lookahead_m: float = 1.0  # furthest path cell in line of sight used as the heading target
    goal_ring_bins: int = 12  # plan to the nearest free cell in each of this many directions around a goal
    escape_radius_m: float = 0.5  # on a cell its map blocks, the agent first heads to a free cell this close
    # geometric: STOP after this many steps within one forward step of the stop radius without getting closer
    settle_steps: int = 12
    checkpoint: str = ""  # for learned navigators: policy.pt of `ovon train --task pointnav` (or its run folder)
    # learned: the policy's memory restarts when the target moves further than this (a new frontier, or a
    # goal point lifted elsewhere); smaller moves are the same target seen better
    retarget_m: float = 0.5
    # learned: argmax actions instead of sampling (seeded at each episode's reset, so runs repeat); argmax
    # locks into turn-left / turn-right cycles more often (PointNav on held-out houses: 62% vs 70% SR)
    deterministic: bool = False
    # learned: the policy is given the point this far along the route on the agent's map (A* as the geometric
    # navigator plans it), not the target itself, when the route is longer; 0 = the checkpoint's training
    # maximum (task.point_max_distance_m, geodesic). A goal vector alone says nothing about walls: a frontier
    # 8-10 m away behind a wall, out of the 1-6 m the policy trained on, had it bump into that wall until the
    # step limit
    subgoal_m: float = 0.0
    # learned: the route point given to the policy stays fixed while it is further than this from the agent
    # and the target moved less than retarget_m, as a PointNav goal does in training. 0 = a new point along
    # the route every step: on a route longer than subgoal_m the point then slides ahead of the agent and
    # every slide over retarget_m restarts the policy's memory
    waypoint_keep_m: float = 0.0
    # learned: when the policy picks a MOVE_FORWARD that the agent's map says is blocked (the agent standing
    # on a cell the map holds navigable), the geometric navigator drives the next `stuck_steps` steps (its
    # detour, then the route; with stuck_steps 0 only that step). Without it the policy drove through gaps
    # that the map's inflated obstacles close, and in the pocket behind such a gap the map held no route to
    # any frontier: VLFM then turned in place until the step limit. Masking the forward, or handing over
    # that one step only, left the policy alternating left and right turns in front of the blocked cell
    map_checked_forward: bool = True
    # learned: within stop_distance_m + this of a goal point the geometric navigator takes over (its final
    # approach and settle rule). The policy learned to reach a floor point within 0.36 m with its own STOP;
    # a goal point on an object, reached at 0.9 m with that STOP masked, is another task. 0 = never
    handover_m: float = 0.25
    # learned: when the policy moved less than one forward step over its last `stuck_steps` steps with a bump
    # among them, the geometric navigator drives the next `stuck_steps` steps. The policy, pushed against a
    # wall, alternates MOVE_FORWARD (bump) and a turn for hundreds of steps; 8 = the 6 turns that face any
    # direction plus 2. 0 = never
    stuck_steps: int = 8

    def __post_init__(self) -> None:
        _positive(
            self, "navigator", ("stop_distance_m", "turn_threshold_deg", "lookahead_m", "escape_radius_m", "retarget_m")
        )
        if self.kind == "learned":
            from pathlib import Path

            path = (
                Path(self.checkpoint) / "policy.pt"
                if self.checkpoint and Path(self.checkpoint).is_dir()
                else Path(self.checkpoint)
            )
            if not self.checkpoint or not path.is_file():
                raise ValueError(
                    f"navigator.checkpoint = {self.checkpoint!r} is not a policy file; fix: "
                    "--agent-arg navigator.checkpoint=PATH to the policy.pt of `ovon train --task "
                    "pointnav` (or its run folder)"
                )
        if self.subgoal_m < 0 or self.handover_m < 0 or self.waypoint_keep_m < 0:
            raise ValueError(
                f"navigator.subgoal_m = {self.subgoal_m!r}, navigator.handover_m = "
                f"{self.handover_m!r} and navigator.waypoint_keep_m = {self.waypoint_keep_m!r} "
                "must be >= 0"
            )
        if self.goal_ring_bins < 1:
            raise ValueError(f"navigator.goal_ring_bins = {self.goal_ring_bins!r} must be >= 1")
        if self.stuck_steps < 0:
            raise ValueError(f"navigator.stuck_steps = {self.stuck_steps!r} must be >= 0")
        if self.settle_steps < 1:
            raise ValueError(f"navigator.settle_steps = {self.settle_steps!r} must be >= 1")


@dataclass(frozen=True)
class ModularConfig:
    """What both modular agents share: maps, the detector, lifting and the bee-lining navigator."""

    maps: MapConfig = field(default_factory=MapConfig)
    detector: DetectorConfig = field(default_factory=DetectorConfig)
    lifting: LiftConfig = field(default_factory=LiftConfig)
    navigator: NavigatorConfig = field(default_factory=NavigatorConfig)


@dataclass(frozen=True)
class ValueMapConfig:
    """Language value map and frontier choice (docs/spec.md#value-map, #frontier-choice)."""

    scorer: ScorerConfig = field(default_factory=ScorerConfig)
    min_confidence: float = 0.25  # confidence at the edge of the view cone (1 on the optical axis)
    decision_threshold: float = 0.35  # new values below this and below the stored confidence are dropped
    frontier_radius_m: float = 0.5  # a frontier's value = median of the non-zero values within this radius
    hysteresis: float = 0.01  # keep the previous frontier unless another is better by more than this
    keep_radius_m: float = 0.5  # the previous frontier "still exists" when a frontier waypoint is this close

    def __post_init__(self) -> None:
        _positive(self, "value", ("frontier_radius_m", "keep_radius_m"))
        if not 0.0 < self.min_confidence <= 1.0:
            raise ValueError(f"value.min_confidence = {self.min_confidence!r} must be in (0, 1]")


@dataclass(frozen=True)
class VLFMConfig(ModularConfig):
    value: ValueMapConfig = field(default_factory=ValueMapConfig)
    spin_steps: int = 12  # TURN_LEFT steps at the start (12 x 30 deg = a full turn)
    frontier_reached_m: float = 0.5  # a frontier this close counts as reached: choose again
    stuck_steps: int = 20  # no progress toward a frontier for this many steps: abandon it (blacklist)
    max_choices_per_step: int = 8  # frontiers tried in one step when chosen ones turn out unreachable
    no_frontier: Literal["stop"] = "stop"  # what to do when no frontier is left (VLFM: STOP)

    def __post_init__(self) -> None:
        if self.spin_steps < 0 or self.stuck_steps < 1 or self.max_choices_per_step < 1:
            raise ValueError("spin_steps must be >= 0, stuck_steps and max_choices_per_step >= 1")


@dataclass(frozen=True)
class DAgRLODConfig(ModularConfig):
    """The end-to-end policy explores until the detector fires, then bee-lining takes over."""

    checkpoint: str = ""  # policy.pt (or a run folder) written by `ovon train`
    deterministic: bool = False  # argmax actions (else sample at `temperature`)
    temperature: float = 0.5
    threads: int = 1


def _positive(cfg: Any, group: str, names: tuple[str, ...]) -> None:
    for n in names:
        v = getattr(cfg, n)
        if not v > 0:
            raise ValueError(f"{group}.{n} = {v!r} must be > 0")


def _paper(base: ModularConfig) -> dict[str, Any]:
    """docs/spec.md#modular-baseline: obstacles 0.6-0.9 m above the floor, OWLv2, a neural image-text
    score (SigLIP here; the paper's VLFM used BLIP-2 ITC) with VLFM's prompt, masks eroded 5 times."""
    del base
    return {
        "maps": {"obstacle_min_height_m": 0.6, "obstacle_max_height_m": 0.9, "pixel_stride": 2},
        "detector": {"kind": "owlv2"},
        "lifting": {"mask_erode_px": 5},
        "value": {"scorer": {"kind": "siglip", "prompt": "Seems like there is a {goal} ahead."}},
    }


PRESETS = ("cpu", "paper")
C = TypeVar("C", bound=ModularConfig)


def modular_config(cls: type[C], preset: str = "cpu", overrides: dict[str, Any] | None = None) -> C:
    """Preset, then overrides: dotted keys ({"detector.miss_rate": 0.2}) or nested dicts; a string under
    "detector" names a detector preset ("perfect", "noisy", "owlv2"), applied before the other keys; a string
    under "navigator" is its kind ("geometric", "learned", package.module:Class)."""
    if preset not in PRESETS:
        raise ConfigError(f"unknown modular preset {preset!r}; valid: {list(PRESETS)}")
    cfg = cls()
    if preset == "paper":
        data = _paper(cfg)
        if not hasattr(cfg, "value"):
            data.pop("value")
        cfg = merge(cfg, data, cls.__name__)
    overrides = dict(overrides or {})
    if isinstance(overrides.get("navigator"), str):  # navigator=learned is navigator.kind=learned
        overrides["navigator.kind"] = overrides.pop("navigator")
    if isinstance(overrides.get("detector"), str):
        try:
            cfg = dataclasses.replace(cfg, detector=detector_preset(overrides.pop("detector")))
        except ValueError as e:
            raise ConfigError(str(e)) from None
    nested: dict[str, Any] = {}
    for key, value in overrides.items():
        node = nested
        parts = str(key).split(".")
        for p in parts[:-1]:
            node = node.setdefault(p, {})
        node[parts[-1]] = value
    try:
        return merge(cfg, nested, cls.__name__) if nested else cfg
    except (TypeError, ValueError) as e:
        raise ConfigError(f"{cls.__name__}: {e}") from None
