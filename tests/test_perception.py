"""`ovon perception pretrain` / `evaluate` and the three roles of the weights it writes: one tiny pretraining
(module fixture, through the CLI) serves every test, so the file stays fast."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import torch

from ovon.dataset.io import VAL_SPLITS
from tests.cli_errors import one_line, run

torch.set_num_threads(1)


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    from ovon.cli.main import main as ovon

    out = tmp_path_factory.mktemp("perception") / "pretrain"
    assert ovon(["perception", "pretrain", "--out", str(out), "--preset", "tiny", "--no-progress"]) == 0
    assert (out / "world_vl.safetensors").is_file()
    return out


@pytest.fixture(scope="module")
def frame(tiny_run):
    """The frames of one pretrain house (rendered by the pretraining itself), with their labels."""
    from ovon.perception.frames import HouseFrames

    return HouseFrames.load(sorted((tiny_run / "frames").glob("*.npz"))[0])


def test_pretrain_writes_weights_and_resume_refuses_another_config(tiny_run, capsys):
    from ovon.models.world import load_world_vl
    from ovon.models.world.net import POOLINGS

    model = load_world_vl(tiny_run / "world_vl.safetensors")
    assert model.pooling in POOLINGS and 0.0 <= model.threshold <= 1.0 and model.source.endswith("safetensors")
    assert load_world_vl(tiny_run) is model  # the run folder names the same file
    rc, _, err = run(["perception", "pretrain", "--out", str(tiny_run), "--preset", "tiny", "--resume",
                      "--set", "steps=7", "--no-progress"], capsys)  # fmt: skip
    one_line(rc, err, str(tiny_run))
    rc, _, err = run(["perception", "pretrain", "--out", str(tiny_run / "x"), "--set", "lr=0"], capsys)
    one_line(rc, err, "lr")


def test_the_roles_run_on_a_frame_and_read_no_ground_truth(tiny_run, frame):
    from ovon.models.config import DetectorConfig, ScorerConfig
    from ovon.models.world.roles import WorldOWLDetector, WorldVLEncoder, WorldVLScorer

    ckpt = str(tiny_run / "world_vl.safetensors")
    rgb = frame.rgb[0]
    obs = {"rgb": rgb}  # no "privileged" key: a role reading ground truth would fail here
    enc = WorldVLEncoder(checkpoint=ckpt)
    emb = enc.encode(obs)
    assert emb.shape == (1, enc.dim) and torch.isfinite(emb).all()
    scorer = WorldVLScorer(ScorerConfig(kind="world-vl", checkpoint=ckpt))
    assert 0.0 <= scorer.score(obs, "chair") <= 1.0
    # threshold 0: every cell passes, so there is a detection whose box must lie inside the frame
    det = WorldOWLDetector(DetectorConfig(kind="world-owl", checkpoint=ckpt, world_threshold=0.0))
    found = det.detect(obs, "chair")
    H, W = rgb.shape[:2]
    assert found
    for d in found:
        x0, y0, x1, y1 = d.box
        assert 0 <= x0 < x1 <= W and 0 <= y0 < y1 <= H and d.mask.shape == (H, W)
    for role in (enc, scorer, det):
        assert getattr(role, "privileged", False) is False, role


def test_evaluate_scores_are_the_detector_decisions(tiny_run, frame):
    """The evaluation scores frames in batches; its decisions must be those of `WorldOWLDetector.detect`."""
    from ovon.models.config import DetectorConfig
    from ovon.models.encoders.text import MiniLMText
    from ovon.models.world import load_world_vl
    from ovon.models.world.roles import WorldOWLDetector
    from ovon.perception.evaluate import world_scores

    goals = ["chair", "bed", "sofa"]
    text = torch.nn.functional.normalize(MiniLMText().encode(goals).float(), dim=-1)
    scores, glob = world_scores(load_world_vl(tiny_run), frame, text)
    assert scores.shape == glob.shape == (len(frame.rgb), len(goals))
    s = np.unique(scores)
    thr = float((s[len(s) // 2 - 1] + s[len(s) // 2]) / 2)  # between two scores: both decisions occur
    det = WorldOWLDetector(DetectorConfig(kind="world-owl", checkpoint=str(tiny_run), world_threshold=thr))
    for f in range(len(frame.rgb)):
        for j, g in enumerate(goals):
            assert bool(det.detect({"rgb": frame.rgb[f]}, g)) == (scores[f, j] >= thr), (f, g)


def test_evaluate_on_the_val_splits(tiny_run, tiny_dataset, tiny_scenes, tmp_path, capsys):
    out = tmp_path / "eval"
    argv = ["perception", "evaluate", "--data", str(tiny_dataset), "--scenes", str(tiny_scenes), "--out", str(out),
            "--checkpoint", str(tiny_run), "--frames-per-house", "12", "--houses", "1", "--no-progress"]  # fmt: skip
    rc, stdout, err = run(argv, capsys)
    assert rc == 0, err
    assert "ORACLE DETECTION" in stdout and "perception.json" in stdout
    report = json.loads((out / "perception.json").read_text())
    assert set(report["splits"]) == set(VAL_SPLITS)
    for split in report["splits"].values():
        assert len(split["houses"]) == 1 and split["pairs"] == 12 * len(split["goals"][split["houses"][0]])
        assert set(split["detectors"]) == {"world-owl", "oracle", "oracle-noisy"}
        for det in split["detectors"].values():
            for kind in ("strict", "synonym"):
                row = det[kind]
                assert set(row) == {"precision", "recall", "ap", "positives"}
                assert all(v is None or 0.0 <= v <= 1.0 for k, v in row.items() if k != "positives")
            assert det["synonym"]["positives"] >= det["strict"]["positives"]
        oracle = split["detectors"]["oracle"]["strict"]
        assert oracle["positives"] == 0 or oracle["recall"] == 1.0  # exact: every goal at >= 5% is found
        assert set(split["retrieval"]) == {"frames", "top1_strict", "top1_synonym", "chance"}
        assert len(split["confusions"]) <= 10
    md = (out / "perception.md").read_text()
    assert "ORACLE DETECTION" in md and all(s in md for s in VAL_SPLITS)
    assert (out / "pr.png").read_bytes()[:4] == b"\x89PNG"
    # resumed: the cached frames are reused, and the same seed gives the same report
    cached = {p: p.stat().st_mtime_ns for p in (out / "frames").glob("*.npz")}
    assert cached
    first = (out / "perception.json").read_bytes()
    rc, _, err = run(argv, capsys)
    assert rc == 0, err
    assert {p: p.stat().st_mtime_ns for p in (out / "frames").glob("*.npz")} == cached
    assert (out / "perception.json").read_bytes() == first


def test_a_missing_checkpoint_is_one_line_naming_it(tmp_path, capsys):
    missing = tmp_path / "no_such_weights.safetensors"
    rc, _, err = run(["perception", "evaluate", "--data", str(tmp_path), "--scenes", str(tmp_path),
                      "--out", str(tmp_path / "out"), "--checkpoint", str(missing)], capsys)  # fmt: skip
    one_line(rc, err, str(missing))
    assert not (tmp_path / "out").exists()  # refused before any work
    rc, _, err = run(["perception", "evaluate", "--data", str(tmp_path), "--scenes", str(tmp_path),
                      "--out", str(tmp_path / "out"), "--frames-per-house", "0"], capsys)  # fmt: skip
    one_line(rc, err, "--frames-per-house")


def test_tied_scores_are_one_threshold_in_ap():
    from ovon.perception.calibrate import average_precision as tied_average_precision

    assert math.isnan(tied_average_precision(np.array([0.1, 0.2]), np.array([False, False])))
    assert tied_average_precision(np.array([1.0, 1.0, 0.0]), np.array([True, False, True])) == pytest.approx(
        0.5 * 0.5 + 0.5 * 2 / 3
    )
