"""What only a GPU shows (skipped without CUDA; CI has none): run on a GPU machine with
`pytest tests/test_cuda.py` beside the training tests, which use the GPU there through `device=auto`."""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np
import pytest
import torch

from ovon.models.config import EncoderConfig, policy_preset
from ovon.models.policy import ActorCritic, build_policy

pytestmark = pytest.mark.skipif(not torch.cuda.is_available(), reason="needs CUDA")
ENC = dataclasses.replace(EncoderConfig(image="cnn"), cnn_dim=16, cnn_channels=(8, 8))
OBS = {
    "rgb": np.zeros((32, 32, 3), np.uint8),
    "depth": np.ones((32, 32), np.float32),
    "goal": "couch",
    "pointgoal": np.ones(3, np.float32),
}


def test_load_puts_the_policy_on_the_gpu(tmp_path) -> None:
    build_policy(policy_preset("tiny"), 16, 8, ENC).save(tmp_path / "p.pt")
    assert all(p.is_cuda for p in ActorCritic.load(tmp_path / "p.pt", map_location="cuda").parameters())


@pytest.mark.parametrize("task", ["objectnav", "pointnav"])
def test_policy_agent_acts_on_the_gpu(tmp_path, task: str) -> None:
    from ovon.agents.policy_agent import PolicyAgent

    if task == "pointnav":
        extra, text_dim = {"task": {"kind": "pointnav"}}, 3
    else:
        extra, text_dim = {"text_table": {"couch": torch.randn(8)}}, 8
    build_policy(policy_preset("tiny"), 16, text_dim, ENC).save(tmp_path / "p.pt", extra=extra)
    agent = PolicyAgent(str(tmp_path / "p.pt"), device="cuda")
    agent.reset({"seed": 0})
    assert all(0 <= agent.act(OBS) < 6 for _ in range(3))


def test_a_cloned_lstm_policy_stays_one_cudnn_chunk() -> None:
    p = build_policy(policy_preset("tiny", core="lstm"), 16, 8, None).cuda()
    x, prev = torch.randn(2, 5, 24, device="cuda"), torch.zeros(2, 5, dtype=torch.long, device="cuda")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # "RNN module weights are not part of single contiguous chunk"
        p.clone()(x, prev)
