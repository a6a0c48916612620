"""Agents with learned perception read no ground truth (issue 37): VLFM with the shipped world-owl detector and
world-vl value scorer is not privileged, and served under the default `remote.allow_privileged=false` it gives
the files of the same agent in-process; a policy trains on the frozen world-vl encoder."""

from __future__ import annotations

import json

import torch

from ovon.agents.remote import RemoteConfig
from ovon.agents.served import servable_factory
from ovon.evaluate.config import EvalConfig
from ovon.evaluate.harness import evaluate
from tests.remote_agents import serving
from tests.test_remote_agent import same_files

torch.set_num_threads(1)

LEARNED = {"detector.kind": "world-owl", "value.scorer.kind": "world-vl"}


def test_served_vlfm_with_learned_perception_needs_no_privileged_channel(tiny_dataset, tiny_scenes, tmp_path):
    cfg = EvalConfig(
        agent="vlfm", agent_kwargs=dict(LEARNED), data=str(tiny_dataset), scenes=str(tiny_scenes),
        splits=("val_seen",), episodes=2,
    )  # fmt: skip
    evaluate(cfg, tmp_path / "local", progress=False)
    card = json.loads((tmp_path / "local" / "summary.json").read_text())["protocol"]["agent"]
    assert card["privileged"] is False and card["oracle_perception"] is False, card
    with serving(servable_factory("vlfm", dict(LEARNED)), name="vlfm") as server:
        remote = EvalConfig(
            agent=f"remote:127.0.0.1:{server.port}", data=str(tiny_dataset), scenes=str(tiny_scenes),
            splits=("val_seen",), episodes=2, remote=RemoteConfig(),
        )  # fmt: skip
        assert remote.remote.allow_privileged is False
        evaluate(remote, tmp_path / "remote", progress=False)
    same_files(tmp_path / "local", tmp_path / "remote")


def test_a_policy_trains_on_the_frozen_world_vl_encoder_and_is_served_without_ground_truth(
    tiny_dataset, tiny_scenes, tmp_path
):
    from ovon.cli.main import main as ovon

    out = tmp_path / "dagger"
    rc = ovon(["train", "--algo", "dagger", "--procedural", "0", "--preset", "tiny", "--encoder", "world-vl",
               "--out", str(out)])  # fmt: skip
    assert rc == 0 and (out / "policy.pt").is_file()
    cfg = json.loads((out / "config.json").read_text())
    assert cfg["encoder"]["image"] == "world-vl"
    args = {"checkpoint": str(out)}
    local = EvalConfig(agent="policy", agent_kwargs=dict(args), data=str(tiny_dataset), scenes=str(tiny_scenes),
                       splits=("val_seen",), episodes=2)  # fmt: skip
    evaluate(local, tmp_path / "local", progress=False)
    card = json.loads((tmp_path / "local" / "summary.json").read_text())["protocol"]["agent"]
    assert card["privileged"] is False and card["oracle_perception"] is False, card
    with serving(servable_factory("policy", args), name="policy") as server:
        remote = EvalConfig(agent=f"remote:127.0.0.1:{server.port}", data=str(tiny_dataset),
                            scenes=str(tiny_scenes), splits=("val_seen",), episodes=2)  # fmt: skip
        evaluate(remote, tmp_path / "remote", progress=False)
    same_files(tmp_path / "local", tmp_path / "remote")


def test_world_vl_env_batches_give_the_same_embeddings_on_any_number_of_workers() -> None:
    """A vector env worker encodes its envs' frames in one batch; a frame's embedding is bitwise the same
    in-process and on 1 or 3 workers. The single-frame path a policy agent uses (batch 1, unpadded) equals
    it up to float rounding and shares its forward pass with a world-owl detector on the same frame."""
    import dataclasses

    import numpy as np

    from ovon.env.stack import EnvRecipe
    from ovon.models.encoders import encode_observation, make_image_encoder
    from ovon.train.config import train_preset
    from ovon.train.envs import TrainEnvs
    from ovon.train.episodes import adhoc_specs

    specs = adhoc_specs([0, 1, 2], categories=["chair", "bed", "toilet"])
    cfg = train_preset("tiny", algo="dagger")
    encoder = dataclasses.replace(cfg.encoder, image="world-vl", world_batch=2)
    rng = np.random.default_rng(0)
    table = {t: rng.normal(size=384).astype(np.float32) for t in {s.goal_category for s in specs}}
    recipe = EnvRecipe(sim=cfg.sim, task=cfg.task, encoder=encoder, text_table=table, scene_repeat=1)
    runs = []
    for workers in (0, 1, 3):
        envs = TrainEnvs(recipe, specs, 3, workers, base_seed=0)
        try:
            seq = [envs.reset().image.clone()]
            for _ in range(3):
                seq.append(envs.step(torch.tensor([1, 2, 3])).image.clone())
            runs.append(seq)
        finally:
            envs.close()
    for a, b, c in zip(*runs):
        assert torch.equal(a, b) and torch.equal(a, c)
    assert runs[0][0].abs().sum() > 0
    single = make_image_encoder(encoder)
    frame = {"rgb": rng.integers(0, 255, (128, 72, 3), dtype=np.uint8), "depth": np.ones((128, 72), np.float32),
             "collided": 1}  # fmt: skip
    both = single.encode({"rgb": np.stack([frame["rgb"]] * 3), "depth": np.stack([frame["depth"]] * 3),
                          "collided": np.ones(3)})  # fmt: skip
    one = encode_observation(single, frame)
    assert one.shape == tuple(both[0].shape)
    np.testing.assert_allclose(one, both[0].numpy(), rtol=1e-4, atol=1e-5)
    assert np.array_equal(one, encode_observation(single, frame))  # deterministic on its own
    from ovon.models.config import DetectorConfig
    from ovon.models.world.roles import WorldOWLDetector

    detector = WorldOWLDetector(DetectorConfig(kind="world-owl"))
    assert detector.model is single.model  # one loaded network: the frame's forward pass is shared
    calls = []
    forward = single.model.features
    single.model.features = lambda rgb: calls.append(len(rgb)) or forward(rgb)
    try:
        frame["rgb"] = rng.integers(0, 255, (128, 72, 3), dtype=np.uint8)
        encode_observation(single, frame)
        detector.detect({"rgb": frame["rgb"], "depth": frame["depth"]}, "chair")
    finally:
        del single.model.features
    assert calls == [1]
