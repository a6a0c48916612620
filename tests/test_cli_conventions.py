"""`ovon`'s command-line conventions: every option has help, `--help` shows defaults, `ovon --help` opens
with what the tool is for, `ovon --version`, "did you mean" for a mistyped command, one-line errors with no
Python reprs."""

from __future__ import annotations

import argparse
import subprocess
import sys
from importlib.metadata import version

import pytest

from ovon.cli.main import build_parser, main


def _parsers(parser: argparse.ArgumentParser, name: str = "ovon"):
    yield name, parser
    for action in parser._actions:  # noqa: SLF001
        if isinstance(action, argparse._SubParsersAction):  # noqa: SLF001
            for sub_name, sub in action.choices.items():
                yield from _parsers(sub, f"{name} {sub_name}")


def test_every_option_has_help():
    missing = [
        f"{name} {'/'.join(a.option_strings) or a.dest}"
        for name, parser in _parsers(build_parser())
        for a in parser._actions  # noqa: SLF001
        if not isinstance(a, argparse._SubParsersAction) and not (a.help or "").strip()  # noqa: SLF001
    ]
    assert not missing, f"options without help: {', '.join(missing)}"


def test_help_shows_defaults(capsys):
    with pytest.raises(SystemExit) as e:
        main(["train", "--help"])
    assert e.value.code == 0
    text = " ".join(capsys.readouterr().out.split())
    assert "(default: objectnav)" in text and "(default: cpu-small)" in text and "(default: train)" in text
    assert "(default: None)" not in text and "(default: False)" not in text


def test_top_level_help_is_for_users(capsys):
    with pytest.raises(SystemExit):
        main(["--help"])
    out = capsys.readouterr().out
    description = out.split("\n\n")[1]
    assert "HM3D-OVON" in description and "Entry point" not in out and "register(" not in out


def test_version(capsys):
    with pytest.raises(SystemExit) as e:
        main(["--version"])
    assert e.value.code == 0
    assert capsys.readouterr().out.strip() == f"ovon {version('ovon')}"


@pytest.mark.parametrize(
    ("argv", "expected"),
    [
        (["evalute"], "did you mean evaluate?"),
        (["dataset", "stat", "x"], "did you mean stats?"),
    ],
)
def test_did_you_mean(capsys, argv, expected):
    with pytest.raises(SystemExit) as e:
        main(argv)
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and expected in err and "'" not in err


def _run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "ovon.cli.main", *args], capture_output=True, text=True, timeout=120)


@pytest.mark.parametrize(
    ("args", "words"),
    [
        (("report", "runs/nope"), "RUNS runs/nope: does not exist"),
        (("curve", "runs/nope", "--out", "c.png"), "RUNS runs/nope: does not exist"),
    ],
)
def test_errors_have_no_python_reprs(tmp_path, args, words):
    res = _run(*args)
    assert res.returncode == 2
    line = res.stderr.strip()
    assert len(line.splitlines()) == 1 and words in line
    assert "(" + "'" not in line and "('" not in line and "Traceback" not in line


def test_data_error_names_what_was_given(tmp_path):
    res = _run(
        "evaluate",
        "--agent",
        "random",
        "--data",
        str(tmp_path / "nope"),
        "--scenes",
        str(tmp_path),
        "--out",
        str(tmp_path / "run"),
    )
    assert res.returncode == 2
    line = res.stderr.strip()
    assert len(line.splitlines()) == 1 and f"--data {tmp_path / 'nope'}: does not exist" in line
    assert "data/datasets/ovon" not in line and "'" not in line


@pytest.mark.parametrize("content", ["missing", "empty"])
def test_stats_refuses_a_shell_only_split(tmp_path, capsys, content):
    """The release's trap: `<split>/<split>.json.gz` holds only the categories; without content/ the
    split would count 0 episodes. `stats` refuses it with the line `verify` shows."""
    import shutil
    from pathlib import Path

    from ovon.dataset.io import EpisodeDataset
    from ovon.dataset.verify import shell_only

    root = tmp_path / "release"
    shutil.copytree(Path(__file__).parent / "fixtures" / "ovon_release", root)
    shutil.rmtree(root / "val_seen" / "content")
    if content == "empty":
        (root / "val_seen" / "content").mkdir()
    assert main(["dataset", "stats", str(root)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "val_seen is shell-only" in err and "fix:" in err
    assert shell_only(EpisodeDataset(root, "val_seen")) in err
    assert main(["dataset", "verify", str(root)]) == 1
    assert "shell-only" in capsys.readouterr().out


def test_stats_of_the_release_fixture_still_counts(capsys):
    from pathlib import Path

    assert main(["dataset", "stats", str(Path(__file__).parent / "fixtures" / "ovon_release")]) == 0
    assert "| val_seen | 1 | 2 |" in capsys.readouterr().out
