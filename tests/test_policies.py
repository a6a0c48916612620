"""Policies: shapes, causality, episode-boundary masking, KV-cache acting, LSTM stepping, overfitting."""

from __future__ import annotations

import dataclasses

import pytest
import torch

from ovon.models.config import EncoderConfig, policy_preset
from ovon.models.lstm import lstm_params, matched_lstm_hidden, transformer_core_params
from ovon.models.policy import ActorCritic, LSTMPolicy, TransformerPolicy, build_policy

torch.set_num_threads(1)

IMG, TXT = 24, 16
D = IMG + TXT


def _policy(core: str = "transformer", **kw) -> ActorCritic:
    torch.manual_seed(0)
    cfg = policy_preset("tiny", core=core, **kw)
    return build_policy(cfg, IMG, TXT).eval()


def _data(b: int, t: int, seed: int = 1):
    g = torch.Generator().manual_seed(seed)
    obs = torch.randn(b, t, D, generator=g)
    prev = torch.randint(0, 6, (b, t), generator=g)
    prev[:, 0] = -1
    return obs, prev


@pytest.mark.parametrize("core", ["transformer", "lstm"])
def test_shapes_and_types(core: str) -> None:
    p = _policy(core)
    assert isinstance(p, TransformerPolicy if core == "transformer" else LSTMPolicy)
    obs, prev = _data(3, 7)
    logits, values = p(obs, prev)
    assert logits.shape == (3, 7, 6) and values.shape == (3, 7)
    st = p.init_state(3)
    lg, v, st = p.act_step(obs[:, 0], prev[:, 0], st, torch.ones(3, dtype=torch.bool))
    assert lg.shape == (3, 6) and v.shape == (3,)
    a, lp, v2, st = p.act(obs[:, 1], a_prev := lg.argmax(-1), st, torch.zeros(3, dtype=torch.bool))
    assert a.shape == (3,) and lp.shape == (3,) and a_prev.shape == (3,)
    assert isinstance(p.distribution(lg), torch.distributions.Categorical)


def test_make_obs_broadcasts_goal() -> None:
    img = torch.randn(2, 5, IMG)
    goal = torch.randn(2, TXT)
    obs = ActorCritic.make_obs(img, goal)
    assert obs.shape == (2, 5, D)
    assert torch.equal(obs[:, 3, IMG:], goal)


@pytest.mark.parametrize("core", ["transformer", "lstm"])
def test_evaluate_reads_a_chunk_and_drops_its_context_prefix(core: str) -> None:
    """`evaluate(chunk, state)`: the one way a learner reads a sequence batch (frozen-encoder embeddings, a
    float16 buffer's too) gives forward's outputs after the chunk's prefix and the LSTM's state after it."""
    from ovon.models.chunk import Chunk

    p = _policy(core)
    obs, prev = _data(3, 9)
    starts = prev < 0
    goal = obs[..., IMG:]
    logits, values, state = p.forward_seq(obs, prev, starts)
    for images in (obs[..., :IMG], obs[..., :IMG].half()):
        got = p.evaluate(Chunk(images, goal, prev, starts, prefix=4))
        want_obs = ActorCritic.make_obs(images.float(), goal)
        want = p.forward_seq(want_obs, prev, starts)
        assert torch.equal(got[0], want[0][:, 4:]) and torch.equal(got[1], want[1][:, 4:])
    got = p.evaluate(Chunk(obs[..., :IMG], goal, prev, starts), via=p)  # through a (DDP) module: no state
    torch.testing.assert_close(got[0], logits)
    torch.testing.assert_close(got[1], values)
    assert got[2] is None
    if core == "lstm":  # chunk by chunk with the state carried: one pass
        first = p.evaluate(Chunk(obs[:, :5, :IMG], goal[:, :5], prev[:, :5], starts[:, :5]))
        second = p.evaluate(Chunk(obs[:, 5:, :IMG], goal[:, 5:], prev[:, 5:], starts[:, 5:]), first[2])
        torch.testing.assert_close(torch.cat([first[0], second[0]], 1), logits)


@pytest.mark.parametrize("core", ["transformer", "lstm"])
def test_causality(core: str) -> None:
    p = _policy(core)
    obs, prev = _data(2, 12)
    with torch.no_grad():
        l1, v1 = p(obs, prev)
        obs2, prev2 = obs.clone(), prev.clone()
        obs2[:, 6:] += torch.randn_like(obs2[:, 6:])
        prev2[:, 6:] = (prev2[:, 6:] + 1) % 6
        l2, v2 = p(obs2, prev2)
    assert torch.allclose(l1[:, :6], l2[:, :6], atol=1e-6)
    assert torch.allclose(v1[:, :6], v2[:, :6], atol=1e-6)
    assert not torch.allclose(l1[:, 6:], l2[:, 6:], atol=1e-4)


@pytest.mark.parametrize("core", ["transformer", "lstm"])
def test_episode_boundary_masking(core: str) -> None:
    p = _policy(core)
    obs, prev = _data(2, 15)
    starts = torch.zeros(2, 15, dtype=torch.bool)
    starts[:, 0] = True
    starts[0, 6] = True
    starts[1, 9] = True
    with torch.no_grad():
        logits, values = p(obs, prev, starts)
        for b, s in ((0, 6), (1, 9)):
            fresh_prev = prev[b : b + 1, s:].clone()
            fresh_prev[:, 0] = -1
            lf, vf = p(obs[b : b + 1, s:], fresh_prev)
            assert torch.allclose(logits[b, s:], lf[0], atol=1e-5)
            assert torch.allclose(values[b, s:], vf[0], atol=1e-5)
            lb, _ = p(obs[b : b + 1, :s], prev[b : b + 1, :s])
            assert torch.allclose(logits[b, :s], lb[0], atol=1e-5)


def test_kv_cache_acting_matches_forward() -> None:
    ctx, steps = 100, 130
    p = _policy("transformer", context=ctx)
    obs, prev = _data(2, steps, seed=3)
    state = p.init_state(2)
    outs, vals = [], []
    with torch.no_grad():
        for t in range(steps):
            done = torch.full((2,), t == 0)
            lg, v, state = p.act_step(obs[:, t], prev[:, t], state, done)
            outs.append(lg)
            vals.append(v)
        acted = torch.stack(outs, 1)
        acted_v = torch.stack(vals, 1)
        full, full_v = p(obs, prev)  # sliding-window mask over the whole episode
        first, _ = p(obs[:, :ctx], prev[:, :ctx])
    assert torch.allclose(acted[:, :ctx], first, atol=1e-5)
    assert torch.allclose(acted, full, atol=1e-5)
    assert torch.allclose(acted_v, full_v, atol=1e-5)


def test_recompute_acting_matches_last_window_forward() -> None:
    ctx, steps = 20, 33
    p = _policy("transformer", context=ctx, act_mode="recompute")
    obs, prev = _data(2, steps, seed=4)
    state = p.init_state(2)
    with torch.no_grad():
        for t in range(steps):
            lg, _, state = p.act_step(obs[:, t], prev[:, t], state, torch.full((2,), t == 0))
            lo = max(0, t - ctx + 1)
            pos = torch.arange(lo, t + 1).expand(2, -1)
            ref, _ = p(obs[:, lo : t + 1], prev[:, lo : t + 1], positions=pos)
            assert torch.allclose(lg, ref[:, -1], atol=1e-5), t


def test_kv_cache_resets_per_env() -> None:
    p = _policy("transformer", context=10)
    obs, prev = _data(2, 25, seed=5)
    state = p.init_state(2)
    restart = 13  # env 1 starts a new episode at step 13; env 0 continues
    with torch.no_grad():
        outs = []
        for t in range(25):
            done = torch.tensor([t == 0, t in (0, restart)])
            pr = prev[:, t].clone()
            pr[done] = -1
            lg, _, state = p.act_step(obs[:, t], pr, state, done)
            outs.append(lg)
        acted = torch.stack(outs, 1)
        starts = torch.zeros(2, 25, dtype=torch.bool)
        starts[:, 0] = True
        starts[1, restart] = True
        full, _ = p(obs, prev, starts)
    assert torch.allclose(acted, full, atol=1e-5)


def test_lstm_act_step_matches_forward() -> None:
    p = _policy("lstm")
    obs, prev = _data(3, 20, seed=6)
    starts = torch.zeros(3, 20, dtype=torch.bool)
    starts[:, 0] = True
    starts[2, 11] = True
    state = p.init_state(3)
    with torch.no_grad():
        outs = []
        for t in range(20):
            lg, _, state = p.act_step(obs[:, t], prev[:, t], state, starts[:, t])
            outs.append(lg)
        full, _ = p(obs, prev, starts)
    assert torch.allclose(torch.stack(outs, 1), full, atol=1e-5)


@pytest.mark.parametrize("core", ["transformer", "lstm"])
def test_overfits_fixed_sequences(core: str) -> None:
    p = _policy(core).train()
    obs, prev = _data(4, 20, seed=7)
    target = torch.randint(0, 6, (4, 20), generator=torch.Generator().manual_seed(8))
    opt = torch.optim.Adam(p.parameters(), lr=3e-3)
    for _ in range(300):
        logits, _ = p(obs, prev)
        loss = torch.nn.functional.cross_entropy(logits.reshape(-1, 6), target.reshape(-1))
        opt.zero_grad()
        loss.backward()
        opt.step()
        if loss.item() < 0.01:
            break
    with torch.no_grad():
        logits, _ = p(obs, prev)
    assert loss.item() < 0.05
    assert (logits.argmax(-1) == target).all()


def test_param_counts_matched() -> None:
    t = transformer_core_params(512, 4, 1024)
    h = matched_lstm_hidden(512, 4, t)
    assert abs(lstm_params(512, h, 4) - t) / t < 0.01
    pt = build_policy(policy_preset("paper"), 768, 768)
    pl = build_policy(policy_preset("paper", core="lstm"), 768, 768)
    assert pt.num_params("core") == t
    assert pl.num_params("core") == lstm_params(512, h, 4)


def test_save_load_and_reinit_critic(tmp_path) -> None:
    p = _policy("lstm")
    p.save(tmp_path / "p.pt", extra={"step": 5})
    q = ActorCritic.load(tmp_path / "p.pt")
    assert isinstance(q, LSTMPolicy) and q.checkpoint_extra == {"step": 5}
    for a, b in zip(p.state_dict().values(), q.state_dict().values()):
        assert torch.equal(a, b)
    w = q.critic_head.weight.clone()
    torch.manual_seed(123)
    q.reinit_critic()
    assert not torch.equal(w, q.critic_head.weight)
    groups = q.parameter_groups()
    assert {"critic", "actor", "prev_action"} == set(groups)


def test_load_puts_the_module_on_map_location_and_keeps_extras_on_the_cpu(tmp_path) -> None:
    """`map_location` is where the policy runs: its weights go there ("meta" stands in for a GPU), while
    the extras (the text table a `TableTextEncoder` turns into numpy) stay on the CPU. Before, the module
    stayed on the CPU and the extras moved: an agent on CUDA failed at load or at its first step."""
    p = _policy("lstm")
    p.save(tmp_path / "p.pt", extra={"text_table": {"couch": torch.randn(TXT)}})
    q = ActorCritic.load(tmp_path / "p.pt", map_location="meta")
    assert all(t.is_meta for t in q.parameters())
    assert q.checkpoint_extra["text_table"]["couch"].device.type == "cpu"


@pytest.mark.parametrize("core", ["transformer", "lstm"])
def test_clone_is_an_independent_equal_copy(core: str) -> None:
    p = _policy(core)
    q = p.clone()
    obs, prev = _data(2, 5)
    assert torch.equal(p(obs, prev)[0], q(obs, prev)[0])
    with torch.no_grad():
        next(q.parameters()).add_(1.0)
    assert not torch.equal(p(obs, prev)[0], q(obs, prev)[0])


def test_cnn_policy_owns_encoder(tmp_path) -> None:
    enc = dataclasses.replace(EncoderConfig(image="cnn"), cnn_dim=IMG, cnn_channels=(8, 8))
    p = build_policy(policy_preset("tiny"), IMG, TXT, enc)
    rgb = torch.randint(0, 255, (2, 3, 32, 32, 3), dtype=torch.uint8)
    img = p.encode_images({"rgb": rgb.reshape(6, 32, 32, 3)}).reshape(2, 3, IMG)
    logits, _ = p(ActorCritic.make_obs(img, torch.randn(2, TXT)), torch.full((2, 3), -1))
    logits.sum().backward()
    assert p.image_encoder.convs[0].weight.grad is not None
    p.save(tmp_path / "c.pt")
    assert ActorCritic.load(tmp_path / "c.pt").image_encoder is not None


def test_goal_similarity_features() -> None:
    """Per text-aligned part: dot, cosine and norm against the unit goal; the part layout follows the
    encoder config, and an encoder without text-space parts is refused by name."""
    enc = EncoderConfig(image="oracle-vl", oracle_grid=1, oracle_global=True)  # 2 parts of TXT dims
    torch.manual_seed(0)
    p = build_policy(policy_preset("tiny", goal_similarity=True), 2 * TXT + 4, TXT, enc).eval()
    assert p.sim_parts == 2 and p.input_proj.in_features == 3 * TXT + 4 + p.cfg.prev_action_dim + 6
    goal = torch.zeros(TXT)
    goal[0] = 2.0  # not unit length: the feature normalises it
    part_a = torch.zeros(TXT)
    part_a[0], part_a[1] = 0.3, 0.4  # dot 0.3, norm 0.5, cosine 0.6
    part_b = torch.zeros(TXT)
    part_b[1] = 1.0  # orthogonal to the goal
    obs = torch.cat([part_a, part_b, torch.ones(4), goal])[None]
    feats = p.goal_similarity(obs)[0]
    assert torch.allclose(feats, torch.tensor([0.3, 0.0, 0.6, 0.0, 0.5, 1.0]), atol=1e-6)
    logits, _ = p(obs[:, None].expand(1, 3, -1), torch.tensor([[-1, 1, 2]]))
    assert logits.shape == (1, 3, 6)
    st = p.init_state(1)  # acting goes through the same input path
    lg, _, _ = p.act_step(obs, torch.tensor([-1]), st, torch.ones(1, dtype=torch.bool))
    assert torch.allclose(lg, logits[:, 0], atol=1e-5)
    with pytest.raises(ValueError, match="goal_similarity"):
        build_policy(policy_preset("tiny", goal_similarity=True), 32, TXT, EncoderConfig(image="cnn", cnn_dim=32))


@pytest.mark.parametrize("core", ["transformer", "lstm"])
def test_without_previous_action_input(core: str) -> None:
    """prev_action_dim=0: the previous action cannot change the output; acting still equals forward."""
    p = _policy(core, prev_action_dim=0)
    assert p.prev_action_emb is None and p.parameter_groups()["prev_action"] == []
    obs, prev = _data(2, 6)
    logits, _ = p(obs, prev)
    other, _ = p(obs, (prev + 1) % 6)
    assert torch.equal(logits, other)
    st = p.init_state(2)
    for t in range(6):
        lg, _, st = p.act_step(obs[:, t], prev[:, t], st, torch.full((2,), t == 0))
        assert torch.allclose(lg, logits[:, t], atol=1e-5)


def test_policy_agent_sampling_temperature(tmp_path) -> None:
    """A near-zero temperature samples the argmax; temperature <= 0 is refused; sampling is seeded per
    episode, so the same episode seed replays the same actions."""
    import numpy as np

    from ovon.agents.policy_agent import PolicyAgent

    enc = dataclasses.replace(EncoderConfig(image="cnn"), cnn_dim=IMG, cnn_channels=(8, 8))
    torch.manual_seed(0)
    p = build_policy(policy_preset("tiny"), IMG, TXT, enc)
    with torch.no_grad():
        p.action_head.weight.normal_(0, 1.0)  # a peaked, input-dependent action distribution
    p.save(tmp_path / "p.pt", extra={"text_table": {"couch": torch.randn(TXT)}})
    rng = np.random.default_rng(0)
    frames = [
        {
            "rgb": rng.integers(0, 255, (32, 32, 3), dtype=np.uint8),
            "depth": rng.uniform(0.5, 5, (32, 32)).astype(np.float32),
            "goal": "couch",
        }
        for _ in range(8)
    ]

    def run(agent, seed=0):
        agent.reset({"seed": seed})
        return [agent.act(f) for f in frames]

    greedy = run(PolicyAgent(str(tmp_path / "p.pt"), deterministic=True))
    assert run(PolicyAgent(tmp_path / "p.pt", device=torch.device("cpu"))) == greedy  # what torch code passes
    assert run(PolicyAgent(str(tmp_path / "p.pt"), deterministic=False, temperature=1e-4)) == greedy
    hot = PolicyAgent(str(tmp_path / "p.pt"), deterministic=False, temperature=50.0)
    assert run(hot, 3) == run(hot, 3)
    assert len({tuple(run(hot, s)) for s in range(5)}) > 1
    with pytest.raises(ValueError, match="temperature"):
        PolicyAgent(str(tmp_path / "p.pt"), deterministic=False, temperature=0.0)
