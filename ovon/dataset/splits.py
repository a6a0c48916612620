"""Category and scene splits (paper: "we uniformly sample ~25% of the object categories ... allocated to
val_seen_synonyms if the maximum SentenceBERT similarity to a training category surpasses a threshold,
otherwise to val_unseen").

Why code: upstream never published this step (its lists came from a manual CSV); here it is
deterministic from a seed and writes, per held-out category, its max similarity and nearest training
category so the split can be audited. Paper ranges: synonyms [0.68, 0.96], unseen [0.45, 0.68].
"""

from __future__ import annotations

import difflib
import json
from collections import Counter
from collections.abc import Collection, Iterable, Sequence
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
    # max cosine to train >= this -> val_seen_synonyms. (0, 1): a held-out name's highest MiniLM similarity
    # to the train names lies well inside (0, 1) in practice (paper: unseen 0.45-0.68, synonyms 0.68-0.96;
    # ours 0.40-0.93), so a threshold <= 0 sends every held-out category to val_seen_synonyms and one of 1
    # every one to val_unseen (only an exact duplicate reaches 1): an empty split either way
    similarity_threshold: float = in_range(0.68, 0.0, 1.0, lo_open=True, hi_open=True)
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
            raise DatasetError(
                f"{source}: malformed category split ({type(e).__name__}: {e}); expected lists train, "
                "val_seen_synonyms and val_unseen; fix: pass a categories.json written by "
                "`ovon dataset splits`"
            ) from None

    def save(self, path: str | Path) -> Path:
        """Write `categories.json` atomically."""
        return write_json(path, self.to_json())


CATEGORY_LISTS: tuple[str, ...] = ("train", *HELD_OUT_SPLITS)  # the lists of a categories.json
SPLITS_FIX = "or write a new file with `ovon dataset splits`"


def _shown(names: Sequence[str], n: int = 5) -> str:
    """The first `n` names, quoted, and how many more."""
    head = ", ".join(repr(c) for c in names[:n])
    return head + (f" and {len(names) - n} more" if len(names) > n else "")


def _categories_word(n: int) -> str:
    return "category" if n == 1 else "categories"


def _vocabulary_names() -> set[str]:
    from ovon.scenes.vocabulary import load_vocabulary

    return set(load_vocabulary().names)


def check_category_split(
    split: CategorySplit,
    source: str = "categories.json",
    *,
    known: Collection[str] | None = None,
    splits: Iterable[str] = (),
) -> CategorySplit:
    """Refuse a category split whose lists break the HM3D-OVON split rules, before any work; returns it.

    Why: a categories.json is read as given (`--categories`, or one left in an output folder), and a bad
    one used to generate silently wrong or empty splits (train categories in val_unseen: "unseen"
    episodes of trained categories; unknown names: splits that `dataset validate` then rejects as empty,
    or an error blaming the scenes). One line naming `source`, the list and the offending categories:

    - no category twice in a list;
    - val_seen_synonyms and val_unseen disjoint from train (held-out categories are never trained on;
      val_seen is train's categories on val scenes, docs/spec.md#category-split) and from each other;
    - every name in `known` (default: the embedded vocabulary, from which scene labels are cleaned: any
      other name can never match an annotated object);
    - train non-empty (the held-out lists are held out from it, val_seen uses it), and the list of every
      split in `splits` (those being generated) non-empty.
    """
    lists = {"train": list(split.train), **{k: [h.category for h in split.held_out(k)] for k in HELD_OUT_SPLITS}}
    fix = f"fix: edit that list in {source}, {SPLITS_FIX}"
    for key, names in lists.items():
        twice = sorted(c for c, n in Counter(names).items() if n > 1)
        if twice:
            raise DatasetError(
                f"{source}: {key} lists {_shown(twice)} more than once; expected each category once "
                f"per list; fix: remove the repeats from {key}"
            )
    rules = (
        ("val_unseen", "train", "val_unseen disjoint from train (unseen categories are never trained on)"),
        (
            "val_seen_synonyms",
            "train",
            "val_seen_synonyms disjoint from train (held-out synonyms of train categories are never trained on)",
        ),
        (
            "val_unseen",
            "val_seen_synonyms",
            "the held-out lists disjoint (a held-out category is a synonym of a train category or unseen, not both)",
        ),
    )
    for key, other, expected in rules:
        both = [c for c in lists[key] if c in set(lists[other])]
        if both:
            raise DatasetError(
                f"{source}: {key} lists {len(both)} {other} {_categories_word(len(both))} "
                f"({_shown(both)}); expected {expected}; fix: remove them from {key} or from "
                f"{other}, {SPLITS_FIX}"
            )
    vocabulary = known is None
    names_known = _vocabulary_names() if known is None else set(known)
    for key, names in lists.items():
        unknown = [c for c in names if c not in names_known]
        if unknown:
            close = difflib.get_close_matches(unknown[0], sorted(names_known), n=1, cutoff=0.8)
            hint = f" (did you mean {close[0]!r} for {unknown[0]!r}?)" if close else ""
            where = "the embedded vocabulary (`ovon scenes vocabulary` lists it)" if vocabulary else "the known ones"
            raise DatasetError(
                f"{source}: {key} names {len(unknown)} {_categories_word(len(unknown))} that "
                f"{'is' if len(unknown) == 1 else 'are'} not in the "
                f"{'vocabulary' if vocabulary else 'known categories'} ({_shown(unknown)}){hint}; "
                f"expected category names of {where}: no annotated object can match them; "
                f"fix: correct or remove them, {SPLITS_FIX}"
            )
    # train and val_seen episodes draw from the train list, the held-out splits from their own
    needed = dict.fromkeys(["train", *(k if k in HELD_OUT_SPLITS else "train" for k in map(canonical_split, splits))])
    for key in needed:
        if not lists[key]:
            why = (
                "the held-out categories are held out from train and val_seen uses its categories"
                if key == "train"
                else f"the {key} split would get no episode"
            )
            raise DatasetError(f"{source}: {key} is empty ({why}); expected at least one category in {key}; {fix}")
    return split


def load_category_split(
    path: str | Path, *, known: Collection[str] | None = None, splits: Iterable[str] = ()
) -> CategorySplit:
    """Read a categories.json and check its lists (`check_category_split`: disjoint where the paper
    requires, known names, train and the lists of `splits` non-empty); one line naming the file if not."""
    path = Path(path)
    fix = "fix: pass a categories.json written by `ovon dataset splits`"
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError, RecursionError) as e:
        raise DatasetError(f"{path}: not valid JSON ({type(e).__name__}); {fix}") from None
    if not isinstance(doc, dict):
        raise DatasetError(f"{path}: expected a JSON object with train / val_seen_synonyms / val_unseen; {fix}")
    for key in CATEGORY_LISTS:
        if key in doc and not isinstance(doc[key], list):
            raise DatasetError(
                f"{path}: malformed category split: {key} = {str(doc[key])[:60]!r}: expected a list "
                f"of categories; {fix}"
            )
    split = CategorySplit.from_json(doc, source=str(path))
    return check_category_split(split, str(path), known=known, splits=splits)


def empty_held_out_problem(split: CategorySplit, n_categories: int, holdout: float | None = None) -> str | None:
    """Why a split just computed by `split_categories` would leave a held-out split empty, naming the
    option to change (`--holdout`, `--threshold`) and a value that works; None when both lists have
    categories. Why: an empty val_seen_synonyms or val_unseen gives a dataset whose split `dataset
    validate` rejects, after the whole generation."""
    held = sorted([*split.val_seen_synonyms, *split.val_unseen], key=lambda h: h.max_similarity)
    if len(held) < 2:
        given = f" {holdout:g}" if holdout is not None else ""
        return (
            f"--holdout{given} holds out {len(held)} of the {n_categories} categories; expected at least 2 "
            "(one for val_seen_synonyms, one for val_unseen); fix: pass a larger --holdout (default 0.25)"
        )
    empty = "val_unseen" if not split.val_unseen else ("val_seen_synonyms" if not split.val_seen_synonyms else "")
    if not empty:
        return None
    sims = sorted({h.max_similarity for h in held})
    full = "val_seen_synonyms" if empty == "val_unseen" else "val_unseen"
    span = f"their highest similarity to a train category lies in [{sims[0]:g}, {sims[-1]:g}]"
    if len(sims) < 2:
        fix = "another --seed or --holdout (every held-out category has the same similarity)"
    else:
        good = 0.68 if sims[0] < 0.68 <= sims[-1] else sims[len(sims) // 2]
        fix = f"a --threshold above {sims[0]:g} and at most {sims[-1]:g}, e.g. --threshold {good:g}"
    return (
        f"--threshold {split.threshold:g} puts all {len(held)} held-out categories in {full} ({span}), so "
        f"{empty} would be empty; expected a threshold inside that range; fix: pass {fix}"
    )


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
