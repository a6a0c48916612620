"""Detectors: the oracle's miss / false-positive rates over many frames, the frame-share threshold, the
tiny OWLv2 model end to end, and lifting a detection to a 3D goal point."""

from __future__ import annotations

import json
import math
import time
from types import SimpleNamespace

import numpy as np
import pytest

from ovon.agents.modular.config import LiftConfig
from ovon.agents.modular.lifting import GoalMemory
from ovon.agents.modular.sensors import DepthProjector, pose_from_odometry
from ovon.env.core import ObjectNavEnv
from ovon.models.config import DetectorConfig, detector_preset
from ovon.models.detectors import make_detector
from ovon.models.encoders import FunctionTextEncoder, ModelNotAvailableError
from ovon.task.episode import EpisodeSpec
from tests.modular_scene import OBJECTS, portrait_sim, two_room_scene

# fake text space: cosines to "couch" are exactly these
COSINES = {"couch": 1.0, "sofa": 0.86, "armchair": 0.6, "toaster": 0.25}


def _fake_text() -> FunctionTextEncoder:
    def fn(texts: list[str]) -> np.ndarray:
        out = []
        for t in texts:
            c = COSINES[t]
            out.append([c, math.sqrt(max(0.0, 1 - c * c)) * (1 if t != "toaster" else -1), 0.0])
        return np.asarray(out, dtype=np.float32)

    return FunctionTextEncoder(fn, 3)


def _observation(shares: dict[int, float], goal_ids=frozenset({1})) -> dict:
    """A 100x100 semantic frame where instance i covers shares[i] of the pixels."""
    sem = np.zeros(100 * 100, dtype=np.int32)
    start = 0
    for iid, share in shares.items():
        n = int(round(share * sem.size))
        sem[start : start + n] = iid
        start += n
    names = ["", "couch", "sofa", "armchair", "toaster"]
    objects = [SimpleNamespace(id=i, category=c) for i, c in enumerate(names) if i]
    world = SimpleNamespace(key="fake", scene=SimpleNamespace(objects=objects))
    p = SimpleNamespace(frame=SimpleNamespace(semantic=sem.reshape(100, 100)), world=world, goal_ids=goal_ids)
    return {"privileged": p}


def test_oracle_miss_and_false_positive_rates_match_the_config():
    cfg = DetectorConfig(miss_rate=0.3, fp_rate=0.5, fp_min_similarity=0.4, fp_power=2.0)
    det = make_detector(cfg, _fake_text())
    obs = _observation({1: 0.1, 2: 0.1, 3: 0.1, 4: 0.1})
    n = 4000
    hits = {1: 0, 2: 0, 3: 0, 4: 0}
    det.reset(7)
    for _ in range(n):
        for d in det.detect(obs, "couch"):
            iid = int(np.unique(obs["privileged"].frame.semantic[d.mask])[0])
            hits[iid] += 1
            assert d.label == "couch" and d.mask.sum() == 1000
    expected = {
        1: 1 - cfg.miss_rate,
        2: cfg.fp_rate * ((0.86 - 0.4) / 0.6) ** 2,
        3: cfg.fp_rate * ((0.6 - 0.4) / 0.6) ** 2,
        4: 0.0,
    }
    for iid, p in expected.items():
        sd = math.sqrt(max(p * (1 - p), 1e-12) / n)
        assert abs(hits[iid] / n - p) <= 4 * sd + 1e-9, (iid, hits[iid] / n, p)
    assert hits[2] > 5 * hits[3] > 0 and hits[4] == 0  # sofa for couch is likely, toaster never


def test_oracle_min_frame_share_and_reseeding():
    det = make_detector(DetectorConfig(min_frame_share=0.05, miss_rate=0.5), _fake_text())
    assert det.detect(_observation({1: 0.04}), "couch") == []
    obs = _observation({1: 0.06})

    def run(seed):
        det.reset(seed)
        return [len(det.detect(obs, "couch")) for _ in range(50)]

    assert run(3) == run(3) and run(3) != run(4)


def test_oracle_detects_by_goal_text_too_and_needs_the_privileged_channel():
    det = make_detector(DetectorConfig(), _fake_text())
    # "sofa" is not in the goal set but is the goal text: a perfect detector reports it
    assert len(det.detect(_observation({2: 0.1}, goal_ids=frozenset()), "sofa")) == 1
    with pytest.raises(RuntimeError, match="privileged"):
        det.detect({"rgb": np.zeros((4, 4, 3), np.uint8)}, "couch")


def test_detector_presets_and_bad_values():
    assert detector_preset("perfect").miss_rate == 0 and detector_preset("noisy").fp_rate > 0
    with pytest.raises(ValueError, match="unknown detector preset 'great'"):
        detector_preset("great")
    with pytest.raises(ValueError, match=r"detector.miss_rate = 1.5: expected a number in \[0, 1\]"):
        make_detector(DetectorConfig(miss_rate=1.5))
    with pytest.raises(ValueError, match="detector.kind"):
        make_detector(DetectorConfig(kind="yolo"))


def test_oracle_false_positives_follow_minilm_similarity():
    """With the real MiniLM: sofa is a likely confusion for couch, toaster a rare one."""
    det = make_detector(detector_preset("noisy"))
    assert det.false_positive_probability("sofa", "couch") > 0.1
    assert det.false_positive_probability("toaster", "couch") < 0.01


@pytest.fixture(scope="module")
def tiny_owlv2(tmp_path_factory) -> str:
    """A random-weight OWLv2 with a 20-token CLIP tokenizer, saved like a downloaded model."""
    from transformers import CLIPTokenizer, Owlv2Config, Owlv2ForObjectDetection, Owlv2ImageProcessorPil

    d = tmp_path_factory.mktemp("owlv2")
    words = [
        "!",
        "a</w>",
        "photo</w>",
        "of</w>",
        "couch</w>",
        "chair</w>",
        "c",
        "o",
        "u",
        "h",
        "a",
        "i",
        "r",
        "p",
        "t",
        "f",
        "</w>",
        "<|startoftext|>",
        "<|endoftext|>",
    ]
    vocab = {w: i for i, w in enumerate(words)}
    (d / "vocab.json").write_text(json.dumps(vocab))
    (d / "merges.txt").write_text("#version: 0.2\n")
    tok = CLIPTokenizer(str(d / "vocab.json"), str(d / "merges.txt"))
    n = len(vocab)
    cfg = Owlv2Config(
        text_config=dict(
            vocab_size=n,
            hidden_size=32,
            intermediate_size=37,
            num_hidden_layers=2,
            num_attention_heads=4,
            max_position_embeddings=16,
            bos_token_id=n - 2,
            eos_token_id=n - 1,
            pad_token_id=n - 1,
        ),
        vision_config=dict(
            hidden_size=32,
            intermediate_size=37,
            num_hidden_layers=2,
            num_attention_heads=4,
            image_size=32,
            patch_size=8,
        ),
        projection_dim=32,
    )
    out = d / "model"
    Owlv2ForObjectDetection(cfg).save_pretrained(out)
    tok.save_pretrained(out)
    Owlv2ImageProcessorPil(size={"height": 32, "width": 32}).save_pretrained(out)
    return str(out)


def test_tiny_owlv2_end_to_end(tiny_owlv2):
    det = make_detector(DetectorConfig(kind="owlv2", owlv2_model=tiny_owlv2, owlv2_threshold=0.0))
    assert det.privileged is False
    rgb = np.random.default_rng(0).integers(0, 255, (64, 48, 3), dtype=np.uint8)
    dets = det.detect({"rgb": rgb}, "couch")
    assert dets, "threshold 0 keeps every box"
    assert [d.score for d in dets] == sorted((d.score for d in dets), reverse=True)
    for d in dets:
        x0, y0, x1, y1 = d.box
        assert 0 <= x0 < x1 <= 48 and 0 <= y0 < y1 <= 64 and d.mask is None and d.label == "couch"
    # a box-only detection lifts through its central part
    from ovon.config.sim import CameraConfig

    cam = CameraConfig(width=48, height=64, hfov_deg=60.0)
    memory = GoalMemory(LiftConfig(), DepthProjector(cam))
    depth = np.full((64, 48), 2.0, dtype=np.float32)
    assert memory.add(dets[:1], depth, pose_from_odometry([0.0, 0.0, 0.0])) > 0
    assert memory.goal_point(pose_from_odometry([0.0, 0.0, 0.0])) is not None


def test_owlv2_missing_model_fails_fast_with_its_name(tmp_path):
    import transformers  # noqa: F401 - its first import (seconds) is not what this test times

    t = time.perf_counter()
    with pytest.raises(ModelNotAvailableError) as e:
        make_detector(DetectorConfig(kind="owlv2", owlv2_model=str(tmp_path / "no-owl")))
    assert time.perf_counter() - t < 10
    msg = str(e.value)
    assert "no-owl" in msg and "\n" not in msg and "detector.kind=oracle" in msg


def test_lifted_detection_lands_on_the_true_object():
    """From room B, facing the couch 1.1 m away: the oracle detection lifted with depth + the true odometry
    pose lands within 0.1 m of the couch's box (planar), and so does the goal point."""
    sim = portrait_sim()
    env = ObjectNavEnv(scene=two_room_scene(), goal="couch", sim=sim)
    start = np.array([5.5, 0.0, 0.55])
    spec = EpisodeSpec("t", "two-rooms", "couch", start_position=start, start_yaw=-math.pi / 2)
    obs, _ = env.reset(seed=0, options={"episode": spec})
    p = env.unwrapped.privileged()
    dets = make_detector(DetectorConfig()).detect({**obs, "privileged": p}, "couch")
    assert len(dets) == 1
    memory = GoalMemory(LiftConfig(), DepthProjector(sim.camera))
    pose = pose_from_odometry(obs["odometry"])
    assert memory.add(dets, obs["depth"], pose) > 10
    # episodic -> world (start yaw -90 deg): world = start + Ry(yaw) [x, z]
    yaw = p.state.yaw
    ex, ez = memory.points[:, 0], memory.points[:, 2]
    wx = start[0] + math.cos(yaw) * ex + math.sin(yaw) * ez
    wz = start[2] - math.sin(yaw) * ex + math.cos(yaw) * ez
    lo, hi = OBJECTS[1][1]
    dx = np.maximum(np.maximum(lo[0] - wx, 0), wx - hi[0])
    dz = np.maximum(np.maximum(lo[2] - wz, 0), wz - hi[2])
    assert np.hypot(dx, dz).max() <= 0.1
    gx, gz = memory.goal_point(pose)
    assert abs(math.hypot(gx, gz) - (lo[0] - start[0])) <= 0.1
    env.close()
