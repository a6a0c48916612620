"""Episode lists for training without a dataset (ad-hoc goals in procedural houses)."""

from __future__ import annotations

from collections.abc import Sequence

from ovon.task.episode import EpisodeSpec


def adhoc_specs(
    scene_seeds: Sequence[int], categories: Sequence[str] | None = None, per_scene: int = 0
) -> list[EpisodeSpec]:
    """One episode per (procedural house, goal category), random starts.

    `categories` restricts the goals; `per_scene` > 0 keeps that many categories per house."""
    from ovon.scenes.procedural import generate_house

    specs = []
    for seed in scene_seeds:
        cats = generate_house(int(seed)).categories
        if categories is not None:
            cats = [c for c in cats if c in set(categories)]
        if per_scene > 0:
            cats = cats[:per_scene]
        specs += [
            EpisodeSpec(episode_id=f"adhoc-{seed}-{c}", scene=f"procedural:{seed}", goal_category=c, split="train")
            for c in cats
        ]
    return specs
