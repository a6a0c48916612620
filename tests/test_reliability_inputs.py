"""Bad input that used to slip through (issue 22, item 10): each case is counted, refused or repaired, with
one line naming the file, the episode or the option."""

from __future__ import annotations

import gzip
import json
import shutil
import warnings
from pathlib import Path

import pytest

from ovon.cli.main import main as ovon
from ovon.dataset.records import DatasetError


def _shard(root: Path, split: str = "val_seen") -> Path:
    return sorted((root / split / "content").glob("*.json.gz"))[0]


def _mutate(root: Path, fn, split: str = "val_seen") -> Path:
    p = _shard(root, split)
    doc = json.loads(gzip.decompress(p.read_bytes()))
    fn(doc)
    p.write_bytes(gzip.compress(json.dumps(doc).encode()))
    return p


def _episodes(root: Path, split: str = "val_seen") -> int:
    return sum(
        len(json.loads(gzip.decompress(p.read_bytes()))["episodes"])
        for p in (root / split / "content").glob("*.json.gz")
    )


@pytest.fixture
def data(tiny_dataset, tmp_path) -> Path:
    dst = tmp_path / "data"
    shutil.copytree(tiny_dataset, dst, ignore=shutil.ignore_patterns(".cache"))
    return dst


def run(argv: list[str], capsys) -> tuple[int, str, list[str]]:
    """`ovon argv` in this process: exit code, stdout, and the error lines of stderr (warnings aside)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            rc = ovon(argv)
        except SystemExit as e:
            rc = int(e.code or 0)
    out, err = capsys.readouterr()
    errors = [ln for ln in err.strip().splitlines() if ln.strip() and not ln.startswith("ovon: warning:")]
    assert "Traceback" not in err and "internal error" not in err, err
    return rc, out, errors


def one_line(rc: int, errors: list[str], *needles: str) -> str:
    assert rc == 2 and len(errors) == 1 and errors[0].startswith("ovon: error:"), errors
    for n in needles:
        assert n in errors[0], (n, errors[0])
    assert "fix:" in errors[0], errors[0]
    return errors[0]


def _evaluate(data: Path, scenes: Path, out: Path, *extra: str) -> list[str]:
    return [
        "evaluate",
        "--agent",
        "random",
        "--data",
        str(data),
        "--scenes",
        str(scenes),
        "--splits",
        "val_seen",
        "--workers",
        "1",
        "--no-progress",
        "--set",
        "task.max_steps=10",
        "--out",
        str(out),
        *extra,
    ]


def _bad_geodesic(d: dict) -> None:
    d["episodes"][0]["info"]["geodesic_distance"] = "far"


def _off_map(d: dict) -> None:
    d["episodes"][1]["start_position"] = [900.0, 0.0, 900.0]


# -- evaluate: skipped episodes are counted in summary.json, the table and the report ---------------------
def test_skipped_episodes_are_counted_in_summary_table_and_report(data, tiny_scenes, tmp_path, capsys):
    _mutate(data, lambda d: (_bad_geodesic(d), _off_map(d)))
    n = _episodes(data)
    out = tmp_path / "run"
    rc, stdout, errors = run(_evaluate(data, tiny_scenes, out), capsys)
    assert rc == 0, errors
    entry = json.loads((out / "summary.json").read_text())["splits"]["val_seen"]
    assert entry["episodes"] == n - 2
    assert entry["skipped"] == {"picked": n, "count": 2, "reasons": {"info_number": 1, "start_off_map": 1}}
    line = f"val_seen: {n - 2} of {n} episodes (2 skipped before the run: 1 info_number, 1 start_off_map"
    assert line in (out / "table.md").read_text()
    assert line in stdout and f"{n - 2} episodes (2 skipped before the run" in stdout
    rc, _, errors = run(["report", str(out), "--out", str(tmp_path / "rep")], capsys)
    assert rc == 0, errors
    assert f"- random, {line}" in (tmp_path / "rep" / "report.md").read_text()


def test_a_limit_picks_the_first_episodes_and_counts_the_invalid_ones_among_them(data, tiny_scenes, tmp_path, capsys):
    _mutate(data, _bad_geodesic)  # the first episode of the split (round-robin order starts with it)
    out = tmp_path / "run"
    rc, _, errors = run(_evaluate(data, tiny_scenes, out, "--episodes", "4", "--seeds", "0,1"), capsys)
    assert rc == 0, errors
    entry = json.loads((out / "summary.json").read_text())["splits"]["val_seen"]
    assert entry["episodes"] == 2 * 3 and entry["skipped"]["picked"] == 4 and entry["skipped"]["count"] == 1
    assert "val_seen: 3 of 4 episodes per seed (1 skipped" in (out / "table.md").read_text()


def test_reports_show_the_episodes_the_last_command_wanted(tiny_dataset, tiny_scenes, tmp_path, capsys):
    """A run evaluated on 3 episodes, then asked for 1, keeps all 3 records in episodes.jsonl; its summary,
    `ovon report` and the experiment report's records cover the 1 (reports once read every record)."""
    from ovon.evaluate.results import read_records, selected_records, summarize

    out = tmp_path / "run"
    for n in ("3", "1"):
        rc, _, errors = run(_evaluate(tiny_dataset, tiny_scenes, out, "--episodes", n), capsys)
        assert rc == 0, errors
    assert len(read_records(out)) == 3 and len(selected_records(out)) == 1
    summary = json.loads((out / "summary.json").read_text())["splits"]["val_seen"]
    assert summary["episodes"] == 1 and summarize(selected_records(out))["val_seen"]["episodes"] == 1
    rc, _, errors = run(["report", str(out), "--out", str(tmp_path / "rep")], capsys)
    assert rc == 0, errors
    soft, dist = summary["soft_spl"]["mean"], summary["distance_to_goal"]["mean"]
    dist = f"| random | val_seen | {100 * soft:.1f} | {dist:.2f} |"
    assert dist in (tmp_path / "rep" / "report.md").read_text()


def test_a_clean_split_reports_zero_skipped_and_keeps_the_table(tiny_dataset, tiny_scenes, tmp_path, capsys):
    out = tmp_path / "run"
    rc, _, errors = run(_evaluate(tiny_dataset, tiny_scenes, out, "--episodes", "2"), capsys)
    assert rc == 0, errors
    entry = json.loads((out / "summary.json").read_text())["splits"]["val_seen"]
    assert entry["skipped"] == {"picked": 2, "count": 0, "reasons": {}}
    table = (out / "table.md").read_text()
    assert "skipped" not in table  # nothing skipped to note: header, rule, one row, then the protocol line
    assert table.splitlines()[3:] == ["", table.splitlines()[-1]] and table.splitlines()[-1].startswith("- Protocol:")


@pytest.mark.parametrize(
    "mutate,needle", [(_bad_geodesic, "info.geodesic_distance = 'far'"), (_off_map, "is not on the navigable map")]
)
def test_strict_refuses_an_invalid_episode_naming_file_and_episode(data, tiny_scenes, tmp_path, capsys, mutate, needle):
    shard = _mutate(data, mutate)
    doc = json.loads(gzip.decompress(shard.read_bytes()))
    eid = doc["episodes"][0 if mutate is _bad_geodesic else 1]["episode_id"]
    out = tmp_path / "run"
    rc, _, errors = run(_evaluate(data, tiny_scenes, out, "--strict"), capsys)
    one_line(rc, errors, str(shard), f"episode {eid!r}", needle, "--strict")
    assert not out.exists()


def _floating(d: dict) -> None:
    d["episodes"][1]["start_position"][1] += 0.6  # navigable x, z; 0.6 m above the floor


def test_a_start_floating_above_its_floor_is_one_rule_for_validate_evaluate_and_the_env(
    data, tiny_scenes, tmp_path, capsys
):
    """The env refuses a start more than 0.5 m from its floor's surface; the off-map filter and `dataset
    validate` apply the same rule (`SceneNav.start_problem`), so such an episode is counted as skipped
    instead of failing the evaluation in the middle of its unit."""
    shard = _mutate(data, _floating)
    eid = json.loads(gzip.decompress(shard.read_bytes()))["episodes"][1]["episode_id"]
    out = tmp_path / "run"
    rc, _, errors = run(_evaluate(data, tiny_scenes, out), capsys)
    assert rc == 0, errors
    entry = json.loads((out / "summary.json").read_text())["splits"]["val_seen"]
    assert entry["skipped"]["reasons"] == {"start_off_map": 1} and entry["episodes"] == _episodes(data) - 1
    rc, _, errors = run(_evaluate(data, tiny_scenes, tmp_path / "strict", "--strict"), capsys)
    one_line(rc, errors, str(shard), f"episode {eid!r}", "from its floor's surface")
    rc, out_text, _ = run(["dataset", "validate", str(data), "--scenes", str(tiny_scenes)], capsys)
    assert rc != 0 and "from its floor's surface" in out_text


# -- episode files: absurd positions, string numbers, corrupt categories.json ------------------------------
@pytest.mark.parametrize("key", ["start_position", "view_point"])
def test_a_huge_position_is_one_line_naming_file_and_key(data, tiny_scenes, tmp_path, capsys, key):
    def far(d: dict) -> None:
        if key == "start_position":
            d["episodes"][0]["start_position"] = [1e308, 0.0, 0.0]
        else:
            goals = next(iter(d["goals_by_category"].values()))
            goals[0]["view_points"][0]["agent_state"]["position"] = [0.0, -1e308, 0.0]

    shard = _mutate(data, far)
    rc, _, errors = run(_evaluate(data, tiny_scenes, tmp_path / "run"), capsys)
    line = one_line(rc, errors, str(shard), "within ±100000 m")
    assert ("episodes[0].start_position" if key == "start_position" else "view_points[0].agent_state.position") in line
    rc, _, errors = run(["dataset", "validate", str(data), "--scenes", str(tiny_scenes)], capsys)
    one_line(rc, errors, str(shard))


def test_stats_with_a_string_geodesic_names_file_and_episode(data, capsys):
    shard = _mutate(data, _bad_geodesic)
    rc, _, errors = run(["dataset", "stats", str(data)], capsys)
    one_line(rc, errors, str(shard), "episodes[0]", "info.geodesic_distance = 'far'")


@pytest.mark.parametrize(
    "text,needle",
    [('{"train": [1, ', "not valid JSON"), ('{"train": 5}', "malformed"), ("[1, 2]", "expected a JSON object")],
)
def test_stats_with_a_corrupt_categories_json_names_the_file(data, capsys, text, needle):
    (data / "categories.json").write_text(text)
    rc, _, errors = run(["dataset", "stats", str(data)], capsys)
    one_line(rc, errors, str(data / "categories.json"), needle)


def test_report_sets_aside_a_record_with_a_string_geodesic(tiny_dataset, tiny_scenes, tmp_path, capsys):
    out = tmp_path / "run"
    assert run(_evaluate(tiny_dataset, tiny_scenes, out, "--episodes", "3"), capsys)[0] == 0
    lines = (out / "episodes.jsonl").read_text().splitlines()
    rec = json.loads(lines[0])
    rec["geodesic_distance"] = "far"
    (out / "episodes.jsonl").write_text("\n".join([json.dumps(rec), *lines[1:]]) + "\n")
    capsys.readouterr()
    assert ovon(["report", str(out), "--out", str(tmp_path / "rep")]) == 0
    err = capsys.readouterr().err
    assert "episodes.jsonl: 1 line(s) that are not complete records skipped (line 1)" in err


# -- train --resume after a kill left a torn line in metrics.jsonl ----------------------------------------
def test_resume_drops_a_torn_last_metrics_line(tmp_path, capsys):
    from ovon.train.logging import RunLogger, read_metrics

    out = tmp_path / "run"
    args = [
        "train",
        "--algo",
        "dagger",
        "--preset",
        "tiny",
        "--procedural",
        "0",
        "--episodes",
        "2",
        "--expert",
        "shortest-path",
        "--out",
        str(out),
    ]
    assert run(args, capsys)[0] == 0
    rows = read_metrics(out)
    metrics = out / "metrics.jsonl"
    whole = metrics.read_bytes()
    metrics.write_bytes(whole + b'{"update": 99, "step": 12')  # what a kill -9 mid-write leaves
    with pytest.warns(UserWarning, match="metrics.jsonl: skipped 1 line"):
        assert read_metrics(out) == rows
    with pytest.warns(UserWarning, match=r"metrics.jsonl: dropped 1 line\(s\) that are not complete"):
        RunLogger(out, total_updates=5, description="t", progress=False, start_update=rows[-1]["update"]).close()
    assert metrics.read_bytes() == whole
    metrics.write_bytes(whole + b'{"update": 99, "step": 12')
    rc, _, errors = run([*args, "--resume"], capsys)
    assert rc == 0, errors
    assert metrics.read_bytes() == whole


# -- scenes: an empty semantic.txt, scenes without a navigable floor -------------------------------------
def test_an_empty_semantic_txt_is_named(tiny_scenes, tmp_path, capsys):
    scenes = tmp_path / "scenes"
    shutil.copytree(tiny_scenes, scenes)
    txt = sorted(scenes.glob("val/*/*.semantic.txt"))[0]
    txt.write_text("")
    rc, _, errors = run(
        [
            "dataset",
            "generate",
            "--scenes",
            str(scenes),
            "--out",
            str(tmp_path / "gen"),
            "--no-progress",
            "--split",
            "val_seen",
        ],
        capsys,
    )
    one_line(rc, errors, str(txt), "holds no annotated instance")
    assert not (tmp_path / "gen").exists()
    rc, _, errors = run(["dataset", "splits", "--scenes", str(scenes), "--out", str(tmp_path / "c.json")], capsys)
    one_line(rc, errors, str(txt))


def _flip_winding(folder: Path) -> None:
    """Rewrite a scene with every face wound the other way: its floors face down (a common export bug),
    so it has no navigable floor."""
    from ovon.scenes.hm3dsem import write_scene
    from ovon.sim.world import load_scene_any

    scene = load_scene_any(str(folder))
    for mesh in (scene.mesh, scene.semantic_mesh):
        if mesh is not None:
            mesh.faces = mesh.faces[:, [0, 2, 1]].copy()
    shutil.rmtree(folder)
    write_scene(scene, folder)


def _generate(scenes: Path, out: Path) -> list[str]:
    return [
        "dataset",
        "generate",
        "--scenes",
        str(scenes),
        "--out",
        str(out),
        "--no-progress",
        "--preset",
        "fast",
        "--split",
        "val_seen",
        "--set",
        "episodes_per_val_split=6",
        "--set",
        "viewpoints.render_size=48",
        "--set",
        "viewpoints.max_viewpoints=4",
        "--workers",
        "1",
    ]


def test_generation_where_no_scene_yields_is_an_error_naming_scene_and_reason(tiny_scenes, tmp_path, capsys):
    scenes = tmp_path / "scenes"
    shutil.copytree(tiny_scenes, scenes, ignore=shutil.ignore_patterns("00022-*"))  # one val scene
    bad = sorted((scenes / "val").iterdir())[0]
    _flip_winding(bad)
    out = tmp_path / "gen"
    rc, _, errors = run(_generate(scenes, out), capsys)
    one_line(rc, errors, f"val/{bad.name}", "no navigable floor")
    assert not out.exists()  # a corrected re-run into the same folder starts afresh


def test_a_scene_without_floor_beside_good_ones_is_a_counted_warning(tiny_scenes, tmp_path, capsys):
    scenes = tmp_path / "scenes"
    shutil.copytree(tiny_scenes, scenes)
    bad = sorted((scenes / "val").iterdir())[0]
    _flip_winding(bad)
    out = tmp_path / "gen"
    capsys.readouterr()
    assert ovon(_generate(scenes, out)) == 0
    warned = [ln for ln in capsys.readouterr().err.splitlines() if "yield no episode" in ln]
    assert len(warned) == 1 and f"1 of 2 scenes of {scenes} yield no episode" in warned[0], warned
    assert f"val/{bad.name}: no navigable floor" in warned[0]
    report = json.loads((out / "generation_report.json").read_text())
    assert list(report["scenes_without_episodes"]) == [f"val/{bad.name}"]
    assert report["new_episodes"]["val_seen"] == 6


def test_generating_a_split_without_its_scene_kind_is_refused(tiny_scenes, tmp_path, capsys):
    scenes = tmp_path / "scenes"
    shutil.copytree(tiny_scenes / "val", scenes / "val")
    rc, _, errors = run(
        [
            "dataset",
            "generate",
            "--scenes",
            str(scenes),
            "--out",
            str(tmp_path / "gen"),
            "--no-progress",
            "--split",
            "train",
        ],
        capsys,
    )
    one_line(rc, errors, "no train scenes", str(scenes / "train"))
    assert not (tmp_path / "gen").exists()


# -- sim view: the output path and the pitch have declared domains ---------------------------------------
@pytest.mark.parametrize(
    "args,needle",
    [
        (["--pitch", "1000"], "--pitch = 1000.0"),
        (["--pitch", "nan"], "--pitch"),
        (["--pose", "1e308,0,0,0"], "--pose"),
        (["--seed", "-1"], "--seed"),
        (["--out", "{dir}"], "--out"),
        (["--out", "{dir}/x.jpg"], ".png"),
    ],
)
def test_sim_view_refuses_out_of_domain_options(tmp_path, capsys, args, needle):
    argv = ["sim", "view", "procedural:3", "--width", "40", "--height", "30", "--out", str(tmp_path / "v.png")]
    argv += [a.replace("{dir}", str(tmp_path)) for a in args]
    rc, _, errors = run(argv, capsys)
    one_line(rc, errors, needle)
    assert not list(tmp_path.glob("*.png")) and not list(tmp_path.glob("*.jpg"))


def test_sim_view_out_naming_a_folder_called_png_is_refused(tmp_path, capsys):
    folder = tmp_path / "frames.png"
    folder.mkdir()
    rc, _, errors = run(["sim", "view", "procedural:3", "--out", str(folder)], capsys)
    one_line(rc, errors, "is a folder", "expected the path of a .png file")


def test_load_split_strict_raises_dataset_error(data, tiny_scenes):
    from ovon.dataset.episodes import load_split

    _mutate(data, _bad_geodesic)
    assert load_split(str(data), str(tiny_scenes), "val_seen", None).skipped == {"info_number": 1}
    with pytest.raises(DatasetError, match=r"episode '0' \(episodes\[0\]\).*--strict"):
        load_split(str(data), str(tiny_scenes), "val_seen", None, strict=True)
