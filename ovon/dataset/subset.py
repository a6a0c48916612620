"""Canonical episode subsets, chosen by content so anyone holding the same dataset gets the same ids.

Papers evaluate "360 random episodes" or subsets of unknown origin whose ids were never published, so
their numbers cannot be reproduced. A subset here is a rule, not a list: every episode gets a rank, the
SHA-256 of `split|scene id|episode id` (the ids as written in the episode files), and a split's quota is
spread over its scenes, then over each scene's goal categories, in proportion to their episode counts
(largest remainders, ties broken by rank); each (scene, category) stratum gives its lowest-ranked episodes.
Nothing depends on the order or location of files, and the rank does not involve the subset's size, so a
subset file is only a convenience: the rule and the dataset reproduce it.
"""

from __future__ import annotations

import hashlib
import json
from collections import defaultdict
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

from ovon.atomic import write_json
from ovon.dataset.episodes import SplitEpisodes
from ovon.dataset.io import VAL_SPLITS, EpisodeDataset
from ovon.dataset.validate import usable_episodes

RULE = "sha256(split|scene_id|episode_id) rank; proportional quotas per scene, then per goal category"
# Named subsets, defined by rule and size so that no id list needs to be shipped.
NAMED: dict[str, int] = {"mini": 360}

EpisodeRef = tuple[str, str]  # (scene id as in the episode file, episode id)


def ids_sha256(ids: Iterable[tuple[str, str, str]]) -> str:
    """The hash of an episode set, (split, scene id, episode id) in any order: what a subset file and a
    protocol card cite, the same for the same episodes."""
    return hashlib.sha256(json.dumps(sorted(map(list, ids))).encode()).hexdigest()


def rank(split: str, scene_id: str, episode_id: str) -> str:
    return hashlib.sha256(f"{split}|{scene_id}|{episode_id}".encode()).hexdigest()


def _quotas(counts: dict[str, int], total: int, tie: dict[str, str]) -> dict[str, int]:
    """Hamilton's largest-remainder apportionment of `total` over keys, in proportion to `counts`."""
    n = sum(counts.values())
    exact = {k: total * c / n for k, c in counts.items()}
    out = {k: int(v) for k, v in exact.items()}
    left = total - sum(out.values())
    for k in sorted(counts, key=lambda k: (-(exact[k] - out[k]), tie[k]))[:left]:
        out[k] += 1
    return out


def choose(split: str, episodes: Iterable[tuple[str, str, str]], size: int) -> list[EpisodeRef]:
    """`size` of (scene id, episode id, goal category) episodes by the rule; all of them when fewer."""
    strata: dict[str, dict[str, list[tuple[str, EpisodeRef]]]] = defaultdict(lambda: defaultdict(list))
    for scene, eid, category in episodes:
        strata[scene][category].append((rank(split, scene, eid), (scene, eid)))
    for cats in strata.values():
        for eps in cats.values():
            eps.sort()
    first = {s: min(e[0][0] for e in cats.values()) for s, cats in strata.items()}
    n = sum(len(e) for cats in strata.values() for e in cats.values())
    per_scene = _quotas({s: sum(map(len, c.values())) for s, c in strata.items()}, min(size, n), first)
    picked: list[tuple[str, EpisodeRef]] = []
    for scene, cats in strata.items():
        per_cat = _quotas({c: len(e) for c, e in cats.items()}, per_scene[scene], {c: e[0][0] for c, e in cats.items()})
        for cat, eps in cats.items():
            picked += eps[: per_cat[cat]]
    return [ref for _, ref in sorted(picked)]


@dataclass(frozen=True)
class Subset:
    name: str
    size: int  # asked per split
    splits: dict[str, list[EpisodeRef]]

    @property
    def ids_sha256(self) -> str:
        return ids_sha256((split, scene, eid) for split, refs in self.splits.items() for scene, eid in refs)

    def to_json(self) -> dict:
        return {
            "name": self.name,
            "rule": RULE,
            "size_per_split": self.size,
            "ids_sha256": self.ids_sha256,
            "splits": {s: [list(r) for r in refs] for s, refs in sorted(self.splits.items())},
        }


def split_episodes(data: str | Path, split: str) -> list[tuple[str, str, str]]:
    """(scene id, episode id, goal category) of every valid episode of a split, as written in its files
    (invalid ones, which evaluation skips, are never chosen)."""
    ds = EpisodeDataset(data, split)
    out = []
    for _, shard in ds.iter_scenes():  # the scene shards: what evaluation reads (`load_split`)
        good, _skipped = usable_episodes(shard)
        out += [(str(ep.scene_id), str(ep.episode_id), ep.object_category) for ep in good]
    return out


def make_subset(data: str | Path, size: int, name: str = "", splits: Iterable[str] = VAL_SPLITS) -> Subset:
    if size < 1:
        raise ValueError(f"--size {size}: expected a positive number of episodes per split; fix: e.g. --size 360")
    if name in NAMED and size != NAMED[name]:
        raise ValueError(
            f"--name {name!r} is the named subset of {NAMED[name]} episodes per split, not {size}; fix: another "
            f"--name, or --size {NAMED[name]}"
        )
    chosen = {s: choose(s, split_episodes(data, s), size) for s in splits}
    return Subset(name or f"size{size}", size, chosen)


def named_subset(data: str | Path, name: str, splits: Iterable[str]) -> Subset:
    if name not in NAMED:
        raise ValueError(
            f"subset {name!r} is not a named subset (known: {', '.join(sorted(NAMED))}); fix: name one of them, "
            "or pass a file written by `ovon dataset subset`"
        )
    return make_subset(data, NAMED[name], name, splits)


def write_subset(subset: Subset, out: str | Path) -> Path:
    return write_json(out, subset.to_json())


def read_subset(path: str | Path) -> Subset:
    """A subset file; anything else is one line naming the file and what was expected."""
    path = Path(path)
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
        splits = {str(s): [(str(a), str(b)) for a, b in refs] for s, refs in doc["splits"].items()}
        return Subset(str(doc["name"]), int(doc["size_per_split"]), splits)
    except (ValueError, KeyError, TypeError, AttributeError) as e:
        raise ValueError(
            f"{path}: not a subset file ({type(e).__name__}: {e}); expected the JSON that `ovon dataset subset` "
            "writes; fix: write it again with `ovon dataset subset DATA --size N --out FILE`"
        ) from None


def check_subset(subset: Subset, split: str, present: Iterable[EpisodeRef], where: str) -> set[EpisodeRef]:
    """The subset's ids of `split`; refuses ids the data does not hold (the subset was made from other data)."""
    if split not in subset.splits:
        raise ValueError(
            f"subset {subset.name!r} holds splits {sorted(subset.splits)}, not {split!r}; fix: --splits "
            f"{','.join(sorted(subset.splits))}, or make the subset with `ovon dataset subset ... --split {split}`"
        )
    wanted = set(subset.splits[split])
    missing = wanted - set(present)
    if missing:
        scene, eid = sorted(missing)[0]
        raise ValueError(
            f"subset {subset.name!r}: {len(missing)} episode(s) of {split} are not in {where} (e.g. episode {eid!r} of "
            f"{scene}); fix: make the subset from this dataset (`ovon dataset subset`) or evaluate the dataset it "
            "was made from"
        )
    return wanted


def load_subset(subset: str, data: str | Path, splits: Iterable[str]) -> Subset:
    """`--subset`: a named subset computed from `data` by its rule, else a subset file (a file called like a
    named subset is passed as ./NAME)."""
    if subset in NAMED:
        return named_subset(data, subset, splits)
    path = Path(subset)
    if path.is_file():
        return read_subset(path)
    raise ValueError(
        f"--subset {subset!r}: neither a subset file nor a named subset (known: {', '.join(sorted(NAMED))}); fix: "
        "pass a file written by `ovon dataset subset DATA --size N --out FILE`, or a named subset"
    )


def restrict_to_subset(sel: SplitEpisodes, subset: Subset, split: str, where: str, limit: int | None) -> SplitEpisodes:
    """The split's episodes that the subset names (in the split's order), the first `limit` of them when limited;
    refuses a subset naming episodes the data does not hold."""
    present = [(s.scene_key, s.episode_id) for s in sel.specs]
    wanted = check_subset(subset, split, present, where)
    keep = [i for i, ref in enumerate(present) if ref in wanted][:limit]
    return SplitEpisodes([sel.specs[i] for i in keep], [sel.shards[i] for i in keep], len(keep))
