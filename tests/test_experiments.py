"""Experiments as data: every definition resolves to valid commands at every scale, the paper's numbers
satisfy the paper's findings, shards cover every cell once, and a tiny run trains, evaluates, survives a
SIGKILL, resumes without repeating finished cells and reports missing cells as "not run"."""

from __future__ import annotations

import contextlib
import io
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import torch
from rich.console import Console

from ovon.experiments import (
    DefinitionError,
    experiment_names,
    load_catalogue,
    load_experiment,
    parse_shard,
    resolve,
    run,
    select,
    write_experiment_report,
)
from ovon.experiments.plan import train_spec
from ovon.experiments.report import experiment_results, table_markdown, wall_text
from ovon.experiments.runner import killed_wall_s
from ovon.experiments.select import DATA

ROOT = Path(__file__).resolve().parents[1]
EXPECTED = {"main", "trajectories", "memory", "noise", "failures"}
MODULAR = {"vlfm", "dagrl-od"}  # built by the "modular" helper; "not available" until then


def all_experiments():
    return [load_experiment(n) for n in experiment_names()]


def quiet() -> Console:
    return Console(file=io.StringIO(), width=200)


@pytest.mark.parametrize("scale", ["tiny", "cpu", "paper"])
def test_every_definition_resolves_at_every_scale(scale: str, tmp_path: Path) -> None:
    from ovon.agents import BUILTIN
    from ovon.train.config import TrainConfig

    assert EXPECTED <= set(experiment_names())
    plan = resolve(all_experiments(), scale, tmp_path)
    trains = {c.name: c for c in plan.cells.values() if c.kind == "train"}
    evals = {c.name: c for c in plan.cells.values() if c.kind == "eval"}
    # RL from scratch is two cells (rl-warmup, rl) below paper scale
    assert len(trains) == (16 if scale == "paper" else 18) and len(evals) == 22
    if scale == "cpu":  # learned perception everywhere but the rows named as the oracle upper bound
        assert {c.train_cfg.encoder.image for c in trains.values()} == {"world-vl"}
        for name, cell in evals.items():
            args = " ".join(cell.commands[0])
            learned = "detector.kind=world-owl" in args
            assert learned == (cell.eval_cell.agent != "policy" and "oracle" not in name), name
    recipes = load_catalogue().recipes
    for name, cell in trains.items():
        assert isinstance(cell.train_cfg, TrainConfig), name
        assert cell.train_cfg.algo == recipes[train_spec(load_catalogue().train[name], scale)[0]].algo
        assert all(d in plan.cells for d in cell.deps), name
        assert cell.folder == tmp_path / scale / "train" / name
        if "--init" in cell.commands[0]:
            init = cell.commands[0][cell.commands[0].index("--init") + 1]
            assert init == str(tmp_path / scale / "train" / cell.deps[1].split(":")[1] / "policy.pt")
    assert trains["dagger-lstm"].train_cfg.policy.core == "lstm"
    assert trains["dagger-sp"].train_cfg.expert == "shortest-path"
    assert trains["dagrl"].deps == ("data:data", "train:dagger")
    for name, cell in evals.items():
        ec = cell.eval_cell
        assert ec.agent in BUILTIN or ec.agent in MODULAR, name
        argv = cell.commands[0]
        seeds = argv[argv.index("--seeds") + 1].split(",")
        assert len(set(seeds)) >= 2
        assert set(argv[argv.index("--splits") + 1].split(",")) <= {"val_seen", "val_seen_synonyms", "val_unseen"}
    if scale == "paper":
        assert trains["dagger"].launcher[0] == "torchrun" and "--nproc-per-node" in trains["dagger"].launcher
        assert trains["dagger"].train_cfg.encoder.image == "siglip"
        assert "--executor" in evals["dagrl"].commands[0] and "ray" in evals["dagrl"].commands[0]
    else:
        assert trains["dagger"].launcher == ()
        assert trains["dagger"].train_cfg.encoder.image == ("oracle-vl" if scale == "tiny" else "world-vl")
    # VLFM sees the camera the policies were trained with (an override, or the default when they match it)
    from ovon.config.sim import cpu_sim_config

    sets, cam, default = evals["vlfm"].run.overrides, trains["dagrl"].train_cfg.sim.camera, cpu_sim_config().camera
    for key in ("width", "height", "hfov_deg"):
        assert sets.get(f"sim.camera.{key}", getattr(default, key)) == getattr(cam, key), key


def test_cells_shared_between_experiments_are_one_run_folder(tmp_path: Path) -> None:
    main = resolve([load_experiment("main")], "cpu", tmp_path)
    memory = resolve([load_experiment("memory")], "cpu", tmp_path)
    both = resolve([load_experiment("main"), load_experiment("memory")], "cpu", tmp_path)
    for cid in ("train:dagger", "train:dagrl", "eval:dagrl"):
        assert main.cells[cid].commands == memory.cells[cid].commands == both.cells[cid].commands
        assert main.cells[cid].folder == memory.cells[cid].folder
    # 5 transformer + 5 LSTM, once each, RL from scratch in two phases, DAgger and DAgRL from a second seed
    assert len([c for c in both.cells if c.startswith("train:")]) == 14


def test_every_table_entry_has_the_papers_numbers_and_they_satisfy_its_findings() -> None:
    for exp in all_experiments():
        evals = {}
        for row in exp.table.rows if exp.table else ():
            for name in {row.eval, *row.evals.values()} - {""}:
                evals[name] = {"summary": None, "status": "missing", "setup": ""}
        for fig in exp.figures:
            evals[fig.eval] = {"summary": None, "status": "missing", "setup": ""}
        res = experiment_results(exp, evals, "cpu")
        for row in res.get("table", {}).get("rows", []):
            for entry in row["cells"].values():
                # only our upper-bound rows have no paper numbers
                assert (entry["paper"] is None) == ("upper bound" in row["name"]) and entry["ours"] is None
        for f in res["findings"]:
            assert f["paper"]["verdict"] == "holds", (exp.name, f["id"], f["paper"])
            assert f["ours"]["verdict"] == "not run"
    ids = sorted(f.id for e in all_experiments() for f in e.findings)
    assert ids == ["a", "b", "c", "d", "e", "f", "g"]


def test_main_table_numbers_are_the_papers() -> None:
    rows = {r.name: r for r in load_experiment("main").table.rows}
    assert rows["DAgRL"].paper["val_seen"] == [41.3, 0.3, 21.2, 0.3]
    assert rows["VLFM"].paper["val_unseen"] == [35.2, None, 19.6, None]
    assert rows["DAgRL+OD"].paper["val_seen_synonyms"] == [39.0, 0.7, 21.4, 0.5]


@pytest.mark.parametrize("n", [1, 2, 3, 5])
def test_shards_cover_every_cell_exactly_once_and_hold_whole_chains(n: int, tmp_path: Path) -> None:
    plan = resolve(all_experiments(), "cpu", tmp_path)
    shards = [select(plan, shard=(i, n)) for i in range(n)]
    assert shards == [select(plan, shard=(i, n)) for i in range(n)]  # deterministic
    cells = [c for s in shards for c in s if c != DATA]
    assert sorted(cells) == sorted(c for c in plan.cells if c != DATA)
    assert len(cells) == len(set(cells))
    for s in shards:
        assert s[0] == DATA
        for c in s:
            assert all(d in s for d in plan.cells[c].deps), (c, plan.cells[c].deps)
    if n > 1:
        assert all(len(s) > 1 for s in shards)


def test_only_takes_what_a_cell_needs(tmp_path: Path) -> None:
    plan = resolve([load_experiment("main")], "cpu", tmp_path)
    assert select(plan, only=["eval:dagrl"]) == [DATA, "train:dagger", "train:dagrl", "eval:dagrl"]
    assert select(plan, only=["bc"]) == [DATA, "train:bc", "eval:bc"]
    with pytest.raises(DefinitionError, match="no cell 'nope'"):
        select(plan, only=["nope"])
    with pytest.raises(DefinitionError, match="0 <= i < n"):
        parse_shard("2/2")


def test_redo_takes_what_depends_on_a_cell_and_never_a_users_dataset(tmp_path: Path) -> None:
    plan = resolve([load_experiment("main")], "cpu", tmp_path)
    result = run(plan, redo_cells=["train:bc"], dry_run=True, console=quiet())
    assert sorted(c for c, s in result.statuses.items() if s.state == "redo") == [
        "eval:bc",
        "eval:bcrl",
        "train:bc",
        "train:bcrl",
    ]
    # what the cascade would move aside must also run: --only leaving it out is refused, before any work
    with pytest.raises(
        DefinitionError,
        match=r"--redo train:bc also recomputes train:bcrl, eval:bc, eval:bcrl .*fix: "
        r"add them to --only",
    ):
        run(plan, only=["train:bc"], redo_cells=["train:bc"], dry_run=True, console=quiet())
    both = run(plan, only=["eval:bc", "eval:bcrl"], redo_cells=["train:bc"], dry_run=True, console=quiet())
    assert both.statuses["eval:bcrl"].state == "redo"
    paper = resolve([load_experiment("main")], "paper", tmp_path)
    with pytest.raises(DefinitionError, match="never moves"):
        run(paper, redo_cells=["data"], dry_run=True, console=quiet())


def _write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


BAD = {
    "unknown recipe": ("train: {x: {recipe: nope}}\n", "recipe = 'nope'"),
    "unknown init": ("train: {x: {recipe: finetune, init: ghost}}\n", "ghost"),
    "bad train key": ("train: {x: {recipe: dagger, set: {ppo.clipp: 0.1}}}\n", "clipp"),
    "unknown field": ("train: {x: {recipe: dagger, expertt: frontier}}\n", "expertt"),
    "bad split": ("train: {x: {recipe: dagger}}\n", "splits"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_definitions_fail_with_one_line(case: str, tmp_path: Path) -> None:
    train, expected = BAD[case]
    splits = "[val_test]" if case == "bad split" else "[val_seen]"
    text = (
        f"title: t\n{train}evaluate: {{e: {{agent: policy, checkpoint: x, splits: {splits}}}}}\n"
        "table: {caption: c, columns: [{name: v, split: val_seen}], rows: [{name: r, eval: e, paper: {v: [1, null, "
        "1, null]}}]}\n"
    )
    with pytest.raises(DefinitionError) as err:
        resolve([load_experiment(str(_write(tmp_path / "bad.yaml", text)))], "cpu", tmp_path)
    msg = str(err.value)
    assert expected in msg and "\n" not in msg


def test_missing_paper_numbers_and_bad_references_are_refused(tmp_path: Path) -> None:
    base = (
        "title: t\ntable: {caption: c, columns: [{name: v, split: val_seen}], rows: [{name: DAgRL, eval: dagrl%s}]}\n"
    )
    two = base.replace("{name: v, split: val_seen}", "{name: v, split: val_seen}, {name: w, split: val_unseen}")
    with pytest.raises(DefinitionError, match="no paper numbers for column 'w'"):  # partial numbers: a typo
        partial = two % ", paper: {v: [1, 1, 1, 1]}"
        resolve([load_experiment(str(_write(tmp_path / "a.yaml", partial)))], "cpu", tmp_path)
    resolve([load_experiment(str(_write(tmp_path / "c.yaml", base % "")))], "cpu", tmp_path)  # none: ours only
    ok = base % ", paper: {v: [1, null, 1, null]}"
    margin = ok + "findings: [{id: z, claim: c, checks: [{kind: drop, margin: 5, pairs: [[DAgRL @ v, DAgRL @ v]]}]}]\n"
    with pytest.raises(DefinitionError, match="margin = 5 on a 'drop' check"):
        resolve([load_experiment(str(_write(tmp_path / "d.yaml", margin)))], "cpu", tmp_path)
    bad_ref = ok + "findings: [{id: z, claim: c, checks: [{kind: greater, pairs: [[DAgRL @ v, BC @ v]]}]}]\n"
    with pytest.raises(DefinitionError, match="'BC @ v'"):
        resolve([load_experiment(str(_write(tmp_path / "b.yaml", bad_ref)))], "cpu", tmp_path)
    why = ok + "findings: [{id: z, claim: c, differs: {huge: s}, checks: [{kind: best, target: DAgRL @ v}]}]\n"
    with pytest.raises(DefinitionError, match="finding z: differs.huge = 's'; expected a scale of scales.yaml"):
        resolve([load_experiment(str(_write(tmp_path / "e.yaml", why)))], "cpu", tmp_path)
    quoted = why.replace("differs: {huge: s}", "differs: {cpu: 'at {DAgRL @ v - BC @ v}'}")
    with pytest.raises(DefinitionError, match=r"quotes \{DAgRL @ v - BC @ v\}, but 'BC @ v' is not a table"):
        resolve([load_experiment(str(_write(tmp_path / "f.yaml", quoted)))], "cpu", tmp_path)
    with pytest.raises(DefinitionError, match="reference 'DAgRL v' is not 'ROW @ COLUMN'"):
        unparsed = why.replace("differs: {huge: s}", "differs: {cpu: 'at {DAgRL v - DAgRL @ v}'}")
        resolve([load_experiment(str(_write(tmp_path / "g.yaml", unparsed)))], "cpu", tmp_path)
    fine = margin.replace("id: z,", "id: z, differs: {cpu: 'at {DAgRL @ v} and {x}'},").replace("margin: 5, ", "")
    resolve([load_experiment(str(_write(tmp_path / "h.yaml", fine)))], "cpu", tmp_path)  # braces without '@' stay
    with pytest.raises(DefinitionError, match="unknown scale 'huge'"):
        resolve([load_experiment("main")], "huge", tmp_path)
    with pytest.raises(DefinitionError, match="seeds"):
        resolve([load_experiment("main")], "cpu", tmp_path, ["evaluate.seeds=[0]"])
    with pytest.raises(DefinitionError, match="unknown experiment 'mian'"):
        load_experiment("mian")


def test_cli_dry_run_prints_each_cells_status_and_command(tmp_path: Path) -> None:
    from ovon.cli.main import main

    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert (
            main(
                [
                    "experiment",
                    "run",
                    "main",
                    "--scale",
                    "paper",
                    "--root",
                    str(tmp_path),
                    "--dry-run",
                    "--shard",
                    "0/2",
                ]
            )
            == 0
        )
    text = out.getvalue()
    assert "torchrun --standalone --nproc-per-node 8 -m ovon.cli.main train --algo" in text
    assert "data:data" in text and "missing" in text
    assert not (tmp_path / "paper").exists()  # a dry run writes nothing


# ----- the runner on a tiny experiment ----------------------------------------------------------------
TINY = """
title: runner test
paper_ref: none
train:
  t-dagger: {recipe: dagger, expert: shortest-path}
  t-ft: {recipe: finetune, init: t-dagger}
evaluate:
  t-dagger: {agent: policy, checkpoint: t-dagger, agent_args: {deterministic: true}, splits: [val_seen]}
  t-ft: {agent: policy, checkpoint: t-ft, agent_args: {deterministic: true}, splits: [val_seen]}
  t-missing: {agent: "tests.no_such_module:Agent", splits: [val_seen]}
table:
  caption: test
  columns: [{name: val_seen, split: val_seen}]
  rows:
    - {name: DAgger, eval: t-dagger, paper: {val_seen: [18.1, 0.4, 9.4, 0.3]}}
    - {name: DAgRL, eval: t-ft, paper: {val_seen: [41.3, 0.3, 21.2, 0.3]}}
    - {name: Missing, eval: t-missing, paper: {val_seen: [1.0, null, 1.0, null]}}
findings:
  - {id: x, claim: DAgRL beats DAgger, checks: [{kind: greater, pairs: [[DAgRL @ val_seen, DAgger @ val_seen]]}]}
"""
TINY_SET = ["data.val_scenes=1"]


def _record(root: Path, cid: str) -> dict:
    path = root / "tiny" / "cells" / f"{cid.replace(':', '-')}.json"
    return json.loads(path.read_text()) if path.exists() else {}


def _alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().split(")")[-1].split()[0] != "Z"
    except OSError:
        return False


def test_tiny_run_survives_a_kill_resumes_without_repeating_and_reports(tmp_path: Path) -> None:
    exp_file = _write(tmp_path / "tiny_exp.yaml", TINY)
    root = tmp_path / "root"
    cmd = [
        sys.executable,
        "-m",
        "ovon.cli.main",
        "experiment",
        "run",
        str(exp_file),
        "--scale",
        "tiny",
        "--root",
        str(root),
        "--no-report",
        *(a for s in TINY_SET for a in ("--set", s)),
    ]
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    deadline = time.time() + 400
    try:
        while time.time() < deadline:  # kill once the fine-tune (the second training cell) is running
            rec = _record(root, "train:t-ft")
            if rec.get("state") == "running" and rec.get("pid"):
                break
            assert proc.poll() is None, proc.stdout.read().decode()
            time.sleep(0.5)
        else:
            pytest.fail("the fine-tune cell never started")
        time.sleep(1.0)
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    finally:
        if proc.poll() is None:
            proc.kill()
    child = _record(root, "train:t-ft")["pid"]
    for _ in range(50):  # the cell's command dies with the runner (parent-death signal)
        if not _alive(child):
            break
        time.sleep(0.2)
    assert not _alive(child)
    first = _record(root, "train:t-dagger")
    assert first["state"] == "done" and first["attempts"] == 1
    policy = root / "tiny" / "train" / "t-dagger" / "policy.pt"
    mtime = policy.stat().st_mtime_ns

    plan = resolve([load_experiment(str(exp_file))], "tiny", root, TINY_SET)
    result = run(plan, console=quiet())
    assert result.ok and result.failed == []
    assert "train:t-dagger" not in result.ran and "data:data" not in result.ran
    assert {"train:t-ft", "eval:t-dagger", "eval:t-ft"} <= set(result.ran)
    assert policy.stat().st_mtime_ns == mtime
    assert _record(root, "train:t-dagger")["attempts"] == 1
    assert _record(root, "data:data")["attempts"] == 1
    assert _record(root, "train:t-ft")["attempts"] == 2 and _record(root, "train:t-ft")["state"] == "done"
    assert result.statuses["eval:t-missing"].state == "unavailable"

    again = run(plan, console=quiet())  # everything finished: nothing runs
    assert again.ran == [] and again.ok
    assert {c: _record(root, c).get("attempts") for c in ("eval:t-dagger", "eval:t-ft")} == {
        "eval:t-dagger": 1,
        "eval:t-ft": 1,
    }

    report = write_experiment_report(plan, tmp_path / "report")
    data = json.loads((tmp_path / "report" / "report.json").read_text())
    rows = {r["name"]: r["cells"]["val_seen"] for r in data["experiments"]["tiny_exp"]["table"]["rows"]}
    assert rows["Missing"]["ours"] is None and "not available" in rows["Missing"]["status"]
    assert rows["DAgRL"]["ours"]["seeds"] == 2 and rows["DAgRL"]["paper"]["sr"] == 41.3
    text = report.read_text()
    assert "not run (paper 1.0)" in text and "| Missing |" in text
    assert "(x) DAgRL beats DAgger" in text
    assert (tmp_path / "report" / "figures" / "curve_t-ft.png").is_file()
    assert (tmp_path / "report" / "figures" / "tiny_exp_table.png").is_file()

    # what each attempt ran with is recorded, the killed one included, and the resolved config
    ft = _record(root, "train:t-ft")
    assert [h["rc"] for h in ft["history"]] == ["killed", 0] and all(h["code"] == ft["code"] for h in ft["history"])
    killed = ft["history"][0]  # its time is estimated from its log, and counted in the cell's
    assert killed["wall_estimated"] and killed["wall_s"] >= 0
    assert ft["wall_s"] == pytest.approx(killed["wall_s"] + ft["history"][1]["wall_s"], abs=0.2)
    assert ft["code"].startswith("ovon ") and ft["config"]["algo"] == "ppo"
    assert ft["config"]["text_cache"] == "$ROOT/tiny/data/text_cache.pt"
    assert _record(root, "eval:t-ft")["config"]["agent_kwargs"]["checkpoint"] == "$ROOT/tiny/train/t-ft/policy.pt"
    assert "episodes_per_val_split" in _record(root, "data:data")["config"]

    # provenance: one clean commit says so at the top; another commit or a dirty tree marks what rests on it
    def codes(cid: str, *texts: str) -> None:
        rec = _record(root, cid)
        rec["code"] = texts[-1]
        rec["history"] = [{**h, "code": t} for h, t in zip(rec["history"], [*texts[:-1], *[texts[-1]] * 9])]
        (root / "tiny" / "cells" / f"{cid.replace(':', '-')}.json").write_text(json.dumps(rec))

    def entries() -> dict:
        data = json.loads((tmp_path / "report" / "report.json").read_text())
        return {r["name"]: r["cells"]["val_seen"]["marked"] for r in data["experiments"]["tiny_exp"]["table"]["rows"]}

    for cid in ("data:data", "train:t-dagger", "train:t-ft", "eval:t-dagger", "eval:t-ft"):
        codes(cid, "ovon 0.1.0 (1111111)")
    text = write_experiment_report(plan, tmp_path / "report").read_text()
    assert "Provenance: every finished cell ran with ovon 0.1.0 (1111111) from a clean tree" in text.splitlines()[2]
    assert "†" not in text and entries() == {"DAgger": False, "DAgRL": False, "Missing": False}
    codes("eval:t-ft", "ovon 0.1.0 (2222222+dirty)")
    text = write_experiment_report(plan, tmp_path / "report").read_text()
    assert "1 cell(s) ran with another commit than ovon 0.1.0 (1111111)" in text.splitlines()[2]
    assert "| eval:t-ft | done | 2222222 | dirty | recorded | † other commit (2222222); dirty tree |" in text
    assert entries() == {"DAgger": False, "DAgRL": True, "Missing": False}
    assert "# eval:t-ft: done" in text and "(2222222+dirty) †" in text
    codes("eval:t-ft", "ovon 0.1.0 (1111111)")
    codes("train:t-dagger", "ovon 0.1.0 (3333333)", "ovon 0.1.0 (1111111)")  # resumed across commits
    text = write_experiment_report(plan, tmp_path / "report").read_text()
    assert "attempts ran with 2 commits (3333333, 1111111)" in text and "| t-dagger† |" in text
    assert entries() == {"DAgger": True, "DAgRL": True, "Missing": False}  # DAgRL starts from DAgger

    # a changed definition is refused before any work, with the fix
    with pytest.raises(DefinitionError, match="--redo"):
        run(
            resolve([load_experiment(str(exp_file))], "tiny", root, [*TINY_SET, "data.train_scenes=2"]), console=quiet()
        )


RESUME = """
title: resume test
paper_ref: none
train:
  r-ppo: {recipe: rl, scales: {tiny: {set: {max_updates: 10}}}}
evaluate:
  r-eval: {agent: policy, checkpoint: r-ppo, splits: [val_seen]}
table:
  caption: test
  columns: [{name: val_seen, split: val_seen}]
  rows: [{name: RL, eval: r-eval, paper: {val_seen: [39.2, 0.4, 18.7, 0.2]}}]
"""


@pytest.mark.slow
def test_a_training_cell_killed_after_update_k_continues_to_the_same_weights(tmp_path: Path) -> None:
    """Runs that outlast a sitting: SIGKILL the runner's process group (runner and `ovon train` child)
    once the training cell has checkpointed update 3 of 10; the same `ovon experiment run` continues it
    (`ovon train --resume`) to the weights of a run that was never interrupted."""
    from ovon.experiments.outputs import last_update
    from ovon.models.policy import ActorCritic

    exp_file = _write(tmp_path / "resume_exp.yaml", RESUME)
    root = tmp_path / "root"
    args = [
        "experiment",
        "run",
        str(exp_file),
        "--scale",
        "tiny",
        "--root",
        str(root),
        "--no-report",
        "--only",
        "train:r-ppo",
        *(a for s in TINY_SET for a in ("--set", s)),
    ]
    folder = root / "tiny" / "train" / "r-ppo"
    proc = subprocess.Popen(
        [sys.executable, "-m", "ovon.cli.main", *args],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        start_new_session=True,
    )
    deadline = time.time() + 400
    try:
        while time.time() < deadline:
            if (folder / "checkpoint.pt").is_file() and (last_update(folder) or 0) >= 3:
                break
            assert proc.poll() is None, proc.stdout.read().decode()
            time.sleep(0.1)
        else:
            pytest.fail("the training cell never reached update 3")
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    killed_at = last_update(folder)
    assert killed_at is not None and 3 <= killed_at < 10
    first_line = (folder / "metrics.jsonl").read_text().splitlines()[0]  # its "time" is the first attempt's
    rec = _record(root, "train:r-ppo")
    assert rec["state"] == "running" and rec["attempts"] == 1
    child = rec["pid"]
    for _ in range(50):
        if not _alive(child):
            break
        time.sleep(0.2)
    assert not _alive(child)

    from ovon.cli.main import main

    with contextlib.redirect_stdout(io.StringIO()) as out:
        assert main(args) == 0  # the same command continues the cell
    assert "--resume" in out.getvalue()
    rec = _record(root, "train:r-ppo")
    assert rec["state"] == "done" and rec["attempts"] == 2 and last_update(folder) == 10
    assert "--resume" in (root / "tiny" / "logs" / "train-r-ppo.log").read_text()
    assert (folder / "metrics.jsonl").read_text().splitlines()[0] == first_line  # continued, not restarted

    # the same cell never interrupted (another root, reading the first one's data)
    data = root / "tiny" / "data"
    straight = resolve(
        [load_experiment(str(exp_file))],
        "tiny",
        tmp_path / "straight",
        [*TINY_SET, "data.source=paths", f"data.episodes={data / 'episodes'}", f"data.scenes={data / 'scenes'}"],
    )
    assert run(straight, only=["train:r-ppo"], write_report=False, console=quiet()).ran == ["train:r-ppo"]
    assert _record(tmp_path / "straight", "train:r-ppo")["attempts"] == 1
    a = ActorCritic.load(folder / "policy.pt").state_dict()
    b = ActorCritic.load(tmp_path / "straight" / "tiny" / "train" / "r-ppo" / "policy.pt").state_dict()
    assert a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)


@pytest.mark.slow
def test_a_finished_training_cell_trains_further_when_its_budget_grows(tmp_path: Path) -> None:
    """A larger budget resumes the finished run (to the weights of a run given that budget from the start);
    its evaluation is refused until redone; a smaller budget is a change, never a cut."""
    from ovon.experiments.outputs import last_update
    from ovon.models.policy import ActorCritic

    def plan(root: Path, updates: int, *extra: str):
        # the evaluation named like its training (as in `main`): a bare `--redo r-ppo` would retrain
        text = RESUME.replace("max_updates: 10", f"max_updates: {updates}").replace("r-eval", "r-ppo")
        exp = _write(tmp_path / f"budget{updates}.yaml", text)
        return resolve([load_experiment(str(exp))], "tiny", root, [*TINY_SET, *extra])

    root = tmp_path / "root"
    first = run(plan(root, 3), only=["train:r-ppo", "eval:r-ppo"], write_report=False, console=quiet())
    assert first.ran == ["data:data", "train:r-ppo", "eval:r-ppo"] and first.ok
    longer = plan(root, 5)
    statuses = run(longer, dry_run=True, console=quiet()).statuses
    assert (statuses["train:r-ppo"].state, statuses["train:r-ppo"].detail) == (
        "partial",
        "to extend: max_updates 3 -> 5",
    )
    assert statuses["eval:r-ppo"].state == "changed" and "train:r-ppo, which it reads" in statuses["eval:r-ppo"].detail
    with pytest.raises(DefinitionError, match="fix: --redo eval:r-ppo recomputes"):
        run(longer, write_report=False, console=quiet())
    again = run(longer, redo_cells=["eval:r-ppo"], write_report=False, console=quiet())
    assert again.ran == ["train:r-ppo", "eval:r-ppo"] and again.ok
    folder = root / "tiny" / "train" / "r-ppo"
    assert last_update(folder) == 5 and _record(root, "train:r-ppo")["attempts"] == 2
    assert "--resume" in (root / "tiny" / "logs" / "train-r-ppo.log").read_text()
    data = root / "tiny" / "data"
    straight = plan(
        tmp_path / "straight",
        5,
        "data.source=paths",
        f"data.episodes={data / 'episodes'}",
        f"data.scenes={data / 'scenes'}",
    )
    assert run(straight, only=["train:r-ppo"], write_report=False, console=quiet()).ran == ["train:r-ppo"]
    a = ActorCritic.load(folder / "policy.pt").state_dict()
    b = ActorCritic.load(tmp_path / "straight" / "tiny" / "train" / "r-ppo" / "policy.pt").state_dict()
    assert a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)
    shorter = run(plan(root, 4), dry_run=True, console=quiet()).statuses["train:r-ppo"]
    assert shorter.state == "changed" and "max_updates 5 -> 4 (a finished training is never cut back)" in shorter.detail


def test_a_training_cell_may_take_another_recipe_and_init_at_a_scale(tmp_path: Path) -> None:
    """`rl` is two PPO phases at cpu scale (rl-warmup, then rl-continue from it) and the paper's one at paper
    scale, where the first phase is then no cell at all."""
    cpu = resolve([load_experiment("main")], "cpu", tmp_path)
    assert cpu.cells["train:rl"].deps == ("data:data", "train:rl-warmup")
    assert "--init" in cpu.cells["train:rl"].commands[0] and "--init" not in cpu.cells["train:rl-warmup"].commands[0]
    continued = "--set max_updates=" + str(cpu.cells["train:rl"].train_cfg.max_updates)
    assert cpu.cells["train:rl"].train_cfg.max_updates != cpu.cells["train:rl-warmup"].train_cfg.max_updates
    memory = resolve([load_experiment("memory")], "cpu", tmp_path)
    assert continued in " ".join(memory.cells["train:rl-lstm"].commands[0])
    paper = resolve([load_experiment("main")], "paper", tmp_path)
    assert paper.cells["train:rl"].deps == ("data:data",) and "train:rl-warmup" not in paper.cells
    assert "--init" not in paper.cells["train:rl"].commands[0]
    assert paper.cells["train:rl"].train_cfg.total_steps == 150_000_000
    bad = _write(tmp_path / "bad.yaml", RESUME.replace("{tiny: {set:", "{tiny: {init: ghost, set:"))
    with pytest.raises(DefinitionError, match="ghost"):
        resolve([load_experiment(str(bad))], "tiny", tmp_path)


def test_lock_keeps_a_second_process_off_a_running_cell(tmp_path: Path) -> None:
    from ovon.experiments.records import cell_lock, lock_holder
    from ovon.experiments.status import cell_status

    plan = resolve([load_experiment("main")], "cpu", tmp_path)
    cell = plan.cells["train:dagger"]
    lock = cell_lock(plan, cell)
    assert lock is not None
    code = (
        "import sys; from pathlib import Path; from ovon.experiments import resolve, load_experiment;"
        "from ovon.experiments.records import cell_lock;"
        f"p = resolve([load_experiment('main')], 'cpu', Path({str(tmp_path)!r}));"
        "sys.exit(0 if cell_lock(p, p.cells['train:dagger']) is None else 1)"
    )
    assert subprocess.run([sys.executable, "-c", code], cwd=ROOT).returncode == 0
    assert f"pid {os.getpid()}" in lock_holder(plan, cell)
    assert cell_status(plan, cell, {}).state == "running"
    lock.release()
    assert lock_holder(plan, cell) is None


def test_redo_moves_cells_aside_under_their_locks(tmp_path: Path) -> None:
    """--redo takes each cell's lock before moving anything (another runner could start a half-moved cell),
    and moves nothing when one of them is held."""
    from ovon.experiments.records import cell_lock, lock_holder
    from ovon.experiments.runner import redo

    plan = resolve([load_experiment("main")], "cpu", tmp_path)
    for cid in ("train:bc", "eval:bc"):
        plan.cells[cid].folder.mkdir(parents=True)
    held = cell_lock(plan, plan.cells["eval:bc"])
    with pytest.raises(DefinitionError, match=r"--redo: cell eval:bc is in use by pid \d+"):
        redo(plan, ["train:bc", "eval:bc"], quiet())
    assert plan.cells["train:bc"].folder.is_dir() and lock_holder(plan, plan.cells["train:bc"]) is None
    held.release()
    redo(plan, ["train:bc", "eval:bc"], quiet())
    assert not plan.cells["train:bc"].folder.exists() and (tmp_path / "cpu" / "train" / "bc.old-1").is_dir()
    assert lock_holder(plan, plan.cells["eval:bc"]) is None


@pytest.mark.slow
def test_main_at_tiny_scale_end_to_end(tmp_path: Path) -> None:
    """The whole `main` experiment at tiny scale (the modular rows stay "not run" until their agents exist),
    then extending the evaluation seeds re-runs only the evaluations."""
    from ovon.agents import BUILTIN

    plan = resolve([load_experiment("main")], "tiny", tmp_path)
    result = run(plan, console=quiet())
    assert result.ok
    want = {c for c in plan.cells if not (c.startswith("eval:") and plan.cells[c].eval_cell.agent not in BUILTIN)}
    assert {c for c, s in result.statuses.items() if s.state == "done"} == want
    more = resolve([load_experiment("main")], "tiny", tmp_path, ["evaluate.seeds=[0,1,2]"])
    again = run(more, console=quiet())
    assert again.ok and all(c.startswith("eval:") for c in again.ran) and again.ran
    text = (tmp_path / "tiny" / "reports" / "main" / "report.md").read_text()
    assert "x 3 seeds per entry" in text
    assert "  - episodes: **" in text and "a rule across splits (flat, drop)" in text  # finding (d)'s intervals
    redone = run(more, redo_cells=["train:bc"], console=quiet())  # BC, BC->RL and their evaluations again
    assert sorted(redone.ran) == ["eval:bc", "eval:bcrl", "train:bc", "train:bcrl"]
    assert (tmp_path / "tiny" / "train" / "bc.old-1" / "policy.pt").is_file()
    assert (tmp_path / "tiny" / "train" / "bc.old-1" / "experiment_record.json").is_file()


def test_within_noise_means_the_deciding_gaps_could_flip_the_verdict() -> None:
    """A finding that loses by 20 points is not "within noise" because another of its gaps is small; one that
    holds is, when any of its gaps is smaller than the two stds summed."""
    from ovon.experiments.definitions import Check
    from ovon.experiments.findings import judge_check

    table = {"dagrl": (20.0, 1.0), "bc": (19.5, 1.0), "rl": (40.0, 0.5), "dagger": (10.0, 0.5)}
    best = Check(kind="best", target="dagrl", others=("bc", "rl"))
    clear_loss = judge_check(best, lambda r, m: table[r])
    assert clear_loss["verdict"] == "does not hold" and not clear_loss["within_noise"]
    close_win = judge_check(Check(kind="best", target="dagrl", others=("bc", "dagger")), lambda r, m: table[r])
    assert close_win["verdict"] == "holds" and close_win["within_noise"]
    close_loss = judge_check(Check(kind="greater", pairs=(("bc", "dagrl"),)), lambda r, m: table[r])
    assert close_loss["verdict"] == "does not hold" and close_loss["within_noise"]
    flat = judge_check(Check(kind="flat", refs=("dagrl", "bc", "dagger"), tolerance=9.0), lambda r, m: table[r])
    assert flat["verdict"] == "does not hold" and flat["within_noise"]  # spread 10 vs 9, stds 1 + 0.5


def test_comparisons_on_the_same_episodes_get_a_paired_verdict_beside_the_two_std_rule() -> None:
    """Two runs 0.5 points apart are "within noise" by the std rule, yet on the same episodes the paired
    interval can show the gap; a pair without shared episodes (None) gets no paired verdict."""
    from ovon.experiments.definitions import Check
    from ovon.experiments.findings import judge_check

    table = {"dagrl": (20.0, 1.0), "dagger": (19.5, 1.0), "bc": (5.0, 1.0)}
    stats = {
        ("dagrl", "dagger"): {"diff": 0.5, "ci_low": 0.1, "ci_high": 0.9, "p": 0.01},
        ("dagrl", "bc"): {"diff": 15.0, "ci_low": -1.0, "ci_high": 30.0, "p": 0.2},
    }
    look = lambda r, m: table[r]  # noqa: E731
    shown = judge_check(Check(kind="greater", pairs=(("dagrl", "dagger"),)), look, lambda a, b, m: stats[(a, b)])
    assert shown["within_noise"] and shown["paired"]["verdict"] == "holds"
    assert "dagrl - dagger +0.5 [+0.1, +0.9]" in shown["paired"]["numbers"]
    wide = judge_check(Check(kind="best", target="dagrl", others=("dagger", "bc")), look, lambda a, b, m: stats[(a, b)])
    assert wide["paired"]["verdict"].startswith("not shown")
    assert "paired" not in judge_check(Check(kind="greater", pairs=(("dagrl", "bc"),)), look, lambda a, b, m: None)


def test_paired_difference_pairs_two_table_entries_on_their_shared_episodes() -> None:
    from ovon.experiments.report import paired_difference

    def recs(wins: list[int]) -> list[dict]:
        return [
            {"split": "val_seen", "seed": 0, "scene": "s", "episode_id": str(i), "success": bool(w), "spl": 0.5 * w}
            for i, w in enumerate(wins)
        ]

    evals = {"a": {"records": recs([1] * 20)}, "b": {"records": recs([0] * 20)}, "c": {"records": recs([1] * 5)}}
    a, b = {"eval": "a", "split": "val_seen"}, {"eval": "b", "split": "val_seen"}
    d = paired_difference(evals, a, b, "sr")
    assert d["diff"] == 100.0 and d["ci_low"] == 100.0 and d["p"] < 1e-5
    assert paired_difference(evals, a, {"eval": "c", "split": "val_seen"}, "sr") is None  # other episodes
    assert paired_difference(evals, a, {"eval": "b", "split": "val_unseen"}, "sr") is None  # other split


def test_a_greater_check_with_a_margin_needs_the_gap_beyond_it() -> None:
    from ovon.experiments.definitions import Check
    from ovon.experiments.findings import judge_check, rule_text

    chk = Check(kind="greater", pairs=(("A @ v", "B @ v"),), margin=5.0)
    assert rule_text(chk) == "SR of A @ v > B @ v + 5"
    values = {"A @ v": (30.0, 1.0), "B @ v": (24.0, 1.0)}
    assert judge_check(chk, lambda r, m: values[r])["verdict"] == "holds"  # +6 > 5, within noise (2 std)
    assert judge_check(chk, lambda r, m: values[r])["within_noise"]
    values["B @ v"] = (26.0, 0.5)  # +4: not beyond the margin
    assert judge_check(chk, lambda r, m: values[r])["verdict"] == "does not hold"
    paired = {"diff": 4.0, "ci_low": 1.0, "ci_high": 7.0, "p": 0.01}
    out = judge_check(chk, lambda r, m: values[r], lambda a, b, m: paired)
    assert out["paired"]["verdict"] == "not shown (an interval includes 5)"
    paired["mde"] = 8.25  # the detectable difference of those episodes: a verdict that is not shown names it
    out = judge_check(chk, lambda r, m: values[r], lambda a, b, m: paired)
    assert out["paired"]["verdict"] == "not shown (an interval includes 5; MDE 8.2 pts)"


def test_a_verdict_that_differs_from_the_papers_carries_its_reason_or_says_it_has_none() -> None:
    from ovon.experiments.definitions import Check, Finding
    from ovon.experiments.report import finding_result, findings_markdown

    f = Finding(id="q", claim="c", checks=(Check(kind="greater", pairs=(("A @ v", "B @ v"),)),), differs={"cpu": "S."})
    holds, fails, missing = (
        {"verdict": v, "within_noise": False, "checks": []} for v in ("holds", "does not hold", "not run")
    )
    assert finding_result(f, fails, holds, "cpu", "x.yaml")["differs"] == "S."
    unexplained = finding_result(f, fails, holds, "paper", "x.yaml")["differs"]
    assert unexplained.startswith("not explained yet") and "finding q in x.yaml" in unexplained
    assert "differs" not in finding_result(f, holds, holds, "cpu", "x.yaml")  # agrees: nothing to explain
    assert "differs" not in finding_result(f, missing, holds, "cpu", "x.yaml")  # not judged yet
    text = "\n".join(findings_markdown([finding_result(f, fails, holds, "cpu", "x.yaml")]))
    assert "here **does not hold**; paper: holds." in text and "why it differs from the paper's: S." in text


def test_a_why_sentence_quotes_this_runs_numbers_not_copies() -> None:
    from ovon.experiments.findings import fill_sentence

    values = {"A @ v": (15.04, 1.2), "B @ v": (10.2, 2.4), "C @ v": None}
    look = values.get
    text = "A {A @ v} vs B {B @ v}: {A @ v - B @ v}; C {C @ v}, {C @ v - A @ v}; {kept} {{"
    assert fill_sentence(text, lambda r, m: look(r)) == "A 15.0 vs B 10.2: +4.8; C (not run), (not run); {kept} {{"
    paired = {"diff": 4.8, "ci_low": 0.5, "ci_high": 9.0, "p": 0.03}
    filled = fill_sentence("{A @ v - B @ v}", lambda r, m: look(r), lambda a, b, m: paired if a == "A @ v" else None)
    assert filled == "+4.8 [+0.5, +9.0]"  # paired where the two ran the same episodes


def test_a_killed_attempt_without_a_time_is_named_beside_the_wall_time(tmp_path: Path) -> None:
    """Records from before the estimate hold a killed attempt with no time: the sum is a lower bound."""
    assert wall_text({"wall_min": 5.5, "untimed": 0}) == "5.5"
    assert wall_text({"wall_min": 5.5, "untimed": 1}) == "5.5 (+ 1 killed attempt, time not recorded)"
    assert wall_text({"wall_min": 5.5, "untimed": 2}).endswith("(+ 2 killed attempts, time not recorded)")
    log = tmp_path / "cell.log"
    log.write_text("===== x\n")
    started = time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(log.stat().st_mtime - 90))
    assert killed_wall_s(started, log) == pytest.approx(90, abs=1.5)
    assert killed_wall_s(started, tmp_path / "missing.log") is None
    assert killed_wall_s(None, log) is None and killed_wall_s("garbage", log) is None
    later = time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(log.stat().st_mtime + 3600))
    assert killed_wall_s(later, log) is None


def test_table_marks_entries_whose_seeds_repeat_one_run() -> None:
    from ovon.experiments.findings import SAME_SEEDS, SAME_SEEDS_NOTE

    ours = {"sr": (82.0, 0.0), "spl": (40.0, 0.0), "episodes": 400, "seeds": 4}
    row = {"name": "VLFM", "setup": "oracle", "cells": {"val_seen": {"ours": ours, "paper": None, "eval": "vlfm"}}}
    table = {"columns": ["val_seen"], "rows": [row]}
    assert SAME_SEEDS not in "\n".join(table_markdown(table))
    ours["seeds_identical"] = True
    text = "\n".join(table_markdown(table))
    assert f"**82.0{SAME_SEEDS}** (paper –)" in text and SAME_SEEDS_NOTE in text and "± 0.0" not in text
    # 100 distinct episodes (400 records over 4 seeds): the table names what they can detect
    assert "100 episodes x 4 seeds per entry" in text and "detects an SR difference of 28.0 points at worst" in text
    ours["seeds"], ours["episodes"] = 1, 100
    assert "**82.0 (1 seed)** (paper –)" in "\n".join(table_markdown(table))
