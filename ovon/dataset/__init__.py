"""Episode datasets: records, lazy reading / atomic writing of the released layout, category splits."""

from ovon.dataset.io import (
    SPLIT_ALIASES,
    SPLITS,
    EpisodeDataset,
    SceneEpisodes,
    goals_for,
    read_shard,
    shard_exists,
    shard_path,
    write_scene_shard,
    write_split_shell,
)
from ovon.dataset.records import (
    DatasetError,
    Episode,
    ObjectGoal,
    ViewPoint,
    category_from_key,
    goal_key,
    resolve_scene_path,
    scene_basename,
    scene_stem,
)

__all__ = [
    "SPLITS",
    "SPLIT_ALIASES",
    "DatasetError",
    "Episode",
    "EpisodeDataset",
    "ObjectGoal",
    "SceneEpisodes",
    "ViewPoint",
    "category_from_key",
    "goal_key",
    "goals_for",
    "read_shard",
    "resolve_scene_path",
    "scene_basename",
    "scene_stem",
    "shard_exists",
    "shard_path",
    "write_scene_shard",
    "write_split_shell",
]
