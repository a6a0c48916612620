"""Category and scene splits (paper: "we uniformly sample ~25% of the object categories ... allocated to
val_seen_synonyms if the maximum SentenceBERT similarity to a training category surpasses a threshold,
otherwise to val_unseen").

Why code: upstream never published this step (its lists came from a manual CSV); here it is
deterministic from a seed and writes, per held-out category, its max similarity and nearest training
category so the split can be audited. Paper ranges: synonyms [0.68, 0.96], unseen [0.45, 0.68].
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ovon.atomic import write_json
from ovon.config.base import in_range, non_empty, validate
from ovon.dataset.io import HELD_OUT_SPLITS, SPLIT_ALIASES, SPLITS
from ovon.dataset.records import DatasetError
from ovon.models.text_minilm import MODEL_NAME, TextEncoder


def canonical_split(split: str) -> str:
    """Our split name for either naming (val_unseen_easy -> val_seen_synonyms, ...)."""
    if split in SPLITS:
        return split
    if split in SPLIT_ALIASES:
        return SPLIT_ALIASES[split]
    raise ValueError(f"unknown split {split!r}; valid: {', '.join(SPLITS)} (or val_unseen_easy/hard)")


@dataclass
class SplitConfig:
    seed: int = in_range(0, 0, 2**32 - 1)
    # share of categories sampled as unseen candidates
    holdout_fraction: float = in_range(0.25, 0.0, 1.0, lo_open=True, hi_open=True)
    similarity_threshold: float = in_range(0.68, -1.0, 1.0)  # max cosine to train >= this -> val_seen_synonyms
    val_scene_fraction: float = in_range(0.2, 0.0, 1.0, lo_open=True, hi_open=True)  # paper: 36 of 181 scenes
    model: str = non_empty(MODEL_NAME)


@dataclass(frozen=True)
class HeldOutCategory:
    category: str
    max_similarity: float  # max cosine similarity to any train category
    nearest_train_category: str

    def to_json(self) -> dict[str, Any]:
        return {
            "category": self.category,
            "max_similarity": round(float(self.max_similarity), 6),
            "nearest_train_category": self.nearest_train_category,
        }


@dataclass
class CategorySplit:
    train: list[str]
    val_seen_synonyms: list[HeldOutCategory] = field(default_factory=list)
    val_unseen: list[HeldOutCategory] = field(default_factory=list)
    threshold: float = 0.68
    seed: int = 0
    model: str = MODEL_NAME

    def categories(self, split: str) -> list[str]:
        """Goal categories of an episode split (train and val_seen share the train categories)."""
        name = canonical_split(split)
        if name not in HELD_OUT_SPLITS:
            return list(self.train)
        return [h.category for h in self.held_out(name)]

    def held_out(self, split: str) -> list[HeldOutCategory]:
        name = canonical_split(split)
        if name == "val_seen_synonyms":
            return list(self.val_seen_synonyms)
        if name == "val_unseen":
            return list(self.val_unseen)
        raise ValueError(f"split {split!r} has no held-out categories")

    def similarity_range(self, split: str) -> tuple[float, float] | None:
        """(min, max) of the held-out categories' max similarity to train (paper's table column)."""
        sims = [h.max_similarity for h in self.held_out(split)]
        return (min(sims), max(sims)) if sims else None

    def to_json(self) -> dict[str, Any]:
        """The `categories.json` document."""
        return {
            "train": list(self.train),
            "val_seen_synonyms": [h.to_json() for h in self.val_seen_synonyms],
            "val_unseen": [h.to_json() for h in self.val_unseen],
            "threshold": self.threshold,
            "seed": self.seed,
            "model": self.model,
        }

    @classmethod
    def from_json(cls, doc: dict[str, Any], source: str = "categories.json") -> CategorySplit:
        try:
            held = {
                k: [
                    HeldOutCategory(str(h["category"]), float(h["max_similarity"]), str(h["nearest_train_category"]))
                    for h in doc[k]
                ]
                for k in HELD_OUT_SPLITS
            }
            return cls(
                train=[str(c) for c in doc["train"]],
                val_seen_synonyms=held["val_seen_synonyms"],
                val_unseen=held["val_unseen"],
                threshold=float(doc.get("threshold", 0.68)),
                seed=int(doc.get("seed", 0)),
                model=str(doc.get("model", MODEL_NAME)),
            )
        except (KeyError, TypeError, ValueError) as e:
            raise DatasetError(f"{source}: malformed category split ({type(e).__name__}: {e}); expected lists train, "
                               "val_seen_synonyms and val_unseen; fix: pass a categories.json written by "
                               "`ovon dataset splits`") from None

    def save(self, path: str | Path) -> Path:
        """Write `categories.json` atomically."""
        return write_json(path, self.to_json())


def load_category_split(path: str | Path) -> CategorySplit:
    path = Path(path)
    fix = "fix: pass a categories.json written by `ovon dataset splits`"
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError, RecursionError) as e:
        raise DatasetError(f"{path}: not valid JSON ({type(e).__name__}); {fix}") from None
    if not isinstance(doc, dict):
        raise DatasetError(f"{path}: expected a JSON object with train / val_seen_synonyms / val_unseen; {fix}")
    return CategorySplit.from_json(doc, source=str(path))


def split_categories(
    categories: Iterable[str],
    cfg: SplitConfig | None = None,
    encoder: TextEncoder | None = None,
    force_holdout: Sequence[str] = (),
) -> CategorySplit:
    """Sample ~holdout_fraction of the categories uniformly (seeded) as unseen candidates, then send
    each to val_seen_synonyms when its max cosine similarity to the train categories is >= the
    threshold, else to val_unseen. `force_holdout` categories are always candidates (tests, audits);
    the rest of the quota is sampled from the other categories. The result does not depend on the
    input order."""
    cfg = validate(cfg or SplitConfig())
    cats = sorted(set(categories))
    forced = sorted(set(force_holdout))
    unknown = [c for c in forced if c not in cats]
    if unknown:
        raise ValueError(f"force_holdout categories {unknown} are not in the category list")
    n_hold = max(int(round(cfg.holdout_fraction * len(cats))), len(forced))
    if n_hold >= len(cats):
        raise ValueError(f"holding out {n_hold} of {len(cats)} categories leaves no train category")
    rest = [c for c in cats if c not in forced]
    rng = np.random.default_rng(cfg.seed)
    sampled = [rest[i] for i in rng.choice(len(rest), size=n_hold - len(forced), replace=False)]
    candidates = sorted(set(forced) | set(sampled))
    train = [c for c in cats if c not in set(candidates)]
    if encoder is None:
        from ovon.models.text_minilm import default_text_encoder

        encoder = default_text_encoder()
    syn: list[HeldOutCategory] = []
    uns: list[HeldOutCategory] = []
    if candidates:
        sims = encoder.encode(candidates) @ encoder.encode(train).T  # (n_cand, n_train) cosine
        for i, c in enumerate(candidates):
            j = int(np.argmax(sims[i]))
            # rounded before comparing so categories.json and the assignment can never disagree
            h = HeldOutCategory(c, round(float(sims[i, j]), 6), train[j])
            (syn if h.max_similarity >= cfg.similarity_threshold else uns).append(h)
    return CategorySplit(train, syn, uns, cfg.similarity_threshold, cfg.seed, cfg.model)


def children_for(
    category: str,
    split_categories: Iterable[str],
    vocab: Any,
    encoder: TextEncoder,
    threshold: float = 0.68,
) -> list[str]:
    """`children_object_categories` of an episode whose goal is `category`.

    Rule: the other categories of the SAME split's category list that share `category`'s shape family
    in the vocabulary (they look alike in the embedded world) AND whose text similarity to `category`
    is >= `threshold`. Restricting to the split's own list means a synonym held out for
    val_seen_synonyms never becomes a goal of a train episode. Instances of children count as goals.
    `vocab` is an `ovon.scenes.vocabulary.Vocabulary` (anything with `in` and `[name].family`); a
    category unknown to it has no children. Sorted by name.
    """
    if category not in vocab:
        return []
    fam = vocab[category].family
    others = sorted({c for c in split_categories if c != category and c in vocab and vocab[c].family == fam})
    if not others:
        return []
    e = encoder.encode([category, *others])
    sims = e[1:] @ e[0]
    return [c for c, s in zip(others, sims) if float(s) >= threshold]


def children_map(
    split_categories: Iterable[str], vocab: Any, encoder: TextEncoder, threshold: float = 0.68
) -> dict[str, list[str]]:
    """`children_for` for every category of a split."""
    cats = sorted(set(split_categories))
    return {c: children_for(c, cats, vocab, encoder, threshold) for c in cats}


def split_scenes(scene_ids: Iterable[str], val_fraction: float = 0.2, seed: int = 0) -> tuple[list[str], list[str]]:
    """Disjoint (train, val) scene lists, deterministic from the seed and independent of input order;
    at least one val scene when there are two or more scenes and val_fraction > 0."""
    if not 0.0 <= val_fraction < 1.0:
        raise ValueError(f"val_fraction {val_fraction} must be in [0, 1)")
    scenes = sorted(set(scene_ids))
    n_val = int(round(val_fraction * len(scenes)))
    if val_fraction > 0 and len(scenes) >= 2:
        n_val = min(max(n_val, 1), len(scenes) - 1)
    perm = np.random.default_rng(seed).permutation(len(scenes))
    val = sorted(scenes[i] for i in perm[:n_val])
    vs = set(val)
    return [s for s in scenes if s not in vs], val
