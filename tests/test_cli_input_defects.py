"""Bad command lines found by the input audit (D4, D10, D11, D12, D15): each is one `ovon: error:` line
naming the option, the value and the fix, before any work, and nothing already written is touched."""

from __future__ import annotations

import argparse
import errno
import json
import os
import shutil
from pathlib import Path

import pytest

from ovon.cli.main import _run
from tests.cli_errors import one_line, run

FIXTURE_SCENE = Path(__file__).parent / "fixtures" / "hm3dsem" / "00001-FixtureScn01"
DEFS = Path(__file__).resolve().parents[1] / "ovon" / "experiments" / "defs"


@pytest.fixture
def a_file(tmp_path: Path) -> Path:
    f = tmp_path / "f"
    f.write_text("x")
    return f


@pytest.fixture
def fake_run(tmp_path: Path) -> Path:
    """A folder that passes the commands' "existing folder" checks; reading it as a run would fail."""
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    return run_dir


# -- D4: train --episodes has evaluate's domain ---------------------------------------------------------
@pytest.mark.parametrize("episodes", ["-1", "0", "abc"])
def test_train_episodes_outside_its_domain_is_one_line(tmp_path, capsys, episodes):
    out = tmp_path / "r"
    rc, _, errors = run(
        [
            "train",
            "--algo",
            "bc",
            "--preset",
            "tiny",
            "--data",
            str(tmp_path / "eps"),
            "--scenes",
            str(tmp_path),
            "--episodes",
            episodes,
            "--out",
            str(out),
        ],
        capsys,
    )
    one_line(rc, errors, "--episodes", repr(int(episodes)) if episodes != "abc" else "'abc'", "integer > 0")
    assert not out.exists()


# -- D10: an output path under an existing file ---------------------------------------------------------
def _under_file_cases(f: Path, run_dir: Path) -> list[list[str]]:
    return [
        [
            "sim",
            "view",
            "procedural:3",
            "--pose",
            "1,0,1,0",
            "--width",
            "40",
            "--height",
            "30",
            "--out",
            str(f / "x.png"),
        ],
        ["scenes", "render-topdown", str(FIXTURE_SCENE), "--out", str(f / "x.png")],
        ["scenes", "generate", "--split", "val", "--count", "1", "--out", str(f / "s")],
        ["dataset", "splits", "--vocabulary", "--out", str(f / "c.json")],
        ["dataset", "generate", "--scenes", str(FIXTURE_SCENE.parent), "--out", str(f / "d"), "--no-progress"],
        ["report", str(run_dir), "--out", str(f)],
        ["report", str(run_dir), "--out", str(f / "rep")],
        [
            "video",
            "--run",
            str(run_dir),
            "--episode",
            "0",
            "--split",
            "val_seen",
            "--seed",
            "0",
            "--out",
            str(f / "v.mp4"),
        ],
        ["curve", str(run_dir), "--out", str(f / "c.png")],
        ["train", "--algo", "bc", "--preset", "tiny", "--out", str(f / "t")],
        ["experiment", "run", "noise", "--scale", "tiny", "--root", str(f / "r"), "--dry-run"],
    ]


@pytest.mark.parametrize("case", range(11))
def test_output_under_an_existing_file_is_one_line_before_any_work(a_file, fake_run, capsys, case):
    argv = _under_file_cases(a_file, fake_run)[case]
    rc, out, errors = run(argv, capsys)
    line = one_line(rc, errors, str(a_file), "existing file, not a folder")
    assert "FileExistsError" not in line and "NotADirectoryError" not in line
    assert a_file.read_text() == "x"
    assert "wrote" not in out and "video:" not in out and "report:" not in out


def test_video_out_without_a_video_suffix_is_refused_before_the_replay(fake_run, tmp_path, capsys):
    rc, _, errors = run(["video", "--run", str(fake_run), "--episode", "0", "--out", str(tmp_path / "v")], capsys)
    one_line(rc, errors, "--out", ".mp4")


def _raising(exc: BaseException) -> argparse.Namespace:
    def func(args: argparse.Namespace) -> int:
        raise exc

    return argparse.Namespace(func=func)


def test_os_errors_naming_a_path_are_one_line_naming_it(a_file, tmp_path, capsys, monkeypatch):
    """Whatever still raises late (a library writer, a path made inside a command) is the user's path,
    not a bug: one line naming it, and the file in the way when there is one."""
    monkeypatch.delenv("OVON_DEBUG", raising=False)
    cases = [
        (FileExistsError(errno.EEXIST, "File exists", str(a_file)), [str(a_file), "existing file, not a folder"]),
        (
            NotADirectoryError(errno.ENOTDIR, "Not a directory", str(a_file / "x.png")),
            [f"{a_file / 'x.png'}: {a_file} is an existing file"],
        ),
        (OSError(errno.EROFS, "Read-only file system", str(tmp_path / "ro")), [str(tmp_path / "ro"), "Read-only"]),
        (OSError(errno.ENOSPC, "No space left on device"), ["No space left", "free disk space"]),
    ]
    for exc, needles in cases:
        rc = _run(_raising(exc))
        _, err = capsys.readouterr()
        lines = err.strip().splitlines()
        assert rc == 2 and len(lines) == 1 and lines[0].startswith("ovon: error:"), err
        assert "fix:" in lines[0]
        for n in needles:
            assert n in lines[0], (n, lines[0])
    rc = _run(_raising(OSError(errno.ECONNRESET, "reset")))  # no path: still a bug, still one line
    assert rc == 3 and "internal error" in capsys.readouterr().err


def test_memory_error_honours_ovon_debug(monkeypatch, capsys):
    monkeypatch.delenv("OVON_DEBUG", raising=False)
    assert _run(_raising(MemoryError())) == 2
    assert "out of memory" in capsys.readouterr().err
    monkeypatch.setenv("OVON_DEBUG", "1")
    with pytest.raises(MemoryError):
        _run(_raising(MemoryError()))


# -- D11: an empty --out / --root -----------------------------------------------------------------------
EMPTY_OUT_CASES = [
    ["evaluate", "--agent", "random", "--data", "{d}", "--scenes", "{d}", "--out", ""],
    ["dataset", "generate", "--scenes", str(FIXTURE_SCENE.parent), "--out", "", "--no-progress"],
    ["scenes", "generate", "--split", "val", "--count", "0", "--out", ""],
    ["train", "--algo", "bc", "--preset", "tiny", "--out", ""],
    ["report", "{d}", "--out", ""],
    ["experiment", "run", "noise", "--scale", "tiny", "--root", "", "--dry-run"],
    ["experiment", "run", "noise", "--scale", "tiny", "--root", "  ", "--dry-run"],
]


@pytest.mark.parametrize("argv", EMPTY_OUT_CASES, ids=[" ".join(c[:2]) + str(i) for i, c in enumerate(EMPTY_OUT_CASES)])
def test_empty_output_path_is_refused_and_the_current_folder_untouched(tmp_path, capsys, monkeypatch, argv):
    cwd = tmp_path / "cwd"
    cwd.mkdir()
    d = tmp_path / "d"
    d.mkdir()
    monkeypatch.chdir(cwd)
    rc, out, errors = run([a.replace("{d}", str(d)) for a in argv], capsys)
    flag = "--root" if "--root" in argv else "--out"
    one_line(rc, errors, flag, "empty")
    assert list(cwd.iterdir()) == [] and "root ." not in out


def test_run_folder_refuses_an_empty_path(tmp_path, monkeypatch):
    from ovon.runfolder import RunFolder, RunFolderError

    monkeypatch.chdir(tmp_path)
    with pytest.raises(RunFolderError, match="--out is empty"):
        RunFolder.open("", "evaluate", {})
    assert list(tmp_path.iterdir()) == []


# -- D12: an experiment run naming no experiment ----------------------------------------------------------
@pytest.mark.parametrize("name", ["", ",", " , "])
def test_experiment_run_without_a_name_is_refused(tmp_path, capsys, name):
    rc, out, errors = run(
        ["experiment", "run", name, "--scale", "tiny", "--root", str(tmp_path / "R"), "--dry-run"], capsys
    )
    one_line(rc, errors, "names no experiment", "main")
    assert "data:data" not in out and not (tmp_path / "R").exists()


# -- D15: experiment messages that named the wrong thing ------------------------------------------------------
def test_experiment_root_that_is_a_file_is_named_as_such(a_file, capsys):
    rc, _, errors = run(["experiment", "run", "noise", "--scale", "tiny", "--root", str(a_file), "--dry-run"], capsys)
    line = one_line(rc, errors, "--root", str(a_file), "existing file, not a folder")
    assert "unreadable" not in line and "changed" not in line
    assert a_file.read_text() == "x"


def test_cell_status_under_a_root_that_is_a_file_names_the_root(a_file):
    from ovon.experiments import DefinitionError, load_experiment, plan_status, resolve

    plan = resolve([load_experiment("noise")], "tiny", a_file)
    with pytest.raises(DefinitionError, match="--root .* is an existing file, not a folder"):
        plan_status(plan)


def test_unknown_redo_cell_names_redo(tmp_path, capsys):
    rc, _, errors = run(
        [
            "experiment",
            "run",
            "noise",
            "--scale",
            "tiny",
            "--root",
            str(tmp_path / "R"),
            "--redo",
            "nosuch",
            "--dry-run",
        ],
        capsys,
    )
    line = one_line(rc, errors, "--redo: no cell 'nosuch'")
    assert "--only" not in line


def test_a_definition_file_value_is_fixed_in_the_file_not_with_set(tmp_path, capsys):
    bad = tmp_path / "badkind.yaml"
    bad.write_text((DEFS / "noise.yaml").read_text().replace("kind: smaller_drop", "kind: bogus"))
    rc, _, errors = run(
        ["experiment", "run", str(bad), "--scale", "tiny", "--root", str(tmp_path / "R"), "--dry-run"], capsys
    )
    line = one_line(rc, errors, "'bogus'", f"fix: edit {bad} at findings[0].checks[0].kind")
    assert "--set" not in line and line.count("fix:") == 1


def test_a_set_value_is_fixed_with_set_as_typed(tmp_path, capsys):
    rc, _, errors = run(
        [
            "experiment",
            "run",
            "noise",
            "--scale",
            "tiny",
            "--root",
            str(tmp_path / "R"),
            "--set",
            "evaluate.seeds=abc",
            "--dry-run",
        ],
        capsys,
    )
    line = one_line(rc, errors, "evaluate.seeds = 'abc'", "fix: --set evaluate.seeds=VALUE")
    assert "--set --set" not in line and "--set." not in line


def test_a_folder_given_as_a_yaml_file_is_named_a_folder(tmp_path, capsys):
    folder = tmp_path / "exp.yaml"
    folder.mkdir()
    rc, _, errors = run(
        ["experiment", "run", str(folder), "--scale", "tiny", "--root", str(tmp_path / "R"), "--dry-run"], capsys
    )
    assert "does not exist" not in one_line(rc, errors, str(folder), "is a folder")
    rc, _, errors = run(
        ["train", "--algo", "bc", "--preset", "tiny", "--config", str(folder), "--out", str(tmp_path / "t")], capsys
    )
    assert "does not exist" not in one_line(rc, errors, "--config", "is a folder")
    assert not (tmp_path / "t").exists()


def test_video_from_another_folder_finds_the_runs_relative_inputs(
    tiny_dataset, tiny_scenes, tmp_path, capsys, monkeypatch
):
    """run.json keeps --data / --scenes as typed (relative to where `ovon evaluate` ran); `ovon video` run
    elsewhere takes them from run_identity.json (absolute) instead of failing with "does not exist"."""
    where = tmp_path / "project"
    (where / "data").mkdir(parents=True)
    shutil.copytree(tiny_dataset, where / "data" / "eps")
    os.symlink(tiny_scenes, where / "data" / "scenes")
    monkeypatch.chdir(where)
    run_dir = tmp_path / "run"
    rc, _, errors = run(
        [
            "evaluate",
            "--agent",
            "random",
            "--data",
            "data/eps",
            "--scenes",
            "data/scenes",
            "--splits",
            "val_seen",
            "--episodes",
            "1",
            "--workers",
            "1",
            "--out",
            str(run_dir),
            "--no-progress",
        ],
        capsys,
    )
    assert rc == 0, errors
    assert json.loads((run_dir / "run.json").read_text())["data"] == "data/eps"
    episode = json.loads((run_dir / "episodes.jsonl").read_text().splitlines()[0])["episode_id"]
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    video = [
        "video",
        "--run",
        str(run_dir),
        "--episode",
        str(episode),
        "--split",
        "val_seen",
        "--seed",
        "0",
        "--no-agent-view",
        "--out",
        "v.mp4",
    ]
    rc, out, errors = run(video, capsys)
    assert rc == 0 and errors == [], errors
    assert (elsewhere / "v.mp4").stat().st_size > 0
    # moved away: one line naming the recorded path, not "data/eps does not exist"
    shutil.move(str(where / "data" / "eps"), str(tmp_path / "moved"))
    rc, _, errors = run([*video[:-1], "v2.mp4"], capsys)
    one_line(rc, errors, "data 'data/eps'", str(where / "data" / "eps"), "relative to the folder it ran in")
    assert not (elsewhere / "v2.mp4").exists()
    # ... and `--data NEW` (as the error's fix says) renders it from where it went
    # a whole project moved (the recorded absolute path gone): its relative path from the new root works
    shutil.copytree(tmp_path / "moved", elsewhere / "data" / "eps")
    rc, out, errors = run([*video[:-1], "v5.mp4"], capsys)
    assert rc == 0 and errors == [], errors
    shutil.rmtree(elsewhere / "data")
    rc, out, errors = run([*video[:-1], "v3.mp4", "--data", str(tmp_path / "moved")], capsys)
    assert rc == 0 and errors == [], errors
    assert (elsewhere / "v3.mp4").stat().st_size > 0
    rc, _, errors = run([*video[:-1], "v4.mp4", "--scenes", str(tmp_path / "nowhere")], capsys)
    one_line(rc, errors, "--scenes", "nowhere")


def test_noise_twice_stop_probability_and_negative_house_seed_are_refused():
    from ovon.agents.random_agent import RandomAgent
    from ovon.config.base import ConfigError
    from ovon.evaluate.config import parse_noise
    from ovon.sim.world import load_scene_any

    with pytest.raises(ConfigError, match="actuation noise given twice"):
        parse_noise("actuation:ilqr,actuation:movebase")
    for p in (2, -0.1, float("nan")):
        with pytest.raises(ValueError, match="a probability in"):
            RandomAgent(stop_probability=p)
    with pytest.raises(ValueError, match="seed must be >= 0"):
        load_scene_any("procedural:-1")


def test_a_torn_split_file_is_named_even_when_shards_hold_the_episodes(tiny_dataset, tmp_path):
    from ovon.dataset.io import DatasetError, EpisodeDataset
    from ovon.dataset.validate import split_problem

    data = tmp_path / "data"
    shutil.copytree(tiny_dataset, data)
    shell = data / "val_seen" / "val_seen.json.gz"
    assert shell.is_file()
    shell.write_bytes(b"garbage")
    with pytest.raises(DatasetError, match="val_seen.json.gz"):
        split_problem(EpisodeDataset(data, "val_seen"))
