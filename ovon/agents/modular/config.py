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
from pathlib import Path
from typing import Any, ClassVar, Literal, TypeVar

from ovon.config.base import (
    ConfigError,
    in_range,
    merge,
    non_negative,
    positive,
    rule,
    validate,
    values_from_option,
)
from ovon.models.config import DetectorConfig, ScorerConfig, detector_preset


@dataclass(frozen=True)
class MapConfig:
    """The agent's own top-down maps, from depth + odometry only."""

    cell_size_m: float = positive(0.05)  # 5 cm cells
    size_m: float = positive(50.0)  # square map centred on the start pose (VLFM: 1000 x 1000 cells)
    # depth points whose height above the floor lies in [min, max] are obstacles; None = the agent's height
    obstacle_min_height_m: float = 0.15
    obstacle_max_height_m: float | None = None
    inflation_radius_m: float | None = None  # None = the agent's radius
    view_range_m: float = positive(5.0)  # explored area: the camera cone up to this range, with line of sight
    pocket_area_m2: float = positive(1.5)  # unexplored pockets smaller than this count as explored
    min_frontier_m: float = 0.15  # frontiers shorter than this are ignored
    pixel_stride: int = in_range(1, 1, None)  # back-project every n-th pixel (rows and columns)
    bump_obstacles: bool = True  # a blocked MOVE_FORWARD (the `collided` bump sensor) marks the cell ahead

    rules: ClassVar = (
        rule(
            ("obstacle_min_height_m", "obstacle_max_height_m"),
            lambda lo, hi: hi is None or hi > lo,
            "obstacle_max_height_m > obstacle_min_height_m (or null)",
        ),
    )


@dataclass(frozen=True)
class LiftConfig:
    """Detections -> 3D goal points (depth + odometry pose)."""

    # erode masks (edge pixels mix object and background depth); VLFM: 5 at 640x480
    mask_erode_px: int = non_negative(1)
    # box-only detections: keep the central part (fraction removed)
    box_shrink: float = in_range(0.5, 0, 1, hi_open=True)
    max_points: int = in_range(2000, 1, None)  # stored goal points per episode (oldest dropped first)
    # evenly spaced subset of a detection's pixels (bounds the cost)
    points_per_detection: int = in_range(256, 1, None)
    min_range_m: float = 0.0  # ignore lifted points closer than this to the camera
    # ignore points beyond this fraction of the depth range (no hit / far)
    max_range_fraction: float = in_range(0.95, 0, 1, lo_open=True)


@dataclass(frozen=True)
class NavigatorConfig:
    """Point-goal navigation (bee-lining to the goal point, driving to frontiers)."""

    # geometric (A* on the agent's own obstacle map) | learned (a PointNav policy: `checkpoint`) |
    # package.module:Class
    kind: str = "geometric"
    stop_distance_m: float = positive(0.9)  # STOP when the goal point is this close (planar distance)
    turn_threshold_deg: float = positive(30.0)  # turn when the next waypoint is more than this off the heading
    lookahead_m: float = positive(1.0)  # furthest path cell in line of sight used as the heading target
    # plan to the nearest free cell in each of this many directions around a goal
    goal_ring_bins: int = in_range(12, 1, None)
    # on a cell its map blocks, the agent first heads to a free cell this close
    escape_radius_m: float = positive(0.5)
    # geometric: STOP after this many steps within one forward step of the stop radius without getting closer
    settle_steps: int = in_range(12, 1, None)
    checkpoint: str = ""  # for learned navigators: policy.pt of `ovon train --task pointnav` (or its run folder)
    # learned: the policy's memory restarts when the target moves further than this (a new frontier, or a
    # goal point lifted elsewhere); smaller moves are the same target seen better
    retarget_m: float = positive(0.5)
    # learned: argmax actions instead of sampling (seeded at each episode's reset, so runs repeat); argmax
    # locks into turn-left / turn-right cycles more often (PointNav on held-out houses: 62% vs 70% SR)
    deterministic: bool = False
    # learned: the policy is given the point this far along the route on the agent's map (A* as the geometric
    # navigator plans it), not the target itself, when the route is longer; 0 = the checkpoint's training
    # maximum (task.point_max_distance_m, geodesic). A goal vector alone says nothing about walls: a frontier
    # 8-10 m away behind a wall, out of the 1-6 m the policy trained on, had it bump into that wall until the
    # step limit
    subgoal_m: float = non_negative(0.0)
    # learned: the route point given to the policy stays fixed while it is further than this from the agent
    # and the target moved less than retarget_m, as a PointNav goal does in training. 0 = a new point along
    # the route every step: on a route longer than subgoal_m the point then slides ahead of the agent and
    # every slide over retarget_m restarts the policy's memory
    waypoint_keep_m: float = non_negative(0.0)
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
    handover_m: float = non_negative(0.25)
    # learned: when the policy moved less than one forward step over its last `stuck_steps` steps with a bump
    # among them, the geometric navigator drives the next `stuck_steps` steps. The policy, pushed against a
    # wall, alternates MOVE_FORWARD (bump) and a turn for hundreds of steps; 8 = the 6 turns that face any
    # direction plus 2. 0 = never
    stuck_steps: int = non_negative(8)

    rules: ClassVar = (
        rule(
            ("kind", "checkpoint"),
            lambda kind, checkpoint: kind != "learned" or _is_policy_file(checkpoint),
            "checkpoint = the policy.pt of `ovon train --task pointnav` (or its run folder) when kind = learned",
        ),
    )


def _is_policy_file(checkpoint: str) -> bool:
    """A policy file, or a run folder holding one (`navigator.checkpoint` of a learned navigator)."""
    path = Path(checkpoint) / "policy.pt" if checkpoint and Path(checkpoint).is_dir() else Path(checkpoint)
    return bool(checkpoint) and path.is_file()


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
    # confidence at the edge of the view cone (1 on the optical axis)
    min_confidence: float = in_range(0.25, 0, 1, lo_open=True)
    decision_threshold: float = 0.35  # new values below this and below the stored confidence are dropped
    # a frontier's value = median of the non-zero values within this radius
    frontier_radius_m: float = positive(0.5)
    hysteresis: float = 0.01  # keep the previous frontier unless another is better by more than this
    # the previous frontier "still exists" when a frontier waypoint is this close
    keep_radius_m: float = positive(0.5)


@dataclass(frozen=True)
class VLFMConfig(ModularConfig):
    value: ValueMapConfig = field(default_factory=ValueMapConfig)
    spin_steps: int = non_negative(12)  # TURN_LEFT steps at the start (12 x 30 deg = a full turn)
    frontier_reached_m: float = 0.5  # a frontier this close counts as reached: choose again
    # no progress toward a frontier for this many steps: abandon it (blacklist)
    stuck_steps: int = in_range(20, 1, None)
    # frontiers tried in one step when chosen ones turn out unreachable
    max_choices_per_step: int = in_range(8, 1, None)
    no_frontier: Literal["stop"] = "stop"  # what to do when no frontier is left (VLFM: STOP)


@dataclass(frozen=True)
class DAgRLODConfig(ModularConfig):
    """The end-to-end policy explores until the detector fires, then bee-lining takes over."""

    checkpoint: str = ""  # policy.pt (or a run folder) written by `ovon train`
    deterministic: bool = False  # argmax actions (else sample at `temperature`)
    temperature: float = 0.5
    threads: int = 1


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
T = TypeVar("T")


def checked(cfg: T, where: str) -> T:
    """`cfg` (the `where` part of a modular config) validated against its declared domains. Why: the parts
    also take configs built in Python, which no `merge` has checked; a bad value is one line naming its
    `--agent-arg` key."""
    with values_from_option("--agent-arg"):
        return validate(cfg, where)


def modular_config(cls: type[C], preset: str = "cpu", overrides: dict[str, Any] | None = None) -> C:
    """Preset, then overrides: dotted keys ({"detector.miss_rate": 0.2}) or nested dicts; a string under
    "detector" names a detector preset ("perfect", "noisy", "owlv2"), applied before the other keys; a string
    under "navigator" is its kind ("geometric", "learned", package.module:Class). Validated against the
    declared domains; a bad value is one line naming its `--agent-arg` key."""
    if preset not in PRESETS:
        raise ConfigError(f"unknown modular preset {preset!r}; valid: {list(PRESETS)}")
    cfg = cls()
    if preset == "paper":
        data = _paper(cfg)
        if not hasattr(cfg, "value"):
            data.pop("value")
        cfg = merge(cfg, data)
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
    with values_from_option("--agent-arg"):
        return merge(cfg, nested) if nested else validate(cfg)
