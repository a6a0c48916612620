"""Bad input to `dataset generate --categories`, `dataset splits`, `demo`, `sim bench`, `sim view --up`,
`scenes generate`, and the permissions of atomic writes (audit defects 15-18 and the minor ones): each is
one `ovon: error:` line naming the option or file, the value and the fix, before any work."""

from __future__ import annotations

import json
import os
import re
import stat
import time
from pathlib import Path

import numpy as np
import pytest

from ovon.dataset.records import DatasetError
from ovon.dataset.splits import (
    CategorySplit,
    HeldOutCategory,
    check_category_split,
    empty_held_out_problem,
    load_category_split,
)
from tests.cli_errors import one_line, run

OVON_SRC = Path(__file__).resolve().parents[1] / "ovon"


# -- 15: categories.json contents ----------------------------------------------------------------------
def _held(names: list[str], near: str) -> list[HeldOutCategory]:
    return [HeldOutCategory(c, 0.5, near) for c in names]


@pytest.fixture(scope="module")
def scene_split(tiny_scenes) -> dict:
    """A valid categories.json document for the tiny scenes: every list has categories of the val scenes."""
    from ovon.dataset.generate import discover_scenes, scene_categories

    refs = discover_scenes(tiny_scenes)
    val = sorted(set().union(*(scene_categories(r) for r in refs if r.kind == "val")))
    train_only = sorted(set().union(*(scene_categories(r) for r in refs if r.kind == "train")) - set(val))
    assert len(val) >= 6
    split = CategorySplit(
        train=val[:-4] + train_only, val_seen_synonyms=_held(val[-4:-2], val[0]), val_unseen=_held(val[-2:], val[0])
    )
    return split.to_json()


def _write(tmp_path: Path, doc: dict, name: str = "categories.json") -> Path:
    path = tmp_path / name
    path.write_text(json.dumps(doc))
    return path


def test_a_valid_category_split_passes_the_checks(scene_split, tmp_path):
    split = load_category_split(
        _write(tmp_path, scene_split), splits=("train", "val_seen", "val_seen_synonyms", "val_unseen")
    )
    assert split.to_json() == scene_split


@pytest.mark.parametrize(
    "case,needles",
    [
        ("train_in_unseen", ["val_unseen lists 3 train categories", "disjoint from train"]),
        ("train_in_synonyms", ["val_seen_synonyms lists 1 train category", "disjoint from train"]),
        ("unseen_in_synonyms", ["val_unseen lists 1 val_seen_synonyms category", "disjoint"]),
        ("unknown", ["val_unseen names 1 category that is not in the vocabulary", "'unicorn'"]),
        ("unknown_train", ["train names 1 category", "'unicorn'"]),
        ("empty_train", ["train is empty"]),
        ("twice", ["train lists", "more than once"]),
    ],
)
def test_category_split_files_breaking_the_split_rules_are_refused(scene_split, tmp_path, case, needles):
    doc = json.loads(json.dumps(scene_split))
    if case == "train_in_unseen":  # the audit's case: train categories copied into val_unseen
        doc["val_unseen"] += [
            {"category": c, "max_similarity": 1.0, "nearest_train_category": c} for c in doc["train"][:3]
        ]
    elif case == "train_in_synonyms":
        doc["val_seen_synonyms"].append(
            {"category": doc["train"][0], "max_similarity": 1.0, "nearest_train_category": doc["train"][0]}
        )
    elif case == "unseen_in_synonyms":
        doc["val_unseen"].append(dict(doc["val_seen_synonyms"][0]))
    elif case == "unknown":
        doc["val_unseen"] = [{"category": "unicorn", "max_similarity": 0.3, "nearest_train_category": "bed"}]
    elif case == "unknown_train":
        doc["train"].append("unicorn")
    elif case == "empty_train":
        doc["train"] = []
    elif case == "twice":
        doc["train"].append(doc["train"][0])
    path = _write(tmp_path, doc)
    with pytest.raises(DatasetError) as e:
        load_category_split(path)
    msg = str(e.value)
    assert msg.startswith(str(path)) and "\n" not in msg and "fix:" in msg, msg
    for n in needles:
        assert n in msg, (n, msg)


def test_an_empty_list_is_refused_only_for_the_splits_generated(scene_split):
    split = CategorySplit.from_json({**scene_split, "val_unseen": []})
    check_category_split(split, "c.json", splits=("val_seen", "val_seen_synonyms"))  # val_unseen not generated
    with pytest.raises(DatasetError, match=r"c\.json: val_unseen is empty"):
        check_category_split(split, "c.json", splits=("val_unseen",))
    with pytest.raises(DatasetError, match=r"c\.json: val_unseen is empty"):
        check_category_split(split, "c.json", splits=("val_unseen_hard",))  # the upstream name


@pytest.mark.parametrize(
    "case,needles",
    [
        ("copied", ["val_unseen lists 3 train categories"]),
        ("unicorn", ["'unicorn'", "not in the vocabulary"]),
        ("empty_unseen", ["val_unseen is empty"]),
        ("empty_train", ["train is empty"]),
        ("absent", ["none of its 1 val_unseen categories", "annotated in a val scene"]),
    ],
)
def test_dataset_generate_refuses_a_bad_categories_file_before_any_work(
    scene_split, tiny_scenes, tmp_path, capsys, case, needles
):
    from ovon.dataset.generate import discover_scenes, scene_categories
    from ovon.scenes.vocabulary import load_vocabulary

    doc = json.loads(json.dumps(scene_split))
    if case == "copied":
        doc["val_unseen"] += [
            {"category": c, "max_similarity": 1.0, "nearest_train_category": c} for c in doc["train"][:3]
        ]
    elif case == "unicorn":
        doc["val_unseen"] = [{"category": "unicorn", "max_similarity": 0.3, "nearest_train_category": "bed"}]
    elif case == "empty_unseen":
        doc["val_unseen"] = []
    elif case == "empty_train":
        doc["train"] = []
    else:  # a vocabulary category that no val scene has: the file was made for other scenes
        annotated = set().union(*(scene_categories(r) for r in discover_scenes(tiny_scenes)))
        listed = set(doc["train"]) | {h["category"] for h in doc["val_seen_synonyms"]}
        other = next(c for c in load_vocabulary().names if c not in annotated and c not in listed)
        doc["val_unseen"] = [{"category": other, "max_similarity": 0.3, "nearest_train_category": doc["train"][0]}]
    cats = _write(tmp_path, doc)
    out = tmp_path / "episodes"
    t0 = time.perf_counter()
    rc, _, errors = run(
        [
            "dataset",
            "generate",
            "--scenes",
            str(tiny_scenes),
            "--out",
            str(out),
            "--categories",
            str(cats),
            "--split",
            "val_unseen",
            "--no-progress",
        ],
        capsys,
    )
    one_line(rc, errors, str(cats), *needles)
    assert "repair those scenes" not in errors[0]
    assert time.perf_counter() - t0 < 10 and not out.exists()


def test_dataset_generate_checks_a_categories_file_left_in_the_output(scene_split, tiny_scenes, tmp_path, capsys):
    out = tmp_path / "episodes"
    out.mkdir()
    _write(
        out,
        {
            **scene_split,
            "val_unseen": [{"category": "unicorn", "max_similarity": 0.3, "nearest_train_category": "bed"}],
        },
    )
    rc, _, errors = run(
        [
            "dataset",
            "generate",
            "--scenes",
            str(tiny_scenes),
            "--out",
            str(out),
            "--split",
            "val_unseen",
            "--no-progress",
        ],
        capsys,
    )
    one_line(rc, errors, str(out / "categories.json"), "'unicorn'")
    assert sorted(p.name for p in out.iterdir()) == ["categories.json"]


class _SameEncoder:
    """Every name embedded alike but for a little seeded noise: every similarity is close to 1."""

    def encode(self, names: list[str]) -> np.ndarray:
        rng = np.random.default_rng(len(names))
        e = np.ones((len(names), 8)) + 0.05 * rng.standard_normal((len(names), 8))
        return (e / np.linalg.norm(e, axis=1, keepdims=True)).astype(np.float32)


@pytest.mark.parametrize(
    "argv,needles",
    [
        (["--threshold", "-0.5"], ["--threshold = -0.5", "(0, 1)"]),
        (["--threshold", "0"], ["--threshold = 0.0", "(0, 1)"]),
        (["--threshold", "1"], ["--threshold = 1.0", "(0, 1)"]),
        (["--threshold", "0.1"], ["--threshold 0.1 puts all", "val_unseen would be empty", "e.g. --threshold"]),
        (["--holdout", "0.0001"], ["--holdout 0.0001 holds out 0 of the", "at least 2"]),
        (["--holdout", "0.002"], ["--holdout 0.002 holds out 1 of the", "at least 2"]),
    ],
)
def test_dataset_splits_refuses_a_split_with_an_empty_held_out_list(tmp_path, capsys, monkeypatch, argv, needles):
    import ovon.models.text_minilm as text_minilm

    monkeypatch.setattr(text_minilm, "default_text_encoder", _SameEncoder)  # the split rule, not MiniLM
    out = tmp_path / "categories.json"
    rc, _, errors = run(["dataset", "splits", "--vocabulary", *argv, "--out", str(out)], capsys)
    one_line(rc, errors, *needles)
    assert not out.exists()


def test_empty_held_out_problem_names_the_threshold_and_a_value_that_works():
    split = CategorySplit(["bed", "chair"], _held(["couch", "sofa"], "bed"), [], threshold=0.3)
    split.val_seen_synonyms[0] = HeldOutCategory("couch", 0.6, "bed")
    msg = empty_held_out_problem(split, 4)
    assert msg and "--threshold 0.3" in msg and "val_unseen would be empty" in msg
    good = float(re.search(r"e\.g\. --threshold ([0-9.]+)", msg).group(1))
    assert 0.5 < good <= 0.6  # between the held-out similarities: both lists get a category
    assert empty_held_out_problem(CategorySplit(["bed"], _held(["sofa"], "bed"), _held(["toaster"], "bed")), 3) is None


# -- 16: `ovon demo` checks every option first --------------------------------------------------------
@pytest.mark.parametrize(
    "argv,needle",
    [
        (["--seeds", "-1"], "--seeds"),
        (["--seeds", "0,0"], "--seeds"),
        (["--seeds", "x"], "--seeds"),
        (["--seeds", ""], "--seeds"),
        (["--workers", "0"], "--workers"),
        (["--episodes", "0"], "--episodes"),
        (["--episodes", "-2"], "--episodes"),
        (["--episodes", "x"], "--episodes"),
        (["--train-scenes", "-1"], "--train-scenes"),
        (["--val-scenes", "0"], "--val-scenes"),
        (["--val-scenes", "100000000"], "--val-scenes"),
    ],
)
def test_demo_refuses_bad_options_before_any_work(tmp_path, capsys, monkeypatch, argv, needle):
    import ovon.cli.main as cli_main

    calls: list[list[str]] = []

    def spy(args=None):  # a sub-command started by the demo (its first is `scenes generate`): stop there
        calls.append(list(args or []))
        return 1

    monkeypatch.setattr(cli_main, "main", spy)
    root = tmp_path / "demo"
    t0 = time.perf_counter()
    rc, _, errors = run(["demo", "--root", str(root), *argv], capsys)
    one_line(rc, errors, needle)
    assert time.perf_counter() - t0 < 10 and not root.exists() and not calls


def test_demo_refuses_a_root_under_a_file(tmp_path, capsys):
    (tmp_path / "f").write_text("x")
    rc, _, errors = run(["demo", "--root", str(tmp_path / "f" / "demo")], capsys)
    one_line(rc, errors, "--root")


# -- 17: `ovon sim bench` names the option that is wrong ---------------------------------------------
@pytest.mark.parametrize(
    "argv,needle,blamed",
    [
        (["--envs-per-worker", "0"], "--envs-per-worker = 0", "--workers"),
        (["--seed", "-3"], "--seed = -3", "non-negative integer"),
        (["--goal", ""], "--goal = ''", None),
        (["--goal", "  "], "--goal", None),
        (["--workers", "-1"], "--workers = -1", None),
        (["--steps", "0"], "--steps = 0", None),
        (["--scene", ""], "--scene", None),
    ],
)
def test_sim_bench_options_are_refused_naming_the_option(capsys, monkeypatch, argv, needle, blamed):
    import ovon.env.bench as bench

    def no_work(*a, **k):
        raise AssertionError("the bench started although an option is bad")

    monkeypatch.setattr(bench, "pick_goal", no_work)
    monkeypatch.setattr(bench, "measure_throughput", no_work)
    rc, _, errors = run(["sim", "bench", *argv], capsys)
    msg = one_line(rc, errors, needle)
    if blamed:
        assert blamed not in msg, msg


# -- minor: --up ------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "up,needle",
    [
        ("q", "--up 'q': expected one of"),
        ("0,0,0", "not all zero"),
        ("nan,0,1", "finite"),
        ("", "--up '' is empty"),
        ("z", "procedural houses"),
    ],
)
def test_sim_view_up_is_checked_for_a_procedural_house(tmp_path, capsys, up, needle):
    out = tmp_path / "v.png"
    rc, _, errors = run(
        ["sim", "view", "procedural:0", "--up", up, "--width", "40", "--height", "30", "--out", str(out)], capsys
    )
    one_line(rc, errors, needle)
    assert not out.exists()


@pytest.mark.parametrize("command", ["inspect", "render-topdown"])
def test_a_zero_up_vector_is_named_as_such_for_a_scene(tmp_path, capsys, command):
    scene = Path(__file__).parent / "fixtures" / "hm3dsem" / "00001-FixtureScn01"
    extra = ["--out", str(tmp_path / "t.png")] if command == "render-topdown" else []
    rc, _, errors = run(["scenes", command, str(scene), "--up", "0,0,0", *extra], capsys)
    msg = one_line(rc, errors, "--up '0,0,0'", "not all zero")
    assert "expected one of" not in msg


# -- minor: scenes generate --count ---------------------------------------------------------------------
@pytest.mark.parametrize(
    "argv,needle",
    [
        (["--count", "0"], "--count = 0"),
        (["--count", "-1"], "--count = -1"),
        (["--count", "100000000"], "--count = 100000000"),
        (["--split", "val", "--count", "20001"], "at most 20000"),
        (["--count", "1", "--seed", "-1"], "--seed = -1"),
        (["--count", "1", "--seed", "42949"], "--seed = 42949"),
        (["--count", "1", "--workers", "0"], "--workers = 0"),
    ],
)
def test_scenes_generate_refuses_a_bad_count_before_making_folders(tmp_path, capsys, argv, needle):
    out = tmp_path / "scenes"
    rc, _, errors = run(["scenes", "generate", "--out", str(out), *argv], capsys)
    one_line(rc, errors, needle)
    assert not out.exists()


# -- 18: atomic writes get the mode a plain open() gives --------------------------------------------------
@pytest.mark.parametrize("mask", [0o022, 0o077, 0o002])
def test_atomic_writes_get_the_permissions_of_a_plain_open(tmp_path, mask):
    from ovon.atomic import atomic_write_path, atomic_write_text, write_json, write_json_gz

    old = os.umask(mask)
    try:
        plain = tmp_path / "plain.txt"
        plain.write_text("x")
        written = [
            atomic_write_text(tmp_path / "a.txt", "x"),
            write_json(tmp_path / "b.json", {"a": 1}),
            write_json_gz(tmp_path / "c.json.gz", [1]),
            atomic_write_path(tmp_path / "d.bin", lambda p: Path(p).write_bytes(b"x")),
        ]
    finally:
        os.umask(old)
    want = stat.S_IMODE(plain.stat().st_mode)
    assert want == 0o666 & ~mask
    assert {p.name: oct(stat.S_IMODE(p.stat().st_mode)) for p in written} == {p.name: oct(want) for p in written}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.txt", "b.json", "c.json.gz", "d.bin", "plain.txt"]


def test_atomic_write_leaves_no_temp_file_and_keeps_the_old_file_on_error(tmp_path):
    from ovon.atomic import atomic_write_path, atomic_write_text, atomic_write_with

    target = atomic_write_text(tmp_path / "f.txt", "old")

    def fail(_f):
        raise RuntimeError("boom")

    for writer in (atomic_write_with, atomic_write_path):
        with pytest.raises(RuntimeError):
            writer(target, fail)
    assert target.read_text() == "old" and [p.name for p in tmp_path.iterdir()] == ["f.txt"]


def test_every_temp_file_writer_goes_through_ovon_atomic():
    """mkstemp / NamedTemporaryFile create 0600 files: only ovon/atomic.py may make temp files to rename."""
    pattern = re.compile(r"\b(mkstemp|NamedTemporaryFile)\(")
    offenders = [
        str(p.relative_to(OVON_SRC)) for p in OVON_SRC.rglob("*.py") if pattern.search(p.read_text(encoding="utf-8"))
    ]
    assert offenders == []


def test_library_callers_get_the_same_refusals(tmp_path):
    """What the command line checks first is refused by the library too: a zero up vector, a house seed beyond
    32 bits (it would repeat a smaller seed's house), a dot-folder listed as a split."""
    from ovon.dataset.io import resolve_split_dir
    from ovon.scenes.hm3dsem.upaxis import parse_up
    from ovon.scenes.procedural import generate_house

    with pytest.raises(ValueError, match="must not be all zero"):
        parse_up("0,0,0")
    for seed in (-1, 2**32):
        with pytest.raises(ValueError, match=r"outside \[0, 2\*\*32\)"):
            generate_house(seed)
    (tmp_path / ".cache").mkdir()
    (tmp_path / "val_seen").mkdir()
    with pytest.raises(FileNotFoundError) as e:
        resolve_split_dir(tmp_path, "train")
    assert "['val_seen']" in str(e.value) and ".cache" not in str(e.value)
