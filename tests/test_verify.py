"""`ovon dataset verify`: the released download's traps are notes, what evaluation cannot use is an error."""

from __future__ import annotations

import shutil

from ovon.dataset.io import read_shard
from ovon.dataset.records import resolve_scene_path
from ovon.dataset.verify import verify_dataset


def _download_with_traps(tiny_dataset, tmp_path):
    data = tmp_path / "objectnav_hm3d_v1"
    shutil.copytree(tiny_dataset, data)
    syn = data / "val_seen_synonyms"
    shell = syn / "val_seen_synonyms.json.gz"
    if shell.exists():
        shell.rename(syn / "val_unseen_easy.json.gz")  # the released folder/file name mix-up
    content = data / "val_seen" / "content"
    shard = sorted(content.iterdir())[0]
    (content / f"._{shard.name}").write_bytes(b"\x00\x05\x16\x07AppleDouble")
    (data / ".DS_Store").write_bytes(b"junk")
    return data


def test_traps_are_named_as_notes_and_the_download_is_usable(tiny_dataset, tiny_scenes, tmp_path):
    data = _download_with_traps(tiny_dataset, tmp_path)
    rep = verify_dataset(data, tiny_scenes)
    table = rep.table()
    assert rep.ok, table
    assert "junk files (ignored)" in table and "._" in table and ".DS_Store" in table
    assert rep.episodes["val_seen"] > 0 and set(rep.episodes) >= {"val_seen", "val_seen_synonyms", "val_unseen"}
    assert all(f.severity != "error" for f in rep.findings)


def test_what_evaluation_cannot_use_is_an_error(tiny_dataset, tiny_scenes, tmp_path):
    data = _download_with_traps(tiny_dataset, tmp_path)
    scenes = tmp_path / "scenes"
    shutil.copytree(tiny_scenes, scenes)
    shard = sorted((data / "val_seen" / "content").glob("[!.]*.json.gz"))[0]
    resolve_scene_path(read_shard(shard).episodes[0].scene_id, scenes).unlink()
    for shard in (data / "val_unseen" / "content").iterdir():
        shard.unlink()
    rep = verify_dataset(data, scenes)
    errors = {(f.split, f.what) for f in rep.findings if f.severity == "error"}
    assert not rep.ok
    assert ("val_unseen", "no usable episodes") in errors
    assert ("val_seen", "scenes missing") in errors, rep.table()
