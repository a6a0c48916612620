"""Canonical subsets: chosen by content (not order or folder), stratified by scene and goal category."""

from __future__ import annotations

import random
import shutil
from collections import Counter

import pytest

from ovon.dataset.subset import check_subset, choose, make_subset, named_subset, read_subset, write_subset


def _episodes() -> list[tuple[str, str, str]]:
    # 3 scenes of 40 / 20 / 10 episodes, categories 'a' (3/4) and 'b' (1/4) in each
    return [(f"hm3d/val/s{s}.glb", str(i), "a" if i % 4 else "b") for s, n in enumerate((40, 20, 10)) for i in range(n)]


def test_the_choice_ignores_order_and_is_proportional_per_scene_and_category():
    eps = _episodes()
    picked = choose("val_seen", eps, 14)
    shuffled = eps[:]
    random.Random(1).shuffle(shuffled)
    assert choose("val_seen", shuffled, 14) == picked
    assert len(picked) == len(set(picked)) == 14
    per_scene = Counter(scene for scene, _ in picked)
    assert per_scene == {"hm3d/val/s0.glb": 8, "hm3d/val/s1.glb": 4, "hm3d/val/s2.glb": 2}
    chosen = set(picked)
    cats = Counter(c for s, e, c in eps if (s, e) in chosen)
    assert cats == {"a": 10, "b": 4}  # per scene: 6+2, 3+1, 1+1 (largest remainders)
    assert set(choose("val_seen", eps, 1000)) == {(s, e) for s, e, _ in eps}
    assert choose("val_unseen", eps, 14) != picked  # the split is part of the rank


def test_a_subset_is_the_same_wherever_the_data_lives(tiny_dataset, tmp_path):
    a = make_subset(tiny_dataset, 5, "five")
    shutil.copytree(tiny_dataset, tmp_path / "elsewhere")
    b = make_subset(tmp_path / "elsewhere", 5, "five")
    assert a.splits == b.splits and a.ids_sha256 == b.ids_sha256
    assert all(len(refs) == 5 for refs in a.splits.values())
    write_subset(a, tmp_path / "five.json")
    assert read_subset(tmp_path / "five.json") == a
    assert named_subset(tiny_dataset, "mini", ["val_seen"]).size == 360


def test_bad_subsets_are_one_line(tiny_dataset, tmp_path):
    (tmp_path / "bad.json").write_text('{"name": "x"}')
    with pytest.raises(ValueError, match=r"bad.json: not a subset file .*fix: write it again") as e:
        read_subset(tmp_path / "bad.json")
    assert "\n" not in str(e.value)
    with pytest.raises(ValueError, match=r"subset 'nope' is not a named subset \(known: mini\)"):
        named_subset(tiny_dataset, "nope", ["val_seen"])
    sub = make_subset(tiny_dataset, 3, "three")
    with pytest.raises(ValueError, match=r"subset 'three': 3 episode\(s\) of val_seen are not in other data"):
        check_subset(sub, "val_seen", [], "other data")
    with pytest.raises(ValueError, match=r"--size 0: expected a positive number"):
        make_subset(tiny_dataset, 0)
