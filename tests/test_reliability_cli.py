"""Every bad command line is one clear line before any work (issue 13: the CLI cases), and a fuzz of
`ovon evaluate` arguments: exit 0 with the right episode count, or exit 2 with one `ovon: error:` line."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from ovon.dataset.episodes import load_specs
from tests.cli_errors import one_line, refused, run

DEEP = "[" * 600 + "]" * 600


def _eval(tiny_dataset, tiny_scenes, out, *extra):
    return [
        "evaluate",
        "--agent",
        "random",
        "--data",
        str(tiny_dataset),
        "--scenes",
        str(tiny_scenes),
        "--out",
        str(out),
        "--no-progress",
        *extra,
    ]


EVAL_CASES = [  # (extra arguments, words the one line must contain)
    (["--episodes", "-1"], ["--episodes", "-1", "integer > 0"]),
    (["--episodes", "abc"], ["--episodes", "'abc'"]),
    (["--splits", ""], ["--splits", "non-empty"]),
    (["--splits", "val_seen,val_seen"], ["--splits", "distinct"]),
    (["--splits", "../../etc"], ["--splits"]),
    (["--splits", "val_nope"], ["val_nope", "splits present"]),
    (["--seeds", ""], ["--seeds", "non-empty"]),
    (["--seeds", "-3"], ["--seeds", ">= 0"]),
    (["--seeds", "1.5"], ["--seeds"]),
    (["--workers", "0"], ["--workers", "[1, 1024]"]),
    (["--set", "task.success_distance=-1"], ["task.success_distance", "-1", "> 0"]),
    (["--set", "task.max_steps=0"], ["task.max_steps", "fix:"]),
    (["--set", "task.max_steps=1e400"], ["task.max_steps"]),
    (["--set", "sim.camera.width=0"], ["sim.camera.width"]),
    (["--set", "sim.camera.hfov_deg=180"], ["sim.camera.hfov_deg", "(0, 180)"]),
    (["--set", "sim.agent.forward_step=0"], ["sim.agent.forward_step"]),
    (["--set", "episodes=3"], ["unknown override group", "fix:"]),
    (["--set", f"sim.camera.width={DEEP}"], ["sim.camera.width"]),
    (["--noise", "actuation:ilqr*abc"], ["--noise", "'abc'"]),
    (["--noise", "wind"], ["--noise", "wind"]),
    (["--agent-arg", "bogus=1"], ["'bogus'", "stop_probability"]),
    (["--agent-arg", "novalue"], ["--agent-arg", "KEY=VALUE"]),
    (["--agent-arg", "a..b=1"], ["--agent-arg", "KEY=VALUE"]),
    (["--agent-arg", "bogus.key=1"], ["'bogus.key'", "stop_probability"]),
    (["--agent-arg", f"seed={DEEP}"], ["agent 'random'"]),
    (["--agent-arg", "stop_probability=abc"], ["stop_probability='abc'"]),
    (["--agent", "json:JSONDecoder"], ["json:JSONDecoder", "reset"]),
    (["--agent", "os:system"], ["not a class"]),
    (["--agent", "nope"], ["unknown agent 'nope'"]),
    (["--agent", "no_such_module_x:Agent"], ["cannot import module"]),
    (["--agent", "policy"], ["'checkpoint'", "--checkpoint"]),
    (["--agent", "policy", "--checkpoint", "/nonexistent/policy.pt"], ["--checkpoint", "does not exist"]),
    (["--executor", "dask"], ["--executor", "invalid choice"]),
    (["--workers"], ["--workers", "expected one argument"]),
]


@pytest.mark.parametrize("extra,needles", EVAL_CASES, ids=[" ".join(c[0])[:40] for c in EVAL_CASES])
def test_bad_evaluate_arguments_are_one_line_errors_before_any_work(
    tiny_dataset, tiny_scenes, tmp_path, capsys, extra, needles
):
    out = tmp_path / "run"
    argv = _eval(tiny_dataset, tiny_scenes, out, *extra)
    if "--agent" in extra:  # the later --agent wins in argparse; keep one
        i = argv.index("--agent")
        del argv[i : i + 2]
    rc, _, err = run(argv, capsys)
    refused(rc, err, *needles)
    assert not out.exists()  # refused before the run folder was touched


def test_bad_checkpoints_and_outputs(tiny_dataset, tiny_scenes, tmp_path, capsys):
    garbage = tmp_path / "policy.pt"
    garbage.write_bytes(b"\x80\x04not a checkpoint")
    rc, _, err = run(
        _eval(tiny_dataset, tiny_scenes, tmp_path / "r", "--checkpoint", str(garbage)) + ["--agent", "policy"], capsys
    )
    one_line(rc, err, "--checkpoint", "not a checkpoint torch can read")
    truncated = tmp_path / "trunc.pt"
    import torch

    torch.save({"a": torch.zeros(1000)}, truncated)
    truncated.write_bytes(truncated.read_bytes()[:500])
    rc, _, err = run(
        _eval(tiny_dataset, tiny_scenes, tmp_path / "r", "--checkpoint", str(truncated)) + ["--agent", "policy"], capsys
    )
    one_line(rc, err, "--checkpoint")
    f = tmp_path / "afile"
    f.write_text("x")
    rc, _, err = run(_eval(tiny_dataset, tiny_scenes, f), capsys)
    one_line(rc, err, "--out", "existing file")
    assert f.read_text() == "x"


def test_bad_dataset_command_arguments(tiny_dataset, tiny_scenes, tmp_path, capsys):
    gen = ["dataset", "generate", "--scenes", str(tiny_scenes), "--out", str(tmp_path / "g"), "--no-progress"]
    for extra, needles in [
        (["--categories", str(tmp_path / "missing.json")], ["--categories", "missing.json", "existing file"]),
        (["--set", "episodes_per_val_split=-5"], ["episodes_per_val_split", "-5"]),
        (["--set", "viewpoints.render_size=0"], ["viewpoints.render_size"]),
        (["--set", "viewpoints.hfov_deg=0"], ["viewpoints.hfov_deg"]),
        (["--split", "val_nope"], ["--split", "val_nope"]),
        (["--workers", "-2"], ["--workers"]),
        (["--config", str(tmp_path / "nope.yaml")], ["--config"]),
    ]:
        rc, _, err = run(gen + extra, capsys)
        one_line(rc, err, *needles)
        assert not (tmp_path / "g").exists()
    rc, _, err = run(["dataset", "generate", "--scenes", str(tmp_path / "nope"), "--out", str(tmp_path / "g")], capsys)
    one_line(rc, err, "--scenes")
    rc, _, err = run(["dataset", "validate", str(tmp_path / "nope"), "--scenes", str(tiny_scenes)], capsys)
    one_line(rc, err, "DATA")
    rc, _, err = run(
        ["dataset", "validate", str(tiny_dataset), "--scenes", str(tiny_scenes), "--max-episodes-per-scene", "0"],
        capsys,
    )
    one_line(rc, err, "--max-episodes-per-scene")
    rc, _, err = run(
        ["dataset", "splits", "--vocabulary", "--holdout", "1.5", "--out", str(tmp_path / "c.json")], capsys
    )
    one_line(rc, err, "--holdout", "(0, 1)")
    rc, _, err = run(["dataset", "stats", str(tmp_path / "nope")], capsys)
    one_line(rc, err, "DATA")


def test_dataset_generate_into_another_generation_is_refused(tiny_dataset, tiny_scenes, capsys):
    rc, _, err = run(
        [
            "dataset",
            "generate",
            "--scenes",
            str(tiny_scenes),
            "--out",
            str(tiny_dataset),
            "--preset",
            "fast",
            "--set",
            "seed=1",
            "--no-progress",
        ],
        capsys,
    )
    one_line(rc, err, "generation.seed 0 -> 1")


def test_argparse_errors_are_one_line(capsys):
    for argv in (["evaluate"], ["nope"], ["evaluate", "--bogus"], ["dataset"]):
        rc, _, err = run(argv, capsys)
        refused(rc, err)


# -- fuzz ------------------------------------------------------------------------------------------------
EPISODES = ["1", "2", "0", "-1", "", "x", "1e3", "2.0", "999999999999999999999"]
SEEDS = ["0", "1", "0,1", "", ",", "0,0", "-1", "a", "1,,2", " 3 "]
SPLITS = ["val_seen", "val_unseen", "val_seen,val_unseen", "", "val_seen,val_seen", "train", "x/../y", "val_nope"]
SETS = [
    "task.max_steps=20",
    "task.max_steps=0",
    "task.success_distance=0.5",
    "task.success_distance=-1",
    "sim.camera.width=32",
    "sim.camera.width=0",
    "sim.camera.hfov_deg=179",
    "sim.camera.hfov_deg=180",
    "sim.agent.radius=0.2",
    "sim.agent.radius=0",
    "task.seen_fraction=2",
    "sim.noise.odometry=true",
    "task.reward.kind=sparse",
    "task.reward.kind=x",
    "x=1",
    "sim.nav.cell_size=.nan",
]


def _expect_ok(episodes: str, seeds: str, splits: str, sets: list[str]) -> bool:
    """An independent oracle: is this command line valid for the tiny dataset?"""
    try:
        e = float(episodes)
        if e != int(e) or e < 1:
            return False
    except ValueError:
        return False
    seed_list = [s.strip() for s in seeds.split(",") if s.strip()]
    if not seed_list or not all(s.isdigit() for s in seed_list) or len(set(map(int, seed_list))) != len(seed_list):
        return False
    split_list = [s for s in splits.split(",") if s]
    if not split_list or len(set(split_list)) != len(split_list):
        return False
    if any(s not in ("val_seen", "val_seen_synonyms", "val_unseen") for s in split_list):
        return False
    good = {
        "task.max_steps=20",
        "task.success_distance=0.5",
        "sim.camera.width=32",
        "sim.camera.hfov_deg=179",
        "sim.agent.radius=0.2",
        "sim.noise.odometry=true",
        "task.reward.kind=sparse",
    }
    # a key set twice takes its last value (a bad value overridden later on the line is not an error)
    last = {s.split("=", 1)[0]: s for s in sets}
    return all(s in good for s in last.values())


@settings(
    max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow]
)
@given(
    episodes=st.sampled_from(EPISODES),
    seeds=st.sampled_from(SEEDS),
    splits=st.sampled_from(SPLITS),
    sets=st.lists(st.sampled_from(SETS), max_size=2),
)
@example(episodes="1", seeds="0", splits="val_seen", sets=["task.success_distance=-1", "task.success_distance=0.5"])
@example(episodes="1", seeds="0", splits="val_seen", sets=["task.success_distance=0.5", "task.success_distance=-1"])
def test_fuzz_evaluate_arguments(tiny_dataset, tiny_scenes, tmp_path_factory, capsys, episodes, seeds, splits, sets):
    out = tmp_path_factory.mktemp("fuzz") / "run"
    argv = _eval(
        tiny_dataset,
        tiny_scenes,
        out,
        "--episodes",
        episodes,
        "--seeds",
        seeds,
        "--splits",
        splits,
        "--workers",
        "1",
        "--set",
        "task.max_steps=20",
    )
    for s in sets:
        argv += ["--set", s]
    rc, stdout, err = run(argv, capsys)  # run() asserts: no traceback, no internal error
    if _expect_ok(episodes, seeds, splits, sets):
        assert rc == 0, err
        summary = json.loads((Path(out) / "summary.json").read_text())
        n_seeds = len([s for s in seeds.split(",") if s.strip()])
        for split in splits.split(","):
            available = len(load_specs(str(tiny_dataset), str(tiny_scenes), split, None))
            assert summary["splits"][split]["episodes"] == min(int(float(episodes)), available) * n_seeds
    else:
        refused(rc, err)


@pytest.mark.parametrize(
    "args,needle",
    [(["--hfov", "180"], "--hfov = 180.0"), (["--width", "0"], "--width = 0"), (["--hfov", "0"], "--hfov = 0.0")],
)
def test_sim_camera_options_use_the_camera_domains(tmp_path, capsys, args, needle):
    from ovon.cli.main import main

    assert main(["sim", "view", "procedural:3", *args, "--out", str(tmp_path / "v.png")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and needle in err[0] and "fix:" in err[0]
    assert not (tmp_path / "v.png").exists()


def test_train_resume_from_a_torn_checkpoint_is_one_line(tmp_path, capsys):
    from ovon.cli.main import main

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
    assert main(args) == 0
    ckpt = out / "checkpoint.pt"
    ckpt.write_bytes(ckpt.read_bytes()[: ckpt.stat().st_size // 2])
    capsys.readouterr()
    assert main([*args, "--resume"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "checkpoint.pt is not a readable training checkpoint" in err[0] and "fix:" in err[0]
