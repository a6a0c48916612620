"""ovon on habitat's own navmesh of the van-gogh-room test scene against habitat's own numbers (golden
data from habitat-sim and habitat-lab tests, tests/fixtures/habitat/README.md): area and islands,
the top-down map, geodesic distances and reachability, and the recorded agent trajectory with sliding.
The figures for the README come from benchmarks/navmesh_agreement.py, which uses the same functions."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch

from ovon.config.sim import NavConfig
from ovon.experts import ShortestPathExpert
from ovon.experts.gridsim import rollout
from ovon.sim.agent import STOP
from ovon.sim.geodesic import distance_field
from ovon.sim.navmesh import load_navmesh, read_navmesh
from ovon.sim.navmesh.agreement import (
    HABITAT_AGENT,
    geodesic_agreement,
    island_agreement,
    topdown_agreement,
    trajectory_agreement,
)
from ovon.sim.types import AgentState

torch.set_num_threads(1)
FIX = Path(__file__).resolve().parent / "fixtures" / "habitat"
NAVMESH = FIX / "van-gogh-room.navmesh"


def _json(name: str) -> dict:
    return json.loads((FIX / name).read_text())


@pytest.fixture(scope="module")
def nav():
    return load_navmesh(NAVMESH, HABITAT_AGENT)


def test_area_and_islands_are_habitats():
    gold = _json("habitat_sim_golden.json")["scenes"]["van-gogh-room"]
    res = island_agreement(read_navmesh(NAVMESH), gold)
    assert res["num_islands"] == gold["num_islands"] == 2
    # habitat accumulates in float32: agreement to its float precision
    assert res["area_rel_error"] < 1e-6
    assert res["island_area_max_rel_error"] < 1e-6 and res["island_radius_max_rel_error"] < 1e-6


def test_topdown_map(nav):
    res = topdown_agreement(read_navmesh(NAVMESH), nav, np.load(FIX / "van-gogh-room_topdown_binary.npy"))
    # the reader gives habitat's polygons: every differing pixel lies within habitat's 1 cm tolerance of an edge
    assert res["navmesh_point_test_mismatch_beyond_1cm"] == 0 and res["navmesh_point_test_agrees"] > 0.99
    assert res["grid_agrees"] > 0.98 and res["grid_iou"] > 0.94  # 5 cm cells vs 10 cm pixels


def test_geodesics_and_reachability():
    golden = _json("test-sim-geodesic-distance-test-golden.json")
    for cs, field_target in ((0.05, 0.01), (0.025, 0.005)):
        sn = load_navmesh(NAVMESH, HABITAT_AGENT, NavConfig(cell_size=cs))
        field = geodesic_agreement(sn, golden, "field")
        assert field["reachability_agrees"] == field["pairs"] == 20 and field["habitat_unreachable"] == 3
        assert field["mean_rel_error"] <= field_target, field
        path = geodesic_agreement(sn, golden, "path")
        assert path["reachability_agrees"] == 20 and path["mean_rel_error"] <= 0.002 and path["max_rel_error"] < 0.01


def test_sliding_trajectory():
    res = trajectory_agreement(load_navmesh(NAVMESH, HABITAT_AGENT), _json("habitat-sim_trajectory_data.json"))
    assert res["steps"] == 57
    # along the straight wall the agent slides as habitat's does (the wall 4 mm inside the cell border) ...
    assert max(res["errors_m"][:45]) < 0.01
    # ... and pushed into the 45-degree wall at the corner it stays within a cell of habitat's position
    assert res["max_xz_error_m"] < 0.05 and res["mean_xz_error_m"] < 0.02


def test_expert_drives_between_habitats_points(nav):
    golden = _json("test-sim-geodesic-distance-test-golden.json")
    for case in golden["single_end"]:
        if case["expected"] is None or not np.isfinite(case["expected"]) or case["expected"] < 1.0:
            continue
        start, end = np.array(case["start"]), np.array(case["end"])
        grid = nav.grid_for(start)
        states, actions, _ = rollout(ShortestPathExpert(), grid, AgentState(start, 0.0), [(end, 0.0)], 200)
        assert actions[-1] == STOP
        assert distance_field(grid, end[None]).distance(states[-1].position) < 0.25
