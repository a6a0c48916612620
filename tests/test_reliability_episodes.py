"""Episode validation shared by `ovon dataset validate` and every reader; scene ids confined (items 4, 5)."""

from __future__ import annotations

import copy
import gzip
import json
import os
import shutil
import warnings
from pathlib import Path, PurePosixPath

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from ovon.cli.main import main as ovon
from ovon.dataset.episodes import load_specs
from ovon.dataset.io import EpisodeDataset, parse_shard, read_shard
from ovon.dataset.records import DatasetError, confined_scene_id
from ovon.dataset.validate import DatasetWarning, check_shard, validate_dataset
from ovon.evaluate.config import EvalConfig
from ovon.evaluate.harness import evaluate, prepare


def _shards(root: Path, split: str = "val_seen") -> list[Path]:
    return sorted((root / split / "content").glob("*.json.gz"))


def _load(p: Path) -> dict:
    return json.loads(gzip.decompress(p.read_bytes()))


def _save(p: Path, doc: dict) -> None:
    p.write_bytes(gzip.compress(json.dumps(doc).encode()))  # allow_nan: a file from elsewhere can hold NaN


@pytest.fixture
def data(tiny_dataset, tmp_path) -> Path:
    dst = tmp_path / "data"
    shutil.copytree(tiny_dataset, dst, ignore=shutil.ignore_patterns(".cache"))
    return dst


def _mutate(data: Path, fn, split: str = "val_seen") -> dict:
    p = _shards(data, split)[0]
    doc = _load(p)
    fn(doc)
    _save(p, doc)
    return doc


def _first_key(doc: dict) -> str:
    ep = doc["episodes"][0]
    return f"{Path(ep['scene_id']).name}_{ep['object_category']}"


CASES = {
    "duplicate_id": lambda d: d["episodes"][1].__setitem__("episode_id", d["episodes"][0]["episode_id"]),
    "info_number": lambda d: d["episodes"][0]["info"].__setitem__("geodesic_distance", float("nan")),
    "rotation": lambda d: d["episodes"][0].__setitem__("start_rotation", [0.0, 0.0, 0.0, 0.0]),
    "rotation_not_unit": lambda d: d["episodes"][0].__setitem__("start_rotation", [0.0, 0.5, 0.0, 0.5]),
    "rotation_not_yaw": lambda d: d["episodes"][0].__setitem__("start_rotation", [0.7071068, 0.0, 0.0, 0.7071068]),
    "empty_category": lambda d: d["episodes"][0].__setitem__("object_category", ""),
    "no_viewpoints": lambda d: [g.__setitem__("view_points", []) for g in d["goals_by_category"][_first_key(d)]],
    "start_not_navigable": lambda d: d["episodes"][0].__setitem__("start_position", [1000.0, 0.0, 1000.0]),
}
KIND = {"rotation_not_unit": "rotation", "rotation_not_yaw": "rotation", "start_not_navigable": "start_not_navigable"}


@pytest.mark.parametrize("case", sorted(CASES))
def test_validate_fails_and_readers_skip_with_a_counted_warning(data, tiny_scenes, case):
    _mutate(data, CASES[case])
    rep = validate_dataset(data, tiny_scenes, ["val_seen"])
    assert not rep.ok and rep.counts[KIND.get(case, case)] >= 1, rep.counts
    before = sum(len(_load(p)["episodes"]) for p in _shards(data))
    cfg = EvalConfig(agent="random", data=str(data), scenes=str(tiny_scenes), splits=("val_seen",))
    with pytest.warns(DatasetWarning, match=r"skipped \d+ of \d+ episodes that fail validation \(\d+ \w+"):
        specs = prepare(cfg)["val_seen"]
    assert 0 < len(specs) < before
    assert code_of(["dataset", "validate", str(data), "--scenes", str(tiny_scenes), "--split", "val_seen"]) == 1


def code_of(argv: list[str]) -> int:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return ovon(argv)


def test_non_finite_start_refuses_the_shard_naming_file_and_key(data, tiny_scenes):
    _mutate(data, lambda d: d["episodes"][3].__setitem__("start_position", [float("nan"), 0.0, 0.0]))
    with pytest.raises(DatasetError, match=r"content/.*\.json\.gz: episodes\[3\]\.start_position: expected 3 finite"):
        load_specs(str(data), str(tiny_scenes), "val_seen", None)


def test_empty_split_and_split_without_content_fail(data, tiny_scenes, capsys):
    for p in _shards(data, "val_unseen"):
        p.unlink()
    shutil.rmtree(data / "val_seen_synonyms" / "content")
    rep = validate_dataset(data, tiny_scenes)
    assert rep.counts["empty_split"] == 2
    assert any("no content/ folder" in e for e in rep.errors)
    for split, why in (("val_unseen", "holds no <scene>.json.gz shards"), ("val_seen_synonyms", "no content/ folder")):
        with pytest.raises(DatasetError, match=why):
            load_specs(str(data), str(tiny_scenes), split, None)
    _mutate(data, lambda d: d.__setitem__("episodes", []))
    for p in _shards(data)[1:]:
        p.unlink()
    assert validate_dataset(data, tiny_scenes, ["val_seen"]).counts["empty_split"] == 1


@pytest.mark.parametrize("scene_id", ["../../etc/passwd", "hm3d/../../../x.glb", "/etc/passwd", "..", "/"])
def test_scene_ids_cannot_leave_the_scenes_root(data, tiny_scenes, scene_id, capsys):
    _mutate(data, lambda d: [e.__setitem__("scene_id", scene_id) for e in d["episodes"]])
    with pytest.raises(DatasetError, match="scenes root"):
        load_specs(str(data), str(tiny_scenes), "val_seen", None)
    assert not validate_dataset(data, tiny_scenes, ["val_seen"]).ok
    rc = ovon(
        [
            "evaluate",
            "--agent",
            "random",
            "--data",
            str(data),
            "--scenes",
            str(tiny_scenes),
            "--splits",
            "val_seen",
            "--out",
            str(data.parent / "run"),
            "--no-progress",
        ]
    )
    err = capsys.readouterr().err.strip()
    assert rc == 2 and err.startswith("ovon: error:") and "scenes root" in err and len(err.splitlines()) == 1


def test_absolute_scene_ids_inside_the_root_still_load(data, tiny_scenes):
    doc = _load(_shards(data)[0])
    rel = doc["episodes"][0]["scene_id"].split("/", 1)[1]  # <split>/<folder>/<file> under the root
    _mutate(data, lambda d: [e.__setitem__("scene_id", str(tiny_scenes / rel)) for e in d["episodes"]])
    specs = load_specs(str(data), str(tiny_scenes), "val_seen", None)
    assert all(Path(s.scene).is_file() and str(tiny_scenes) in s.scene for s in specs)


@settings(max_examples=300, deadline=None)
@given(
    st.lists(
        st.sampled_from(
            ["..", ".", "a", "b.glb", "", "/", "//", "\\", "data", "scene_datasets", "~", "..a", "...", "a..", " "]
        ),
        max_size=8,
    ).map("/".join)
)
def test_fuzz_resolved_scene_paths_stay_inside_the_root(tmp_path_factory, scene_id):
    root = Path("/srv/scenes")
    try:
        rel = confined_scene_id(scene_id, root)
    except DatasetError:
        return
    assert not PurePosixPath(rel).is_absolute() and ".." not in PurePosixPath(rel).parts
    assert os.path.normpath(root / rel).startswith(str(root) + "/")


def test_evaluate_with_bad_episodes_runs_only_the_good_ones(data, tiny_scenes, tmp_path):
    _mutate(data, CASES["rotation"])
    cfg = EvalConfig(agent="random", data=str(data), scenes=str(tiny_scenes), splits=("val_seen",))
    with pytest.warns(DatasetWarning):
        s = evaluate(cfg, tmp_path / "run", progress=False)
    n = sum(len(_load(p)["episodes"]) for p in _shards(data))
    assert s["splits"]["val_seen"]["episodes"] == n - 1


# -- fuzz: any mutation of a shard is read or refused with a DatasetError; checks never raise ------------
JSON = st.recursive(
    st.none() | st.booleans() | st.integers(-(10**9), 10**9) | st.floats() | st.text(max_size=6),
    lambda c: st.lists(c, max_size=3) | st.dictionaries(st.text(max_size=4), c, max_size=3),
    max_leaves=6,
)


@settings(max_examples=250, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(where=st.integers(0, 10**6), value=JSON, drop=st.booleans())
def test_fuzz_episode_files(tiny_dataset, where, value, drop):
    p = _shards(tiny_dataset)[0]
    doc = copy.deepcopy(_FUZZ_DOC.setdefault(p, _load(p)))
    paths = list(_paths(doc))
    parent, key = paths[where % len(paths)]
    if drop and isinstance(parent, dict):
        parent.pop(key, None)
    else:
        parent[key] = value
    try:
        shard = parse_shard(json.loads(json.dumps(doc)))
    except DatasetError as e:
        assert "\n" not in str(e)
        return
    chk = check_shard(shard)  # never raises
    for i, ep in enumerate(shard.episodes):
        if not chk.bad(i):
            assert shard.goals_for(ep) is not None


_FUZZ_DOC: dict = {}


def _paths(node):
    if isinstance(node, dict):
        for k, v in node.items():
            yield node, k
            yield from _paths(v)
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield node, i
            yield from _paths(v)


def test_deeply_nested_or_garbage_shards_are_clear_errors(data):
    p = _shards(data)[0]
    p.write_bytes(gzip.compress(b"[" * 100000 + b"]" * 100000))
    with pytest.raises(DatasetError, match="nested too deeply"):
        read_shard(p)
    p.write_bytes(gzip.compress(b'{"episodes": [1, 2'))
    with pytest.raises(DatasetError, match="not valid JSON"):
        EpisodeDataset(data, "val_seen").load_scene(p.name[: -len(".json.gz")])
