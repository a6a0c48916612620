"""Experiment provenance: reports name no path of the machine they ran on (`$ROOT`, `$EPISODES`,
`$SCENES`, pasteable in a shell), a preset changed in code makes a finished cell stale (its resolved
config is recorded), and records written before either stay readable."""

from __future__ import annotations

import dataclasses
import io
import json
import os
import re
import shlex
import shutil
import subprocess
from pathlib import Path

import pytest
from rich.console import Console

from ovon.experiments import DefinitionError, load_experiment, resolve, run, write_experiment_report
from ovon.experiments.identity import config_unknown, resolved_config
from ovon.experiments.inputs import inputs
from ovon.experiments.plan import display
from ovon.experiments.provenance import parse_code
from ovon.experiments.records import record_path, write_record
from ovon.experiments.report import run_command_line
from ovon.experiments.status import cell_status
from ovon.experiments.tokens import full_commands, shell_word


def _plan(root: Path, data: Path, scenes: Path, experiment: str = "noise"):
    """An experiment at cpu scale reading a dataset outside its root (`data.source: paths`)."""
    return resolve(
        [load_experiment(experiment)],
        "cpu",
        root,
        ["data.source=paths", f"data.episodes={data}", f"data.scenes={scenes}"],
    )


def _done(plan, cid: str, **extra) -> None:
    """A finished cell as the runner records it (outputs present, inputs as they are now)."""
    cell = plan.cells[cid]
    cell.folder.mkdir(parents=True, exist_ok=True)
    (cell.folder / ("policy.pt" if cell.kind == "train" else "summary.json")).write_text("{}")
    rec = {
        "kind": cell.kind,
        "name": cell.name,
        "state": "done",
        "attempts": 1,
        "rc": 0,
        "wall_s": 60.0,
        "commands": full_commands(plan, cell),
        "inputs": inputs(plan, cell),
        "code": "ovon 0.1.0 (abc1234)",
        "config": resolved_config(plan, cell),
    }
    rec.update(extra)
    write_record(plan, cell, {k: v for k, v in rec.items() if v is not ...})


def test_commands_in_reports_name_no_path_of_the_machine_and_paste_into_a_shell(
    tmp_path, tiny_dataset, tiny_scenes
) -> None:
    root = tmp_path / "runs" / "exp"
    plan = _plan(root, tiny_dataset, tiny_scenes)
    write_experiment_report(plan, tmp_path / "report")
    text = (tmp_path / "report" / "report.md").read_text()
    data = (tmp_path / "report" / "report.json").read_text()
    for leaked in (str(tmp_path), str(tiny_dataset), str(tiny_scenes)):
        assert leaked not in text and leaked not in data
    assert "--out $ROOT/cpu/train/dagrl" in text and "--data $EPISODES --scenes $SCENES" in text
    again = run_command_line(plan)
    assert again == (
        "ovon experiment run noise --scale cpu --root $ROOT --set data.source=paths "
        "--set data.episodes=$EPISODES --set data.scenes=$SCENES"
    )
    assert f"all of them: `{again}`" in text
    assert "Provenance: no cell has finished yet" in text
    # pasted after ROOT=... EPISODES=... SCENES=..., every command is the one the runner executes
    env = {**os.environ, "ROOT": str(root), "EPISODES": str(tiny_dataset), "SCENES": str(tiny_scenes)}
    for cell in plan.cells.values():
        for argv, shown in zip(cell.commands, full_commands(plan, cell)):
            words = (
                subprocess.run(["bash", "-c", "printf '%s\\0' " + shown], env=env, capture_output=True, check=True)
                .stdout.decode()
                .split("\0")[:-1]
            )
            assert words == shlex.split(display(cell, argv)), cell.id
    # a root with a space and a dataset inside the root
    spaced = tmp_path / "my runs"
    plan = resolve([load_experiment("noise")], "tiny", spaced)
    cmd = full_commands(plan, plan.cells["data:data"])[-1]
    assert "--out $ROOT/tiny/data/episodes" in cmd and str(spaced) not in cmd
    assert shell_word("$ROOT/a b") == '"$ROOT/a b"' and shell_word("$HOME/x") == "'$HOME/x'"
    assert shell_word("text_cache=$ROOT/x") == "text_cache=$ROOT/x" and shell_word("a'b") == shlex.quote("a'b")
    assert run_command_line(plan) == "ovon experiment run noise --scale tiny --root $ROOT"


def test_records_from_before_configs_stay_done_compare_their_run_folder_and_the_runner_says_so_once(
    tmp_path, tiny_dataset, tiny_scenes
) -> None:
    from ovon.config.base import to_dict
    from ovon.runfolder import IDENTITY_FILE, RunFolder

    root = tmp_path / "root"
    plan = _plan(root, tiny_dataset, tiny_scenes)
    cell = plan.cells["train:dagger"]
    _done(plan, "train:dagger", config=...)  # the old form: no resolved config recorded
    assert "config" not in json.loads(record_path(plan, cell).read_text())
    assert cell_status(plan, cell, {}).state == "done"
    assert config_unknown(plan, list(plan.cells)) == ["train:dagger"]
    out = io.StringIO()
    run(plan, dry_run=True, console=Console(file=out, width=300))
    text = out.getvalue()
    assert text.count("ran before ovon recorded resolved configs (train:dagger)") == 1
    assert re.search(r"^train:dagger +done \(1.0 min\)$", text, re.M)
    # such a record is compared with its run folder's identity, which names the difference
    with RunFolder.open(cell.folder, "train", {**to_dict(cell.train_cfg), "expert": "shortest-path"}):
        pass
    assert cell_status(plan, cell, {}).detail == (
        'its resolved config changed since it ran: expert "shortest-path" -> "frontier"'
    )
    (cell.folder / IDENTITY_FILE).unlink()
    write_experiment_report(plan, tmp_path / "report")
    assert (
        "| train:dagger | done | abc1234 | clean | not recorded (run folder compared) |  |"
        in (tmp_path / "report" / "report.md").read_text()
    )


def test_a_preset_changed_in_code_makes_a_finished_cell_stale(tmp_path, tiny_dataset, tiny_scenes, monkeypatch) -> None:
    import ovon.agents.modular.vlfm as vlfm
    import ovon.config.dataset as gen
    import ovon.train.config as train_config

    root = tmp_path / "root"
    plan = _plan(root, tiny_dataset, tiny_scenes)
    _done(plan, "train:dagger")
    _done(plan, "eval:vlfm")
    rec = json.loads(record_path(plan, plan.cells["eval:vlfm"]).read_text())
    assert rec["config"]["agent_config"]["spin_steps"] == 12 and rec["config"]["sim"]["camera"]["width"] == 72
    assert json.loads(record_path(plan, plan.cells["train:dagger"]).read_text())["config"]["text_cache"] == (
        "$ROOT/cpu/data/text_cache.pt"
    )
    assert {
        c: s.state
        for c, s in run(plan, dry_run=True, console=Console(file=io.StringIO())).statuses.items()
        if c in ("train:dagger", "eval:vlfm")
    } == {"train:dagger": "done", "eval:vlfm": "done"}
    # more seeds or episodes extend an evaluation: not a change of its config
    more = resolve(
        [load_experiment("noise")],
        "cpu",
        root,
        ["data.source=paths", f"data.episodes={tiny_dataset}", f"data.scenes={tiny_scenes}", "evaluate.seeds=[0,1,2]"],
    )
    assert cell_status(more, more.cells["eval:vlfm"], {}).state == "partial"
    # moving the dataset changes nothing: its path is a token, its content is the input
    moved = tmp_path / "elsewhere"
    tiny_dataset.rename(moved)
    try:
        elsewhere = _plan(root, moved, tiny_scenes)
        assert [cell_status(elsewhere, elsewhere.cells[c], {}).state for c in ("train:dagger", "eval:vlfm")] == [
            "done",
            "done",
        ]
    finally:
        moved.rename(tiny_dataset)

    # the cpu-small preset's DAgger schedule changes in code: the command line is the same, the config is not
    cpu_small = train_config.PRESETS["cpu-small"]
    monkeypatch.setitem(
        train_config.PRESETS,
        "cpu-small",
        lambda: dataclasses.replace(cpu_small(), dagger=dataclasses.replace(cpu_small().dagger, beta_updates=7)),
    )
    # and VLFM's preset
    make = vlfm.modular_config
    monkeypatch.setattr(
        vlfm, "modular_config", lambda cls, preset, over: dataclasses.replace(make(cls, preset, over), spin_steps=3)
    )
    now = _plan(root, tiny_dataset, tiny_scenes)
    assert now.cells["train:dagger"].commands == plan.cells["train:dagger"].commands
    st = cell_status(now, now.cells["train:dagger"], {})
    assert (
        st.state == "changed" and st.detail == "its resolved config changed since it ran: dagger.beta_updates 200 -> 7"
    )
    assert cell_status(now, now.cells["eval:vlfm"], {}).detail.endswith("agent_config.spin_steps 12 -> 3")
    with pytest.raises(DefinitionError) as err:
        run(now, console=Console(file=io.StringIO()))
    msg = str(err.value)
    assert "changed since they ran" in msg and "dagger.beta_updates 200 -> 7" in msg and "--redo dagger," in msg
    assert "\n" not in msg
    # --redo moves the stale cells (and what depends on them) aside
    res = run(now, redo_cells=["dagger", "vlfm"], dry_run=True, console=Console(file=io.StringIO()))
    assert res.statuses["train:dagger"].state == "redo" and res.statuses["eval:vlfm"].state == "redo"

    # the generation preset of generated data (tiny scale) is part of the data cell's config
    tiny = resolve([load_experiment("noise")], "tiny", root)
    write_record(
        tiny,
        tiny.cells["data:data"],
        {
            "state": "done",
            "config": resolved_config(tiny, tiny.cells["data:data"]),
        },
    )
    assert cell_status(tiny, tiny.cells["data:data"], {}).state != "changed"
    fast = gen.GENERATION_PRESETS["fast"]
    monkeypatch.setitem(
        gen.GENERATION_PRESETS,
        "fast",
        lambda: dataclasses.replace(fast(), starts=dataclasses.replace(fast().starts, max_tries=99)),
    )
    tiny = resolve([load_experiment("noise")], "tiny", root)  # the cells' configs are resolved with the plan
    st = cell_status(tiny, tiny.cells["data:data"], {})
    assert st.state == "changed" and "starts.max_tries 2000 -> 99" in st.detail


def test_parse_code() -> None:
    assert parse_code("ovon 0.1.0 (abc1234+dirty)") == {
        "version": "ovon 0.1.0",
        "commit": "abc1234",
        "dirty": True,
        "text": "ovon 0.1.0 (abc1234+dirty)",
    }
    assert parse_code("ovon 0.1.0")["commit"] is None and not parse_code("ovon 0.1.0")["dirty"]
    assert parse_code("")["version"] == ""


def test_what_reads_a_changed_cell_is_changed_too(tmp_path, tiny_dataset, tiny_scenes, monkeypatch) -> None:
    """A DAgger whose config changed makes the DAgRL fine-tuned from it, and that one's evaluation, stale
    (they used to stay "done", and a report showed their numbers as current)."""
    import ovon.train.config as train_config

    root = tmp_path / "root"
    plan = _plan(root, tiny_dataset, tiny_scenes)
    for cid in ("train:dagger", "train:dagrl", "eval:dagrl-od"):
        _done(plan, cid)
    quiet = Console(file=io.StringIO())
    before = run(plan, dry_run=True, console=quiet).statuses
    assert [before[c].state for c in ("train:dagger", "train:dagrl", "eval:dagrl-od")] == ["done"] * 3
    cpu_small = train_config.PRESETS["cpu-small"]
    monkeypatch.setitem(
        train_config.PRESETS,
        "cpu-small",
        lambda: dataclasses.replace(cpu_small(), dagger=dataclasses.replace(cpu_small().dagger, beta_updates=7)),
    )
    now = run(_plan(root, tiny_dataset, tiny_scenes), dry_run=True, console=quiet).statuses
    assert now["train:dagger"].state == "changed" and now["train:dagrl"].state == "changed"
    assert (now["eval:dagrl-od"].state, now["eval:dagrl-od"].detail) == (
        "changed",
        "train:dagrl, which it reads, changed since it ran",
    )


def test_a_cells_identity_is_its_config_not_its_command_words(tmp_path) -> None:
    """A data cell's `--workers` (generation is the same with any number) leaves it done; another episode
    count or scene count makes it changed, named by its config key."""
    plan = resolve([load_experiment("noise")], "tiny", tmp_path)
    data = plan.cells["data:data"]
    write_record(plan, data, {"state": "done", "config": resolved_config(plan, data)})
    (plan.episodes_dir / "train").mkdir(parents=True)
    (plan.episodes_dir / "train" / "train.json.gz").write_bytes(b"{}")

    def status(*sets: str):
        now = resolve([load_experiment("noise")], "tiny", tmp_path, list(sets))
        return cell_status(now, now.cells["data:data"], {})

    assert status().state == "done" and status("data.workers=3").state == "done"
    assert status("data.set={episodes_per_val_split: 5}").detail.startswith(
        "its resolved config changed since it ran: episodes_per_train_scene 8 -> 60"
    )
    assert status("data.train_scenes=2").detail.endswith("scene_generation.train_scenes 1 -> 2")


def test_another_scene_dataset_at_the_same_path_makes_finished_cells_stale(tmp_path, tiny_dataset, tiny_scenes) -> None:
    """The scenes are an input like the episodes: a file of another size under the scenes root (another
    release copied over it) makes what read them stale; records from before scenes were recorded stay done."""
    scenes = tmp_path / "scenes"
    shutil.copytree(tiny_scenes, scenes, symlinks=False)
    plan = _plan(tmp_path / "root", tiny_dataset, scenes)
    _done(plan, "eval:vlfm")
    _done(plan, "eval:vlfm-noise", inputs={"data": inputs(plan, plan.cells["eval:vlfm-noise"])["data"]})
    assert cell_status(plan, plan.cells["eval:vlfm"], {}).state == "done"
    victim = next(p for p in sorted(scenes.rglob("*")) if p.is_file())
    victim.write_bytes(victim.read_bytes() + b"\0")
    st = cell_status(plan, plan.cells["eval:vlfm"], {})
    assert (st.state, st.detail) == ("changed", "its input(s) scenes changed since it ran")
    assert cell_status(plan, plan.cells["eval:vlfm-noise"], {}).state == "done"


def test_an_episode_file_edited_to_the_same_size_makes_finished_cells_stale(tmp_path, tiny_dataset, tiny_scenes):
    """The episodes' content is an input (names and sizes alone missed a same-size edit); the hashes persist
    in the scale folder by size and mtime, so a later status pass reads no file again."""
    from ovon.experiments import inputs as state

    data = tmp_path / "episodes"
    shutil.copytree(tiny_dataset, data)
    plan = _plan(tmp_path / "root", data, tiny_scenes)
    _done(plan, "eval:vlfm")
    _done(plan, "eval:vlfm-noise", inputs={"data": inputs(plan, plan.cells["eval:vlfm-noise"])["data"]})
    cache = plan.base / state.HASH_CACHE
    assert cache.is_file() and len(json.loads(cache.read_text())) == len(state.episode_files(data))
    victim = state.episode_files(data)[0]
    body = bytearray(victim.read_bytes())
    body[len(body) // 2] ^= 0xFF  # another byte, the same size
    victim.write_bytes(bytes(body))
    st = cell_status(plan, plan.cells["eval:vlfm"], {})
    assert (st.state, st.detail) == ("changed", "its input(s) episodes changed since it ran")
    assert cell_status(plan, plan.cells["eval:vlfm-noise"], {}).state == "done"  # recorded names and sizes only
    # the persisted hash is what a later pass uses while size and mtime hold
    state._HASHES.clear()
    entries = json.loads(cache.read_text())
    entry = entries[str(victim)]
    entries[str(victim)] = [entry[0], entry[1], "0" * 64]
    cache.write_text(json.dumps(entries))
    before = state.episodes_content_fingerprint(plan)
    state._HASHES.clear()
    os.utime(victim, ns=(victim.stat().st_atime_ns, victim.stat().st_mtime_ns + 1))
    assert state.episodes_content_fingerprint(plan) != before  # a new mtime: read again


def test_the_generators_hidden_cache_is_not_an_input_and_records_that_hashed_it_stay_done(
    tmp_path, tiny_dataset, tiny_scenes
) -> None:
    """`dataset generate` keeps goal caches in `<episodes>/.cache/`: growing or deleting them makes nothing
    stale. Records written while the fingerprints still hashed them compare by that older reckoning."""
    from ovon.experiments import inputs as state

    data = tmp_path / "episodes"
    shutil.copytree(tiny_dataset, data)
    hidden = data / ".cache" / "goals" / "another-scene.json.gz"  # beside the fixture's own cache
    hidden.parent.mkdir(parents=True, exist_ok=True)
    hidden.write_bytes(b"cache v1")
    plan = _plan(tmp_path / "root", data, tiny_scenes)
    legacy = {"data": state.data_fingerprint(plan, hidden=True)}
    legacy["episodes"] = state.episodes_content_fingerprint(plan, hidden=True)
    assert legacy["episodes"] != state.episodes_content_fingerprint(plan)
    _done(plan, "eval:vlfm")
    _done(plan, "eval:vlfm-noise", inputs={**inputs(plan, plan.cells["eval:vlfm-noise"]), **legacy})
    for cid in ("eval:vlfm", "eval:vlfm-noise"):
        assert cell_status(plan, plan.cells[cid], {}).state == "done"
    hidden.write_bytes(b"cache v2, longer")  # the cache regrown: new cells are unaffected
    assert cell_status(plan, plan.cells["eval:vlfm"], {}).state == "done"
    st = cell_status(plan, plan.cells["eval:vlfm-noise"], {})  # an old record hashed the old cache
    assert (st.state, st.detail) == ("changed", "its input(s) data, episodes changed since it ran")
    shutil.rmtree(data / ".cache")
    assert cell_status(plan, plan.cells["eval:vlfm"], {}).state == "done"
    victim = state.episode_files(data)[0]  # a real episode file still counts
    victim.write_bytes(victim.read_bytes() + b"\0")
    assert cell_status(plan, plan.cells["eval:vlfm"], {}).state == "changed"


def test_a_cell_whose_code_changed_while_it_ran_ran_with_both(tmp_path, monkeypatch) -> None:
    """The code is read when an attempt starts and when it ends: a tree edited meanwhile, or a new untracked
    module in the package, is not "a clean tree"."""
    import ovon
    from ovon.experiments.provenance import attempt_codes, code_version

    record = {
        "code": "ovon 0.1.0 (abc1234)",
        "code_end": "ovon 0.1.0 (abc1234+dirty)",
        "history": [{"code": "ovon 0.1.0 (abc1234)", "code_end": "ovon 0.1.0 (abc1234+dirty)"}],
    }
    assert attempt_codes(record) == ["ovon 0.1.0 (abc1234)", "ovon 0.1.0 (abc1234+dirty)"]
    repo = tmp_path / "repo"
    (repo / "pkg").mkdir(parents=True)
    (repo / "pkg" / "__init__.py").write_text("")

    def git(*a: str) -> None:
        # the user's git config (commit signing, hooks) must not decide this test
        subprocess.run(
            ["git", "-C", str(repo), "-c", "commit.gpgsign=false", "-c", "core.hooksPath=/dev/null", *a],
            check=True,
            capture_output=True,
            env={
                **os.environ,
                "GIT_AUTHOR_NAME": "t",
                "GIT_AUTHOR_EMAIL": "t@t",
                "GIT_COMMITTER_NAME": "t",
                "GIT_COMMITTER_EMAIL": "t@t",
                "GIT_CONFIG_GLOBAL": os.devnull,
                "GIT_CONFIG_NOSYSTEM": "1",
            },
        )

    git("init", "-q")
    git("add", "-A")
    git("commit", "-qm", "x")
    monkeypatch.setattr(ovon, "__file__", str(repo / "pkg" / "__init__.py"))
    assert not code_version().endswith("+dirty)")
    (repo / "pkg" / "new_agent.py").write_text("X = 1\n")
    assert code_version().endswith("+dirty)")


def test_an_interrupted_cell_whose_input_changed_is_changed_not_failed(tmp_path, tiny_dataset, tiny_scenes) -> None:
    """An evaluation interrupted before its policy was retrained cannot resume (the run folder refuses the new
    checkpoint): it says "changed" (the fix: --redo), not "failed" on every run."""
    plan = _plan(tmp_path / "root", tiny_dataset, tiny_scenes)
    _done(plan, "train:dagrl")
    cell = plan.cells["eval:dagrl-od"]
    cell.folder.mkdir(parents=True)
    write_record(
        plan,
        cell,
        {
            "kind": "eval",
            "name": cell.name,
            "state": "failed",
            "rc": "interrupted",
            "config": resolved_config(plan, cell),
            "inputs": inputs(plan, cell),
        },
    )
    statuses = {
        "data:data": cell_status(plan, plan.cells["data:data"], {}),
        "train:dagrl": cell_status(plan, plan.cells["train:dagrl"], {}),
    }
    assert cell_status(plan, cell, statuses).state == "failed"
    (plan.cells["train:dagrl"].folder / "policy.pt").write_text('{"retrained": 1}')
    st = cell_status(plan, cell, statuses)
    assert (st.state, st.detail) == ("changed", "its input(s) train:dagrl changed since its last attempt")
