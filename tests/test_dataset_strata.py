"""Start-distance strata of the val splits: every split holds the same number of episodes per geodesic bin, so
the splits differ in their goals, not in how far their starts are."""

from __future__ import annotations

import gzip
import json
from collections import Counter
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from ovon.config.base import ConfigError, validate
from ovon.config.dataset import StartConfig
from ovon.dataset.generate import deal_strata, generate, stratum_bounds
from ovon.dataset.io import VAL_SPLITS
from tests.conftest import tiny_generation_config

EDGES = (1.0, 2.5, 4.0, 30.0)


def test_episodes_are_dealt_evenly_over_the_bins() -> None:
    pairs = [("a", "bed"), ("a", "couch"), ("b", "couch"), ("b", "sink")]
    counts = {("a", "bed"): 3, ("a", "couch"): 2, ("b", "couch"): 4, ("b", "sink"): 1}
    dealt = deal_strata(counts, pairs, 4)
    assert [len(dealt[s][c]) for s, c in pairs] == [3, 2, 4, 1]
    per_bin = Counter(b for cats in dealt.values() for bins in cats.values() for b in bins)
    assert max(per_bin.values()) - min(per_bin.values()) <= 1 and sum(per_bin.values()) == 10
    assert deal_strata(counts, pairs, 0) == {}


def test_a_bin_falls_back_to_its_nearest_neighbours_within_the_start_limits() -> None:
    starts = StartConfig(min_geodesic=1.5, max_geodesic=20.0, val_strata_m=EDGES)
    got = stratum_bounds(starts, 0, 3)
    assert [j for j, _ in got] == [0, 1, 2]
    assert (got[0][1].min_geodesic, got[0][1].max_geodesic) == (1.5, 2.5)  # clipped to the start limits
    assert (got[2][1].min_geodesic, got[2][1].max_geodesic) == (4.0, 20.0)
    assert [j for j, _ in stratum_bounds(starts, 2, 3)] == [2, 1, 0]


@pytest.mark.parametrize("edges", [(3.0, 2.0), (1.0,)])
def test_bad_edges_are_refused(edges) -> None:
    with pytest.raises(ConfigError, match="val_strata_m"):
        validate(StartConfig(val_strata_m=edges), "starts")


def _distances(root: Path, split: str) -> np.ndarray:
    out = []
    for f in sorted((root / split / "content").glob("*.json.gz")):
        out += [e["info"]["geodesic_distance"] for e in json.loads(gzip.decompress(f.read_bytes()))["episodes"]]
    return np.array(out)


def test_generated_val_splits_share_their_strata(tiny_scenes, tmp_path) -> None:
    g = tiny_generation_config()
    cfg = replace(g, episodes_per_val_split=12, starts=replace(g.starts, val_strata_m=EDGES))
    report = generate(tiny_scenes, tmp_path / "eps", cfg, splits=VAL_SPLITS, workers=1, progress=False)
    moved = report.rejections.get("stratum_moved", 0)
    for split in VAL_SPLITS:
        d = _distances(tmp_path / "eps", split)
        if not len(d):
            continue
        per_bin = np.histogram(d, bins=EDGES)[0]
        # dealt evenly (+-1 per bin), except the episodes a house could not place in their own bin
        target = len(d) / (len(EDGES) - 1)
        assert np.abs(per_bin - target).sum() <= 2 * (len(EDGES) - 1) + 2 * moved, (split, per_bin, moved)
