"""Category splits (synonyms vs unseen by MiniLM similarity), children rule, scene splits."""

from __future__ import annotations

import json
from dataclasses import dataclass

import numpy as np
import pytest
import torch

from ovon.dataset.splits import (
    CategorySplit,
    SplitConfig,
    children_for,
    load_category_split,
    split_categories,
    split_scenes,
)
from ovon.models.text_minilm import MiniLMTextEncoder, default_text_encoder

torch.set_num_threads(1)


@pytest.fixture(scope="module")
def encoder() -> MiniLMTextEncoder:
    return default_text_encoder()


def test_minilm_similarities(encoder):
    e = encoder.encode(["couch", "sofa", "toaster", "couch"])
    assert e.shape == (4, 384) and e.dtype == np.float32
    assert np.allclose(np.linalg.norm(e, axis=1), 1.0, atol=1e-5)
    assert np.array_equal(e[0], e[3])
    assert float(e[0] @ e[1]) > 0.8
    assert float(e[0] @ e[2]) < 0.4
    assert encoder.encode([]).shape == (0, 384)


def test_synonym_goes_to_synonyms_and_unrelated_to_unseen(encoder, tmp_path):
    cats = ["couch", "bed", "chair", "sofa", "toaster"]
    split = split_categories(cats, SplitConfig(seed=3), encoder, force_holdout=["sofa", "toaster"])
    assert split.train == ["bed", "chair", "couch"]
    assert [h.category for h in split.val_seen_synonyms] == ["sofa"]
    assert split.val_seen_synonyms[0].nearest_train_category == "couch"
    assert split.val_seen_synonyms[0].max_similarity >= 0.68
    assert [h.category for h in split.val_unseen] == ["toaster"]
    assert split.val_unseen[0].max_similarity < 0.68
    assert split.categories("val_seen") == split.train
    assert split.categories("val_unseen_easy") == ["sofa"]
    assert split.categories("val_unseen_hard") == ["toaster"]
    # categories.json round trip, audit fields present
    path = split.save(tmp_path / "categories.json")
    doc = json.loads(path.read_text())
    assert set(doc) == {"train", "val_seen_synonyms", "val_unseen", "threshold", "seed", "model"}
    assert doc["threshold"] == 0.68 and doc["seed"] == 3 and doc["model"] == "all-MiniLM-L6-v2"
    assert set(doc["val_unseen"][0]) == {"category", "max_similarity", "nearest_train_category"}
    back = load_category_split(path)
    assert isinstance(back, CategorySplit) and back.to_json() == split.to_json()


def test_split_is_deterministic_and_order_free(encoder):
    cats = [f"{a} {b}" for a in ("red", "small", "old", "tall") for b in ("lamp", "box", "table", "vase", "rug")]
    cfg = SplitConfig(seed=11)
    a = split_categories(cats, cfg, encoder)
    b = split_categories(list(reversed(cats)), cfg, encoder)
    assert a.to_json() == b.to_json()
    n_held = len(a.val_seen_synonyms) + len(a.val_unseen)
    assert n_held == 5 and len(a.train) == 15
    assert not set(a.train) & set(a.categories("val_seen_synonyms") + a.categories("val_unseen"))
    c = split_categories(cats, SplitConfig(seed=12), encoder)
    assert c.to_json() != a.to_json()


@dataclass(frozen=True)
class _Cat:
    family: str


def test_children_rule(encoder):
    vocab = {
        "couch": _Cat("sofa"),
        "sofa": _Cat("sofa"),
        "loveseat": _Cat("sofa"),
        "fridge": _Cat("appliance"),
        "refrigerator": _Cat("appliance"),
        "toaster": _Cat("appliance"),
    }
    train = ["couch", "sofa", "loveseat", "fridge", "refrigerator", "toaster"]
    # same family + similar text; loveseat (0.40) and toaster (other object) are not children
    assert children_for("couch", train, vocab, encoder, 0.68) == ["sofa"]
    assert children_for("fridge", train, vocab, encoder, 0.68) == ["refrigerator"]
    assert children_for("toaster", train, vocab, encoder, 0.68) == []
    # a synonym held out of the split never leaks in
    assert children_for("couch", ["couch", "loveseat"], vocab, encoder, 0.68) == []
    assert children_for("unknown thing", train, vocab, encoder, 0.68) == []


def test_split_scenes():
    scenes = [f"{i:05d}-scene{i}" for i in range(181)]
    tr, va = split_scenes(scenes, 0.2, seed=0)
    assert len(va) == 36 and len(tr) == 145 and not set(tr) & set(va)
    assert sorted(tr + va) == sorted(scenes)
    assert split_scenes(list(reversed(scenes)), 0.2, seed=0) == (tr, va)
    assert split_scenes(scenes, 0.2, seed=1) != (tr, va)
    assert split_scenes(["a", "b"], 0.1, seed=0)[1] != []
