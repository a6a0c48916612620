"""Episode-generation configs (dataset.md). `paper` follows the paper; `fast` is for CPU demos/tests."""

from __future__ import annotations

from dataclasses import dataclass, field, replace


@dataclass(frozen=True)
class ViewpointConfig:
    render_size: int = 512  # square frames for generation
    hfov_deg: float = 90.0
    camera_height: float = 1.31
    grid_step: float = 0.25
    max_distance: float = 1.0  # viewpoints within this of the object's oriented box
    tilts_deg: tuple[float, ...] = (-30.0, 0.0, 30.0)
    min_score: float = 0.05  # keep viewpoints whose summed coverage exceeds this
    goal_min_coverage: float = 0.05  # an object is a goal if seen at > 5% of the frame from some viewpoint
    backend: str = "auto"
    max_viewpoints: int = 0  # 0 = keep all; else the best N (file size)


@dataclass(frozen=True)
class StartConfig:
    min_island_radius: float = 1.5
    min_geodesic: float = 1.0
    max_geodesic: float = 30.0
    max_height_span: float = 0.25  # single floor: the path's height range
    min_geo_euclid_ratio: float = 1.0  # paper's optional hard rule uses 1.05
    pointnav_ratio_rejection: bool = True  # keep w.p. 20*(r-0.98)^2 when r < 1.1
    max_tries: int = 2000
    oracle_check: bool = True  # keep a start only if the shortest-path oracle finishes from it (grid rollout)


@dataclass(frozen=True)
class SplitGenConfig:
    seed: int = 0
    holdout_fraction: float = 0.25
    similarity_threshold: float = 0.68
    children: bool = True  # children_object_categories from synonym families (splits.children_for)
    # Children = same shape family AND text similarity >= this. Higher than the split threshold because at
    # 0.68 a third of the categories get children ("bathroom cabinet" -> five other cabinets).
    children_threshold: float = 0.8


@dataclass(frozen=True)
class GenerationConfig:
    seed: int = 0
    episodes_per_train_scene: int = 50_000
    episodes_per_val_split: int = 3_000  # released val splits hold 3000 episodes each
    viewpoints: ViewpointConfig = field(default_factory=ViewpointConfig)
    starts: StartConfig = field(default_factory=StartConfig)
    splits: SplitGenConfig = field(default_factory=SplitGenConfig)
    decimals: int = 6  # positions rounded for stable, compact files


def paper_generation() -> GenerationConfig:
    return GenerationConfig()


def fast_generation() -> GenerationConfig:
    """Small frames (coverage is a fraction, so it barely changes) and few episodes."""
    g = GenerationConfig(episodes_per_train_scene=60, episodes_per_val_split=60)
    return replace(g, viewpoints=replace(g.viewpoints, render_size=96, max_viewpoints=16))


GENERATION_PRESETS = {"paper": paper_generation, "fast": fast_generation}
