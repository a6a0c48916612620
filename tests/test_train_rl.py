"""RL plumbing that decides whether PPO can learn at all: GAE, the critic's explained variance, that
rollout and update see the same policy (ratio 1 at lr 0, for the transformer's sliding window too), the
imitation anchors and the critic warm-up gate of the fine-tune."""

from __future__ import annotations

import dataclasses
import zlib
from pathlib import Path

import numpy as np
import pytest
import torch

torch.set_num_threads(1)

from ovon.train.collect import explained_variance, gae  # noqa: E402
from ovon.train.config import FinetuneConfig, train_preset  # noqa: E402
from ovon.train.episodes import adhoc_specs  # noqa: E402
from ovon.train.finetune import anchor_weight, kl_to, reference_logits  # noqa: E402
from ovon.train.logging import read_metrics  # noqa: E402
from ovon.train.text import needed_texts, write_text_table  # noqa: E402


@pytest.fixture(scope="module")
def specs():
    return adhoc_specs([0], categories=["couch", "bed", "toilet", "sink"])


@pytest.fixture(scope="module")
def table(tmp_path_factory, specs) -> str:
    path = tmp_path_factory.mktemp("text") / "table.pt"
    vec = {
        t: np.random.default_rng(zlib.crc32(t.encode())).standard_normal(16).astype(np.float32)
        for t in needed_texts(specs)
    }
    write_text_table(path, vec)
    return str(path)


def test_gae_matches_a_hand_computation() -> None:
    r = torch.tensor([[1.0, 0.0, 2.0]])
    v = torch.tensor([[0.5, 0.2, 0.1, 3.0]])
    d = torch.tensor([[False, True, False]])
    g, lam = 0.9, 0.8
    d2 = 2.0 + g * 3.0 - 0.1  # last step bootstraps
    d1 = 0.0 - 0.2  # done: no value after it, no later advantage
    d0 = 1.0 + g * 0.2 - 0.5
    expect = torch.tensor([[d0 + g * lam * d1, d1, d2]])
    adv, ret = gae(r, v, d, g, lam)
    torch.testing.assert_close(adv, expect)
    torch.testing.assert_close(ret, expect + v[:, :3])


def test_explained_variance() -> None:
    ret = torch.tensor([1.0, 2.0, 3.0, 4.0])
    assert explained_variance(ret, ret) == pytest.approx(1.0)
    assert explained_variance(torch.full((4,), 2.5), ret) == pytest.approx(0.0)
    assert explained_variance(-ret, ret) < 0
    assert explained_variance(ret, torch.ones(4)) == 0.0  # nothing to explain


@pytest.mark.parametrize("core", ["transformer", "lstm"])
def test_first_updates_at_lr_zero_have_ratio_one(tmp_path: Path, specs, table: str, core: str) -> None:
    """With lr 0 the update must see exactly the policy that acted: PPO's ratio is 1 (approx_kl 0,
    clipfrac 0), and the log-probs it recomputes equal those the actions were sampled with
    (behaviour_kl 0), also in later chunks where the transformer's acting window reaches back into the
    previous chunks (episodes of up to 40 steps, chunks of 8, window 6, 2 layers: the key/value cache sees
    2 x 5 steps back)."""
    from ovon.train import train

    cfg = train_preset("tiny", algo="ppo", text_cache=table, max_updates=5, lr=0.0)
    cfg = dataclasses.replace(cfg, policy=dataclasses.replace(cfg.policy, core=core, layers=2, context=6))
    train(cfg, specs, tmp_path / core)
    rows = read_metrics(tmp_path / core)
    assert len(rows) == 5
    for r in rows:
        assert abs(r["approx_kl"]) < 1e-7 and r["clipfrac"] == 0.0
        assert r["behaviour_kl"] < 1e-8, r  # a one-window prefix leaves 1e-7..3e-7 here


@pytest.mark.parametrize("core", ["transformer", "lstm"])
def test_dagger_with_its_context_prefix_learns_from_the_policy_that_acted(
    tmp_path: Path, specs, table: str, core: str
) -> None:
    """`dagger.context_prefix`: each buffered chunk is re-read after the steps acting saw (transformer) or
    from the acting (h, c) (LSTM), so at lr 0 the update's log-probs of the newest rollout equal those the
    actions were taken with (`behaviour_kl` 0) in every update; without it they differ once episodes
    cross chunk boundaries. The buffer's context is views of older chunks: a one-rollout buffer works too."""
    from ovon.train import train

    for prefix, buffer in ((True, 3), (True, 1), (False, 3)):
        cfg = train_preset("tiny", algo="dagger", expert="shortest-path", text_cache=table, max_updates=6, lr=0.0)
        cfg = dataclasses.replace(
            cfg,
            policy=dataclasses.replace(cfg.policy, core=core, layers=2, context=6),
            dagger=dataclasses.replace(
                cfg.dagger, context_prefix=prefix, grad_steps=2, buffer_rollouts=buffer, sample_rollouts=min(2, buffer)
            ),
        )
        out = tmp_path / f"{core}-{prefix}-{buffer}"
        train(cfg, specs, out)
        kl = [r["behaviour_kl"] for r in read_metrics(out)]
        assert len(kl) == 6 and kl[0] < 1e-8  # the first chunk starts every episode: nothing to miss
        if prefix:
            assert max(kl) < 1e-8, kl
        else:
            assert max(kl[1:]) > 1e-6, kl


def test_without_the_context_prefix_the_update_reads_another_policy(tmp_path: Path, specs, table: str) -> None:
    """The check above can fail: re-reading chunks alone gives the transformer a shorter context than it
    acted with once episodes cross chunk boundaries."""
    from ovon.train import train

    cfg = train_preset("tiny", algo="ppo", text_cache=table, max_updates=5, lr=0.0)
    cfg = dataclasses.replace(
        cfg,
        ppo=dataclasses.replace(cfg.ppo, context_prefix=False),
        policy=dataclasses.replace(cfg.policy, layers=2, context=6),
    )
    train(cfg, specs, tmp_path / "noprefix")
    rows = read_metrics(tmp_path / "noprefix")
    assert rows[0]["behaviour_kl"] < 1e-6  # the first chunk starts every episode: same context
    assert max(r["behaviour_kl"] for r in rows[1:]) > 1e-6


def test_anchor_weight_decays_linearly() -> None:
    ft = FinetuneConfig(anchor="kl", anchor_coef=2.0, anchor_decay_updates=100, scale=0.5)
    assert anchor_weight(ft, 0) == 2.0
    assert anchor_weight(ft, 25) == pytest.approx(1.0)
    assert anchor_weight(ft, 50) == 0.0 and anchor_weight(ft, 80) == 0.0
    assert anchor_weight(dataclasses.replace(ft, anchor_decay_updates=0), 10_000) == 2.0
    assert anchor_weight(dataclasses.replace(ft, anchor="none"), 0) == 0.0


def test_kl_to() -> None:
    a = torch.randn(3, 5, 4)
    assert kl_to(a, a).item() == pytest.approx(0.0, abs=1e-7)
    assert kl_to(a, torch.zeros_like(a)).item() > 0


def test_lstm_reference_carries_its_own_memory_from_chunk_to_chunk() -> None:
    """The KL anchor's reference LSTM, read chunk by chunk with its own carried (h, c), gives the logits of
    one pass over the whole rollout; read with the fine-tuned policy's memory (what the anchor did before)
    it gives other logits from the second chunk on."""
    from ovon.models.chunk import Chunk
    from ovon.models.config import policy_preset
    from ovon.models.policy import build_policy

    torch.manual_seed(0)
    reference = build_policy(policy_preset("tiny", core="lstm"), 24, 16).eval()
    tuned = build_policy(policy_preset("tiny", core="lstm"), 24, 16).eval()  # other weights
    g = torch.Generator().manual_seed(3)
    B, T, chunks = 3, 8, 3
    n = chunks * T + 1  # + the bootstrap observation
    img, goal = torch.randn(B, n, 24, generator=g), torch.randn(B, n, 16, generator=g)
    prev = torch.randint(0, 6, (B, n), generator=g)
    starts = torch.rand(B, n, generator=g) < 0.1
    starts[:, 0] = True
    prev[starts] = -1
    with torch.no_grad():
        whole = reference.forward_seq(reference.make_obs(img, goal), prev, starts)[0]
        ref_state = tuned_state = None
        for c in range(chunks):
            sl = slice(c * T, c * T + T + 1)
            chunk = Chunk(img[:, sl], goal[:, sl], prev[:, sl], starts[:, sl])
            logits, ref_state = reference_logits(reference, chunk, T, ref_state)
            torch.testing.assert_close(logits, whole[:, c * T : (c + 1) * T], rtol=1e-5, atol=1e-5)
            wrong, _ = reference_logits(reference, chunk, T, tuned_state)
            if c > 0:
                assert (wrong - logits).abs().max() > 1e-3
            tuned_state = tuned.forward_seq(
                tuned.make_obs(img[:, sl][:, :T], goal[:, sl][:, :T]),
                prev[:, sl][:, :T],
                starts[:, sl][:, :T],
                tuned_state,
            )[2]


@pytest.mark.parametrize("anchor", ["kl", "expert"])
def test_finetune_anchor_keeps_the_initial_policy(tmp_path: Path, specs, table: str, anchor: str) -> None:
    """The anchor term is on from the first update; KL to the initial policy is 0 before the actor moves."""
    from ovon.train import train

    dag = train_preset("tiny", algo="dagger", expert="shortest-path", text_cache=table)
    train(dag, specs, tmp_path / "dagger")
    ft = dataclasses.replace(
        dag,
        algo="ppo",
        max_updates=3,
        finetune=FinetuneConfig(
            anchor=anchor, anchor_coef=0.5, anchor_decay_updates=4, actor_unfreeze=0, actor_warmup_end=0, actor_lr=1e-3
        ),
    )
    train(ft, specs, tmp_path / "ft", init=str(tmp_path / "dagger"))
    rows = read_metrics(tmp_path / "ft")
    assert [r["anchor/weight"] for r in rows] == [0.5, 0.375, 0.25]
    assert all(np.isfinite(r["anchor_loss"]) and r["anchor_loss"] >= 0 for r in rows)
    assert rows[0]["lr/actor"] == 1e-3
    if anchor == "kl":
        assert rows[0]["anchor_loss"] < 1e-3  # ~0: the actor starts as the reference (one minibatch moves it)
    else:
        assert rows[0]["anchor_loss"] > 0.1  # cross-entropy to the labels


def test_critic_warmup_gate_holds_the_actor(tmp_path: Path, specs, table: str) -> None:
    from ovon.train import train

    dag = train_preset("tiny", algo="dagger", expert="shortest-path", text_cache=table)
    train(dag, specs, tmp_path / "dagger")
    ft = dataclasses.replace(
        dag,
        algo="ppo",
        max_updates=3,
        finetune=FinetuneConfig(actor_unfreeze=0, actor_warmup_end=0, actor_lr=1e-3, critic_warmup_ev=0.999),
    )
    train(ft, specs, tmp_path / "ft", init=str(tmp_path / "dagger"))
    rows = read_metrics(tmp_path / "ft")
    assert all(r["lr/actor"] == 0.0 and r["actor_gate_open"] == 0.0 for r in rows)
    assert all("explained_variance" in r for r in rows)


@pytest.mark.parametrize("core", ["transformer", "lstm"])
def test_separate_critic_trains_its_own_core_and_resumes_exactly(tmp_path: Path, specs, table: str, core: str) -> None:
    """`finetune.critic=separate`: the critic is a copy of the initial network whose core learns the value
    (the shared critic is a linear read of features trained for actions); the policy gets no value
    gradient (actor frozen here: its weights stay the initial ones); an LSTM critic carries its own memory
    across chunks, and a resumed run reproduces every loss, the value loss too."""
    from ovon.models.policy import ActorCritic
    from ovon.train import train
    from ovon.train.checkpoint import load_checkpoint

    dag = train_preset("tiny", algo="dagger", expert="shortest-path", text_cache=table, max_updates=2)
    dag = dataclasses.replace(dag, policy=dataclasses.replace(dag.policy, core=core))
    train(dag, specs, tmp_path / "dagger")
    ft = dataclasses.replace(dag, algo="ppo", max_updates=4, finetune=FinetuneConfig(critic="separate"))
    train(ft, specs, tmp_path / "straight", init=str(tmp_path / "dagger"))
    train(dataclasses.replace(ft, max_updates=2), specs, tmp_path / "split", init=str(tmp_path / "dagger"))
    train(ft, specs, tmp_path / "split", init=str(tmp_path / "dagger"), resume=True)
    a, b = read_metrics(tmp_path / "straight"), read_metrics(tmp_path / "split")
    assert [(r["loss"], r["value_loss"]) for r in a] == [(r["loss"], r["value_loss"]) for r in b]
    assert all(np.isfinite(r["explained_variance"]) for r in a)
    init = ActorCritic.load(tmp_path / "dagger" / "policy.pt").state_dict()
    tuned = ActorCritic.load(tmp_path / "straight" / "policy.pt").state_dict()
    critic = load_checkpoint(tmp_path / "straight")["ranks"][0]["critic_net"]
    core_keys = [k for k in init if k.startswith("core.")]
    assert core_keys and all(torch.equal(init[k], tuned[k]) for k in init if not k.startswith("critic_head."))
    assert any(not torch.equal(init[k], critic[k]) for k in core_keys)  # the critic's own core learned
    assert all(torch.equal(init[k], critic[k]) for k in init if k.startswith("action_head."))
