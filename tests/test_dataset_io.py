"""Released-format reading, lossless/deterministic writing, corrupt-file errors, scene path resolution."""

from __future__ import annotations

import gzip
import json
import shutil
import warnings
from pathlib import Path

import pytest

from ovon.atomic import gzip_bytes, write_json_gz
from ovon.dataset import (
    DatasetError,
    Episode,
    EpisodeDataset,
    ObjectGoal,
    ViewPoint,
    category_from_key,
    goal_key,
    goals_for,
    read_shard,
    resolve_scene_path,
    scene_basename,
    shard_exists,
    write_scene_shard,
    write_split_shell,
)

FIXTURE = Path(__file__).parent / "fixtures" / "ovon_release"
SCENE = "TEEsavR23oF"


def _load_fixture() -> tuple[EpisodeDataset, object]:
    ds = EpisodeDataset(FIXTURE, "val_seen")
    with pytest.warns(UserWarning, match=r"\._TEEsavR23oF\.json\.gz"):
        scenes = ds.scenes()
    assert scenes == [SCENE]
    return ds, ds.load_scene(SCENE)


def test_release_fixture_loads_with_goals_reattached():
    ds, shard = _load_fixture()
    assert len(shard.episodes) == 2
    ep0, ep1 = shard.episodes
    assert ep0.scene_id == "hm3d/val/00800-TEEsavR23oF/TEEsavR23oF.basis.glb"
    assert ep0.goals == [] and ep0.start_room is None and ep0.shortest_paths is None
    assert set(shard.goals_by_category) == {
        "TEEsavR23oF.basis.glb_armchair",
        "TEEsavR23oF.basis.glb_couch",
        "TEEsavR23oF.basis.glb_sofa",
    }
    goals0 = shard.goals_for(ep0)
    assert [g.object_id for g in goals0] == ["armchair_57", "armchair_58"]
    assert [g.instance_id for g in goals0] == [57, 58]
    assert goals0[0].view_points[0] == ViewPoint([2.0, 0.1, -3.5], [0.0, 0.7071068, 0.0, 0.7071068], 0.41)
    assert goals0[0].extra["radius"] is None and "room_name" in goals0[0].extra
    # children count as goals
    goals1 = goals_for(ep1, shard.goals_by_category)
    assert [g.object_id for g in goals1] == ["couch_12", "sofa_9"]
    assert ep1.goal_categories == ["couch", "sofa"]
    # iteration does not need the shell to hold anything
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert [e.episode_id for e in ds.iter_episodes()] == ["0", "1"]


def test_keys_and_basenames():
    sid = "hm3d/val/00800-TEEsavR23oF/TEEsavR23oF.basis.glb"
    assert scene_basename(sid) == "TEEsavR23oF.basis.glb"
    assert goal_key(sid, "kitchen cabinet") == "TEEsavR23oF.basis.glb_kitchen cabinet"
    assert category_from_key("00800-TEEs_avR.basis.glb_kitchen_cabinet") == "kitchen_cabinet"
    with pytest.raises(ValueError, match="glb_"):
        category_from_key("nonsense")
    assert ObjectGoal("wall clock", "wall_clock_101", [0, 0, 0]).instance_id == 101


def test_round_trip_is_lossless_and_deterministic(tmp_path):
    _, shard = _load_fixture()
    # add keys we do not model: they must survive
    shard.episodes[0].extra["future_field"] = {"a": [1, 2]}
    shard.goals_by_category["TEEsavR23oF.basis.glb_couch"][0].extra["semantic_tag"] = "x"
    shard.extra["category_to_task_category_id"] = {"couch": 0}
    p = write_scene_shard(tmp_path, "val_seen", SCENE, shard.episodes, shard.goals_by_category, shard.extra)
    assert p == tmp_path / "val_seen" / "content" / f"{SCENE}.json.gz"
    assert shard_exists(tmp_path, "val_seen", SCENE) and not shard_exists(tmp_path, "val_seen", "other")
    back = read_shard(p)
    assert back.episodes == shard.episodes
    assert back.goals_by_category == shard.goals_by_category
    assert back.extra == shard.extra
    # the raw JSON matches the original document plus the added keys
    orig = json.loads(gzip.decompress((FIXTURE / "val_seen" / "content" / f"{SCENE}.json.gz").read_bytes()))
    new = json.loads(gzip.decompress(p.read_bytes()))
    orig["episodes"][0]["future_field"] = {"a": [1, 2]}
    orig["goals_by_category"]["TEEsavR23oF.basis.glb_couch"][0]["semantic_tag"] = "x"
    orig["category_to_task_category_id"] = {"couch": 0}
    assert new == orig
    # same records -> same bytes, whatever the goals dict order; no temp files left behind
    gbc_rev = dict(reversed(list(shard.goals_by_category.items())))
    q = write_scene_shard(tmp_path / "b", "val_seen", SCENE, shard.episodes, gbc_rev, shard.extra)
    assert q.read_bytes() == p.read_bytes()
    assert sorted(x.name for x in p.parent.iterdir()) == [f"{SCENE}.json.gz"]
    # gzip header: mtime 0, no file name
    assert p.read_bytes()[4:8] == b"\0\0\0\0" and p.read_bytes()[3] & 0x08 == 0
    assert gzip_bytes(b"abc") == gzip_bytes(b"abc")


def test_shell_with_top_level_maps_is_kept_not_required(tmp_path):
    write_split_shell(tmp_path, "val_unseen", {"category_to_task_category_id": {"toaster": 3}})
    ep = Episode("7", "hm3d/val/x/x.basis.glb", [0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0], "toaster")
    write_scene_shard(tmp_path, "val_unseen", "x", [ep], {goal_key(ep.scene_id, "toaster"): []})
    ds = EpisodeDataset(tmp_path, "val_unseen")
    assert ds.shell()["category_to_task_category_id"] == {"toaster": 3}
    assert [e.episode_id for e in ds.iter_episodes()] == ["7"]
    assert ds.load_scene("x").goals_for(ep) == []


@pytest.mark.parametrize(
    ("on_disk", "asked"),
    [
        ("val_seen_synonyms", "val_unseen_easy"),
        ("val_unseen_easy", "val_seen_synonyms"),
        ("val_unseen", "val_unseen_hard"),
        ("val_unseen_hard", "val_unseen"),
    ],
)
def test_split_aliases(tmp_path, on_disk, asked):
    ep = Episode("0", "hm3d/val/s/s.basis.glb", [0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0], "sofa")
    write_split_shell(tmp_path, on_disk)
    write_scene_shard(tmp_path, on_disk, "s", [ep], {goal_key(ep.scene_id, "sofa"): []})
    ds = EpisodeDataset(tmp_path, asked)
    assert ds.split_dir.name == on_disk
    assert ds.scenes() == ["s"] and ds.shell() == {"episodes": []}


def test_missing_split_names_what_was_tried(tmp_path):
    (tmp_path / "train").mkdir()
    with pytest.raises(FileNotFoundError, match=r"val_unseen_hard.*train"):
        EpisodeDataset(tmp_path, "val_unseen")


def _copy_fixture(tmp_path: Path) -> Path:
    dst = tmp_path / "rel"
    shutil.copytree(FIXTURE, dst)
    return dst / "val_seen" / "content" / f"{SCENE}.json.gz"


def _doc() -> dict:
    return json.loads(gzip.decompress((FIXTURE / "val_seen" / "content" / f"{SCENE}.json.gz").read_bytes()))


def test_corrupt_gzip_names_the_file(tmp_path):
    shard = _copy_fixture(tmp_path)
    shard.write_bytes(shard.read_bytes()[:40])  # truncated
    with pytest.raises(DatasetError, match=r"content/TEEsavR23oF\.json\.gz: not a readable gzip"):
        read_shard(shard)
    shard.write_bytes(b"not gzip at all")
    ds = EpisodeDataset(shard.parents[2], "val_seen")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with pytest.raises(DatasetError, match=r"TEEsavR23oF\.json\.gz"):
            ds.load_scene(SCENE)
    shard.write_bytes(gzip.compress(b"{not json"))
    with pytest.raises(DatasetError, match=r"TEEsavR23oF\.json\.gz: not valid JSON"):
        read_shard(shard)
    assert issubclass(DatasetError, ValueError)


@pytest.mark.parametrize(
    ("mutate", "message"),
    [
        (lambda d: d.pop("goals_by_category"), r"goals_by_category: missing key"),
        (lambda d: d.pop("episodes"), r"episodes: missing key"),
        (lambda d: d["episodes"][1].pop("scene_id"), r"episodes\[1\]\.scene_id: missing key"),
        (
            lambda d: d["episodes"][1].__setitem__("start_rotation", [0, 1, 0]),
            r"episodes\[1\]\.start_rotation: expected 4 numbers",
        ),
        (
            lambda d: d["episodes"][0].__setitem__("children_object_categories", "sofa"),
            r"episodes\[0\]\.children_object_categories: expected a list of strings",
        ),
        (
            lambda d: d["goals_by_category"]["TEEsavR23oF.basis.glb_armchair"][1]["view_points"][0].pop("iou"),
            r"goals_by_category\['TEEsavR23oF\.basis\.glb_armchair'\]\[1\]\.view_points\[0\]\.iou: missing key",
        ),
        (lambda d: d.__setitem__("episodes", {}), r"episodes: expected a list"),
    ],
)
def test_bad_records_name_file_and_key(tmp_path, mutate, message):
    doc = _doc()
    mutate(doc)
    path = tmp_path / "content" / "X.json.gz"
    write_json_gz(path, doc)
    with pytest.raises(DatasetError, match=r"content/X\.json\.gz: " + message):
        read_shard(path)


def test_resolve_scene_path(tmp_path):
    sid = "hm3d/val/00800-TEEsavR23oF/TEEsavR23oF.basis.glb"
    # nothing there: the error lists every tried path
    with pytest.raises(FileNotFoundError) as ei:
        resolve_scene_path(sid, tmp_path)
    msg = str(ei.value)
    for p in [
        tmp_path / "hm3d/val/00800-TEEsavR23oF/TEEsavR23oF.basis.glb",
        tmp_path / "hm3d/val/00800-TEEsavR23oF/TEEsavR23oF.glb",
        tmp_path / "val/00800-TEEsavR23oF/TEEsavR23oF.basis.glb",
        tmp_path / "val/00800-TEEsavR23oF/TEEsavR23oF.glb",
    ]:
        assert str(p) in msg
    # plain-glb release under the dataset folder itself (root = .../hm3d): .glb fallback + dropped prefix
    plain = tmp_path / "val/00800-TEEsavR23oF/TEEsavR23oF.glb"
    plain.parent.mkdir(parents=True)
    plain.write_bytes(b"glb")
    assert resolve_scene_path(sid, tmp_path) == plain
    assert resolve_scene_path("data/scene_datasets/" + sid, tmp_path) == plain
    # scene-datasets root with the basis file: preferred
    basis = tmp_path / "hm3d/val/00800-TEEsavR23oF/TEEsavR23oF.basis.glb"
    basis.parent.mkdir(parents=True)
    basis.write_bytes(b"glb")
    assert resolve_scene_path("./data/scene_datasets/" + sid, tmp_path) == basis
    assert resolve_scene_path(sid, tmp_path) == basis


def test_failed_write_leaves_nothing(tmp_path):
    ep = Episode(
        "0", "s.basis.glb", [0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0], "sofa", info={"geodesic_distance": float("nan")}
    )
    with pytest.raises(ValueError):
        write_scene_shard(tmp_path, "train", "s", [ep], {})
    assert not shard_exists(tmp_path, "train", "s")
    assert [p for p in tmp_path.rglob("*") if p.is_file()] == []


def test_interrupted_atomic_write_keeps_old_file(tmp_path, monkeypatch):
    from ovon import atomic

    target = tmp_path / "a.json.gz"
    write_json_gz(target, {"episodes": []})
    before = target.read_bytes()

    def boom(src, dst):
        raise KeyboardInterrupt

    monkeypatch.setattr(atomic.os, "replace", boom)
    with pytest.raises(KeyboardInterrupt):
        write_json_gz(target, {"episodes": [1]})
    assert target.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["a.json.gz"]
