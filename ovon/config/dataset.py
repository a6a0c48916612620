"""Episode-generation configs (docs/spec.md#generation). `paper` follows the paper; `fast` is for CPU demos/tests.

Every field has a declared domain (`ovon.config.base`): a negative episode count, a 0-pixel render or a
0 m viewpoint grid is refused before any scene is loaded."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any, ClassVar, Literal

from ovon.config.base import Each, Range, build, constrained, in_range, less, non_empty, non_negative, positive, rule


@dataclass(frozen=True)
class ViewpointConfig:
    render_size: int = in_range(512, 8, 4096)  # square frames for generation
    hfov_deg: float = in_range(90.0, 0.0, 180.0, lo_open=True, hi_open=True)
    camera_height: float = in_range(1.31, 0.0, 5.0, lo_open=True)
    grid_step: float = in_range(0.25, 0.01, 5.0)
    max_distance: float = positive(1.0)  # viewpoints within this of the object's oriented box
    tilts_deg: tuple[float, ...] = non_empty((-30.0, 0.0, 30.0), each=Range(-90.0, 90.0))
    min_score: float = in_range(0.05, 0.0, 1.0, hi_open=True)  # keep viewpoints whose summed coverage exceeds this
    # an object is a goal if seen at > 5% of the frame from some viewpoint
    goal_min_coverage: float = in_range(0.05, 0.0, 1.0, hi_open=True)
    backend: Literal["auto", "gl", "embree"] = "auto"
    max_viewpoints: int = non_negative(0)  # 0 = keep all; else the best N (file size)


@dataclass(frozen=True)
class StartConfig:
    min_island_radius: float = non_negative(1.5)
    min_geodesic: float = non_negative(1.0)
    max_geodesic: float = positive(30.0)
    max_height_span: float = non_negative(0.25)  # single floor: the path's height range
    min_geo_euclid_ratio: float = non_negative(1.0)  # paper's optional hard rule uses 1.05
    pointnav_ratio_rejection: bool = True  # keep w.p. 20*(r-0.98)^2 when r < 1.1
    max_tries: int = in_range(2000, 1, 10_000_000)
    oracle_check: bool = True  # keep a start only if the shortest-path oracle finishes from it (grid rollout)
    # Start-distance strata of the val splits: geodesic bin edges (m, increasing), e.g. [1, 2.5, 4.5, 7, 30]. Each
    # val split's episodes are dealt over the bins in turn, so every split has the same number of episodes per bin
    # and the splits differ in their goal categories, not in how far their starts are (docs/concepts/protocol.md).
    # () = no strata (the paper's sampling).
    val_strata_m: tuple[float, ...] = constrained((), Each(Range(0.0, 1000.0)))

    rules: ClassVar = (
        less("min_geodesic", "max_geodesic"),
        rule(
            ("val_strata_m",),
            lambda e: len(e) == 0 or (len(e) >= 2 and all(a < b for a, b in zip(e, e[1:]))),
            "starts.val_strata_m empty or at least two increasing edges, e.g. [1.0, 2.5, 4.5, 7.0, 30.0]",
        ),
    )


@dataclass(frozen=True)
class SplitGenConfig:
    seed: int = non_negative(0)
    holdout_fraction: float = in_range(0.25, 0.0, 1.0, lo_open=True, hi_open=True)
    # <= 0 or 1 would leave a held-out list empty
    similarity_threshold: float = in_range(0.68, 0.0, 1.0, lo_open=True, hi_open=True)
    children: bool = True  # children_object_categories from synonym families (splits.children_for)
    # Children = same shape family AND text similarity >= this. Higher than the split threshold because at
    # 0.68 a third of the categories get children ("bathroom cabinet" -> five other cabinets).
    children_threshold: float = in_range(0.8, -1.0, 1.0)


@dataclass(frozen=True)
class GenerationConfig:
    seed: int = non_negative(0)
    episodes_per_train_scene: int = in_range(50_000, 1, 10_000_000)
    episodes_per_val_split: int = in_range(3_000, 1, 10_000_000)  # released val splits hold 3000 episodes each
    viewpoints: ViewpointConfig = field(default_factory=ViewpointConfig)
    starts: StartConfig = field(default_factory=StartConfig)
    splits: SplitGenConfig = field(default_factory=SplitGenConfig)
    decimals: int = in_range(6, 1, 15)  # positions rounded for stable, compact files


def paper_generation() -> GenerationConfig:
    return GenerationConfig()


def fast_generation() -> GenerationConfig:
    """Small frames (coverage is a fraction, so it barely changes) and few episodes. Every viewpoint is
    kept (no `max_viewpoints` cap): a cap keeps only the best-scoring side of each object and shrinks the
    success region below the paper's (all navigable poses within 1 m that see the object)."""
    g = GenerationConfig(episodes_per_train_scene=60, episodes_per_val_split=60)
    return replace(g, viewpoints=replace(g.viewpoints, render_size=96))


GENERATION_PRESETS = {"paper": paper_generation, "fast": fast_generation}


def generation_config(args: Any) -> GenerationConfig:
    """The `GenerationConfig` of an `ovon dataset generate` command line (an argparse namespace): the
    preset, `--config` (YAML), `--set`."""
    return build(GenerationConfig, GENERATION_PRESETS[args.preset](), args.config or None, args.set)
