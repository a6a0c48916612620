"""Reading and writing episode datasets in the released HM3D-OVON layout.

Layout: `<root>/<split>/<split>.json.gz` (a shell, `{"episodes": []}`, possibly with top-level maps
that we keep but never require) and `<root>/<split>/content/<scene>.json.gz` shards holding
`episodes` and `goals_by_category`. Why lazy: train holds millions of episodes, so scenes are listed
up front and each shard is parsed only when asked for.
"""

from __future__ import annotations

import gzip
import json
import warnings
import zlib
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ovon.atomic import write_json_gz
from ovon.dataset.records import DatasetError, Episode, ObjectGoal, goal_key

# The split names, defined here only: the HM3D-OVON episode splits in the paper's order, the evaluation
# splits (the columns of its tables) and those whose goal categories training never sees.
SPLITS: tuple[str, ...] = ("train", "val_seen", "val_seen_synonyms", "val_unseen")
VAL_SPLITS: tuple[str, ...] = SPLITS[1:]
HELD_OUT_SPLITS: tuple[str, ...] = SPLITS[2:]
# Upstream generation code names the two unseen-category splits differently; accept both.
SPLIT_ALIASES: dict[str, str] = {
    "val_unseen_easy": "val_seen_synonyms",
    "val_unseen_hard": "val_unseen",
    "val_seen_synonyms": "val_unseen_easy",
    "val_unseen": "val_unseen_hard",
}
SHARD_SUFFIX = ".json.gz"
RECORD_FIX = "fix: correct that value in the file, or regenerate it with `ovon dataset generate`"
# A split is a folder under the dataset root: a plain name, never a path that could leave the root.
SPLIT_NAME_PATTERN = r"[A-Za-z0-9][A-Za-z0-9_.-]*"


@dataclass
class SceneEpisodes:
    """One shard: its episodes and the goal instances keyed by `<scene basename>_<category>`."""

    episodes: list[Episode]
    goals_by_category: dict[str, list[ObjectGoal]]
    extra: dict[str, Any] = field(default_factory=dict)  # unknown top-level keys, kept for writing

    def goals_for(self, episode: Episode) -> list[ObjectGoal]:
        return goals_for(episode, self.goals_by_category)


def goals_for(episode: Episode, goals_by_category: Mapping[str, list[ObjectGoal]]) -> list[ObjectGoal]:
    """Goal instances of the episode: those of `object_category` then of each child category.

    A missing key for the episode's own category is an error (the episode would be unsolvable); a
    child category without instances in this scene contributes nothing.
    """
    key = goal_key(episode.scene_id, episode.object_category)
    if key not in goals_by_category:
        raise KeyError(
            f"episode {episode.episode_id!r}: no goals_by_category entry {key!r} "
            f"({len(goals_by_category)} keys in this shard)"
        )
    out = list(goals_by_category[key])
    for child in episode.children_object_categories:
        out.extend(goals_by_category.get(goal_key(episode.scene_id, child), []))
    return out


# ----------------------------------------------------------------------------------------------------
# low-level reading


def _read_json_gz(path: Path) -> Any:
    try:
        with gzip.open(path, "rb") as f:
            raw = f.read()
    except (OSError, EOFError, zlib.error) as e:
        raise DatasetError(f"{path}: not a readable gzip file ({e})") from None
    try:
        return json.loads(raw.decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as e:
        raise DatasetError(f"{path}: not valid JSON ({e}); fix: regenerate or re-download the file") from None
    except RecursionError:
        raise DatasetError(
            f"{path}: JSON nested too deeply to be an episode file; fix: regenerate or re-download the file"
        ) from None


def parse_shard(doc: Any, require_goals: bool = True) -> SceneEpisodes:
    """Parse a shard document; errors name the key / record index (the caller adds the file)."""
    if not isinstance(doc, dict):
        raise DatasetError(f"top level: expected an object, got {type(doc).__name__}")
    if "episodes" not in doc:
        raise DatasetError("episodes: missing key")
    if require_goals and "goals_by_category" not in doc:
        raise DatasetError("goals_by_category: missing key")
    eps = doc["episodes"]
    if not isinstance(eps, list):
        raise DatasetError(f"episodes: expected a list, got {type(eps).__name__}")
    gbc = doc.get("goals_by_category", {}) or {}
    if not isinstance(gbc, dict):
        raise DatasetError(f"goals_by_category: expected an object, got {type(gbc).__name__}")
    goals: dict[str, list[ObjectGoal]] = {}
    for key, lst in gbc.items():
        where = f"goals_by_category[{key!r}]"
        if not isinstance(lst, list):
            raise DatasetError(f"{where}: expected a list, got {type(lst).__name__}")
        goals[key] = [ObjectGoal.from_dict(g, f"{where}[{i}]") for i, g in enumerate(lst)]
    episodes = [Episode.from_dict(e, f"episodes[{i}]") for i, e in enumerate(eps)]
    extra = {k: v for k, v in doc.items() if k not in ("episodes", "goals_by_category")}
    return SceneEpisodes(episodes, goals, extra)


def read_shard(path: str | Path, require_goals: bool = True) -> SceneEpisodes:
    """Load one `.json.gz` shard; any problem is a DatasetError naming the file and key."""
    path = Path(path)
    doc = _read_json_gz(path)
    try:
        return parse_shard(doc, require_goals=require_goals)
    except DatasetError as e:
        raise DatasetError(f"{path}: {e}; {RECORD_FIX}") from None


# ----------------------------------------------------------------------------------------------------
# dataset


def resolve_split_dir(root: str | Path, split: str) -> Path:
    """`<root>/<split>`, or the folder of the split's other name (val_unseen_easy <-> val_seen_synonyms,
    val_unseen_hard <-> val_unseen) when the asked one is absent."""
    root = Path(root)
    cand = [root / split]
    if split in SPLIT_ALIASES:
        cand.append(root / SPLIT_ALIASES[split])
    for c in cand:
        if c.is_dir():
            return c
    present = (
        sorted(p.name for p in root.iterdir() if p.is_dir() and not p.name.startswith(".")) if root.is_dir() else []
    )
    raise FileNotFoundError(
        f"split {split!r} not found: tried {', '.join(str(c) for c in cand)}; "
        + (
            f"splits present under {root}: {present}; fix: name one of them (--splits), or point --data at the "
            "dataset root that holds the split's folder"
            if root.is_dir()
            else f"{root} does not exist; fix: point --data at the dataset root (it holds val_seen/ ...)"
        )
    )


class EpisodeDataset:
    """Lazy view of one split: `scenes()` lists shards, `load_scene()` parses one on demand."""

    def __init__(self, root: str | Path, split: str) -> None:
        self.root = Path(root)
        self.split = split
        self.split_dir = resolve_split_dir(self.root, split)
        self._scenes: list[str] | None = None
        self._shell: dict[str, Any] | None = None

    def __repr__(self) -> str:
        return f"EpisodeDataset(root={str(self.root)!r}, split={self.split!r})"

    @property
    def shell_path(self) -> Path:
        return self.split_dir / f"{self.split_dir.name}{SHARD_SUFFIX}"

    @property
    def content_dir(self) -> Path:
        return self.split_dir / "content"

    def shard_path(self, scene: str) -> Path:
        return self.content_dir / f"{scene}{SHARD_SUFFIX}"

    def shell(self) -> dict[str, Any]:
        """Top-level document of `<split>.json.gz` (empty when the file is absent)."""
        if self._shell is None:
            if self.shell_path.is_file():
                doc = _read_json_gz(self.shell_path)
                if not isinstance(doc, dict):
                    raise DatasetError(f"{self.shell_path}: top level: expected an object")
                self._shell = doc
            else:
                self._shell = {}
        return self._shell

    def shell_episodes(self) -> SceneEpisodes:
        """Episodes stored directly in the shell (empty in the released per-scene layout)."""
        doc = self.shell()
        if not doc.get("episodes"):
            return SceneEpisodes([], {})
        try:
            return parse_shard(doc, require_goals=False)
        except DatasetError as e:
            raise DatasetError(f"{self.shell_path}: {e}; {RECORD_FIX}") from None

    def scenes(self) -> list[str]:
        """Scene names with a shard, sorted; `._*` AppleDouble files are skipped with a warning."""
        if self._scenes is None:
            names: list[str] = []
            junk: list[str] = []
            if self.content_dir.is_dir():
                for p in sorted(self.content_dir.iterdir()):
                    if not p.name.endswith(SHARD_SUFFIX) or not p.is_file():
                        continue
                    if p.name.startswith("._"):
                        junk.append(p.name)
                        continue
                    if p.name.startswith("."):  # our own temp files (`.X.json.gz.*.tmp` never match)
                        continue
                    names.append(p.name[: -len(SHARD_SUFFIX)])
            if junk:
                warnings.warn(
                    f"{self.content_dir}: skipping {len(junk)} AppleDouble junk file(s): {', '.join(junk)}",
                    stacklevel=2,
                )
            self._scenes = names
        return list(self._scenes)

    def __len__(self) -> int:
        return len(self.scenes())

    def load_scene(self, scene: str) -> SceneEpisodes:
        path = self.shard_path(scene)
        if not path.is_file():
            raise FileNotFoundError(f"no shard for scene {scene!r} in {self.content_dir}")
        return read_shard(path)

    def files(self) -> list[Path]:
        """The files that hold this split's episodes (shell + shards), for content hashes."""
        out = [self.shell_path] if self.shell_path.is_file() else []
        return out + [self.shard_path(s) for s in self.scenes()]

    def fingerprint(self) -> str:
        """Content hash of the split (names and bytes of its files): a run folder's input identity."""
        from ovon.runfolder import files_sha256

        return files_sha256(self.split_dir, [p.relative_to(self.split_dir) for p in self.files()])

    def iter_scenes(self) -> Iterator[tuple[str, SceneEpisodes]]:
        """(scene, shard) pairs, one shard in memory at a time."""
        for scene in self.scenes():
            yield scene, self.load_scene(scene)

    def iter_episodes(self) -> Iterator[Episode]:
        yield from self.shell_episodes().episodes
        for _, shard in self.iter_scenes():
            yield from shard.episodes


# ----------------------------------------------------------------------------------------------------
# writing


def shard_path(root: str | Path, split: str, scene: str) -> Path:
    return Path(root) / split / "content" / f"{scene}{SHARD_SUFFIX}"


def shard_exists(root: str | Path, split: str, scene: str) -> bool:
    """True when the scene's shard is on disk; shards are written atomically, so present = complete."""
    return shard_path(root, split, scene).is_file()


def shard_document(
    episodes: Iterable[Episode],
    goals_by_category: Mapping[str, Iterable[ObjectGoal]],
    extra: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """The JSON document of a shard; goal keys are sorted so the bytes do not depend on dict order."""
    doc: dict[str, Any] = {
        "episodes": [e.to_dict() for e in episodes],
        "goals_by_category": {k: [g.to_dict() for g in goals_by_category[k]] for k in sorted(goals_by_category)},
    }
    for k, v in (extra or {}).items():
        if k not in doc:
            doc[k] = v
    return doc


def write_scene_shard(
    root: str | Path,
    split: str,
    scene: str,
    episodes: Iterable[Episode],
    goals_by_category: Mapping[str, Iterable[ObjectGoal]],
    extra: Mapping[str, Any] | None = None,
) -> Path:
    """Write `<root>/<split>/content/<scene>.json.gz` atomically and byte-deterministically."""
    return write_json_gz(shard_path(root, split, scene), shard_document(episodes, goals_by_category, extra))


def write_split_shell(root: str | Path, split: str, extra: Mapping[str, Any] | None = None) -> Path:
    """Write `<root>/<split>/<split>.json.gz` = `{"episodes": [], **extra}`."""
    doc: dict[str, Any] = {"episodes": []}
    for k, v in (extra or {}).items():
        if k != "episodes":
            doc[k] = v
    return write_json_gz(Path(root) / split / f"{split}{SHARD_SUFFIX}", doc)
