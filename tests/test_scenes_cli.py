"""`ovon scenes` commands end to end on a tiny generated dataset."""

from __future__ import annotations

from pathlib import Path

from ovon.cli.main import main
from ovon.cli.scenes import house_seed
from ovon.scenes.hm3dsem import list_scenes, load_scene

FIXTURE = Path(__file__).parent / "fixtures" / "hm3dsem" / "00001-FixtureScn01"


def test_house_seeds_deterministic_and_split_specific() -> None:
    assert house_seed(0, "train", 1) == house_seed(0, "train", 1)
    assert house_seed(0, "train", 1) != house_seed(0, "val", 1)
    assert house_seed(0, "train", 1) != house_seed(1, "train", 1)


def test_generate_inspect_render(tmp_path: Path, capsys) -> None:
    out = tmp_path / "data"
    assert main(["scenes", "generate", "--split", "val", "--count", "2", "--seed", "5", "--out", str(out),
                 "--workers", "1"]) == 0  # fmt: skip
    scenes = list_scenes(out, "val")
    assert len(scenes) == 2
    for folder in scenes:
        stem = folder.name.split("-", 1)[1]
        assert {p.name for p in folder.iterdir()} == {
            f"{stem}{s}" for s in (".glb", ".semantic.glb", ".semantic.txt", ".ovon.json")
        }
        assert load_scene(folder).objects
    mtimes = {p: p.stat().st_mtime_ns for p in out.rglob("*.glb")}
    capsys.readouterr()
    assert main(["scenes", "generate", "--split", "val", "--count", "2", "--seed", "5", "--out", str(out)]) == 0
    assert "2 skipped" in capsys.readouterr().out
    assert {p: p.stat().st_mtime_ns for p in out.rglob("*.glb")} == mtimes

    assert main(["scenes", "inspect", str(scenes[0])]) == 0
    text = capsys.readouterr().out
    assert scenes[0].name in text and "dropped by cleaning" in text

    png = tmp_path / "top.png"
    assert main(["scenes", "render-topdown", str(scenes[0]), "--out", str(png)]) == 0
    assert png.stat().st_size > 10_000


def test_inspect_and_render_fixture(tmp_path: Path, capsys) -> None:
    assert main(["scenes", "inspect", str(FIXTURE), "--json"]) == 0
    assert '"objects_dropped": 2' in capsys.readouterr().out
    png = tmp_path / "fx.png"
    assert main(["scenes", "render-topdown", str(FIXTURE), "--out", str(png), "--floor", "1"]) == 0
    assert png.is_file()


def test_cli_errors_are_clear(tmp_path: Path, capsys) -> None:
    assert main(["scenes", "inspect", str(tmp_path / "missing")]) == 2
    assert "missing" in capsys.readouterr().err


def test_vocabulary_command(capsys) -> None:
    assert main(["scenes", "vocabulary"]) == 0
    assert "categories" in capsys.readouterr().out
