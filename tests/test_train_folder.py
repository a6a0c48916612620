"""`ovon.train.train(...)` owns its run folder: the Python API refuses a second writer, a resume with other
settings or other episodes, and a second run in a used folder, exactly like `ovon train`."""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys
import zlib
from pathlib import Path

import numpy as np
import pytest
import torch

torch.set_num_threads(1)

from ovon.runfolder import RunFolderError  # noqa: E402
from ovon.train import EpisodeSource, train  # noqa: E402
from ovon.train.config import train_preset  # noqa: E402
from ovon.train.episodes import adhoc_specs  # noqa: E402
from ovon.train.folder import specs_sha256  # noqa: E402
from ovon.train.logging import read_metrics  # noqa: E402
from ovon.train.text import needed_texts, write_text_table  # noqa: E402
from tests.test_train import write_synthetic_shards  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture()
def bc_cfg(tmp_path: Path):
    shards = write_synthetic_shards(tmp_path / "shards")
    cfg = train_preset("tiny", algo="bc", max_updates=2, checkpoint_every=1)
    return dataclasses.replace(cfg, bc=dataclasses.replace(cfg.bc, shards=str(shards), batch_chunks=3))


def test_python_api_writes_the_identity_and_refuses_a_used_folder(tmp_path: Path, bc_cfg) -> None:
    out = tmp_path / "run"
    train(bc_cfg, None, out)
    ident = json.loads((out / "run_identity.json").read_text())
    assert ident["kind"] == "train" and ident["config"]["algo"] == "bc"
    assert "max_updates" not in ident["config"]  # may change on resume: not part of what the run is
    assert json.loads((out / "config.json").read_text())["max_updates"] == 2
    assert not (out / ".lock").exists()  # released when train() returns
    with pytest.raises(RunFolderError, match="already holds a train run; fix: pass --resume"):
        train(bc_cfg, None, out)


def test_python_api_refuses_a_mismatched_resume_and_allows_a_longer_one(tmp_path: Path, bc_cfg) -> None:
    out = tmp_path / "run"
    train(bc_cfg, None, out)
    other = dataclasses.replace(bc_cfg, lr=bc_cfg.lr * 2)
    with pytest.raises(RunFolderError, match=r"settings differ: lr "):
        train(other, None, out, resume=True)
    assert len(read_metrics(out)) == 2  # nothing was written by the refused call
    train(dataclasses.replace(bc_cfg, max_updates=3), None, out, resume=True)  # a budget may grow
    assert len(read_metrics(out)) == 3


def test_python_api_refuses_a_second_writer(tmp_path: Path, bc_cfg) -> None:
    out = tmp_path / "run"
    train(bc_cfg, None, out)
    holder = subprocess.Popen(  # another process holding the folder, as a running `train` does
        [
            sys.executable,
            "-c",
            "import sys, time\nfrom ovon.runfolder import FileLock\n"
            f"lock = FileLock({str(out / '.lock')!r})\nprint('held', flush=True)\ntime.sleep(60)",
        ],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert holder.stdout is not None and holder.stdout.readline().strip() == "held"
        with pytest.raises(RunFolderError, match="is in use by another ovon process"):
            train(dataclasses.replace(bc_cfg, max_updates=3), None, out, resume=True)
    finally:
        holder.kill()
        holder.wait()
    assert len(read_metrics(out)) == 2


def test_python_api_refuses_resuming_with_other_episodes(tmp_path: Path) -> None:
    specs = adhoc_specs([0], categories=["bed", "toilet"])
    table = tmp_path / "table.pt"
    write_text_table(
        table,
        {
            t: np.random.default_rng(zlib.crc32(t.encode())).standard_normal(16).astype(np.float32)
            for t in needed_texts(adhoc_specs([0]))
        },
    )
    cfg = train_preset(
        "tiny", algo="dagger", expert="shortest-path", num_envs=1, rollout_steps=4, max_updates=1, text_cache=str(table)
    )
    out = tmp_path / "dagger"
    train(cfg, specs, out)
    assert json.loads((out / "run_identity.json").read_text())["inputs"]["episodes"]["sha256"] == specs_sha256(specs)
    with pytest.raises(RunFolderError, match=r"settings differ: inputs\.episodes\.sha256"):
        train(cfg, specs[:1], out, resume=True)
    assert len(read_metrics(out)) == 1


def test_episode_source_is_what_the_command_line_records(tmp_path: Path) -> None:
    """`ovon train --procedural 0 --episodes 2` = `train(cfg, EpisodeSource(procedural="0", limit=2), out)`."""
    src = EpisodeSource(procedural="0", limit=2)
    assert [s.episode_id for s in src.load()] == [s.episode_id for s in adhoc_specs([0])[:2]]
    config, inputs = src.identity()
    assert config == {"cli": {"split": "train", "episodes": 2, "procedural": "0"}} and inputs == {}
    with pytest.raises(ValueError, match="--data needs --scenes"):
        EpisodeSource(data=str(tmp_path)).load()
    with pytest.raises(ValueError, match="dagger needs episodes"):
        train(train_preset("tiny", algo="dagger"), EpisodeSource(), tmp_path / "none")
    assert not (tmp_path / "none").exists()  # refused before the folder is made
