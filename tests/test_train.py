"""Training: exact resume, torchrun/DDP, BC overfitting, DAgger/PPO end to end, the policy agent."""

from __future__ import annotations

import dataclasses
import json
import os
import subprocess
import sys
import zlib
from pathlib import Path

import numpy as np
import pytest
import torch

torch.set_num_threads(1)

from ovon.train.bc import SHARD_FORMAT  # noqa: E402
from ovon.train.config import PPOConfig, TrainConfig, train_preset  # noqa: E402
from ovon.train.episodes import adhoc_specs  # noqa: E402
from ovon.train.logging import read_metrics  # noqa: E402
from ovon.train.text import needed_texts, write_text_table  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
GOALS = ["couch", "bed", "toilet", "sink"]


def _hash_vec(text: str, dim: int = 16) -> np.ndarray:
    return np.random.default_rng(zlib.crc32(text.encode())).standard_normal(dim).astype(np.float32)


@pytest.fixture(scope="module")
def house_specs():
    return adhoc_specs([0], categories=GOALS)


@pytest.fixture(scope="module")
def table_path(tmp_path_factory, house_specs) -> str:
    """A hash text table covering the vocabulary: no language model is loaded in these tests."""
    path = tmp_path_factory.mktemp("text") / "table.pt"
    write_text_table(path, {t: _hash_vec(t) for t in needed_texts(house_specs)})
    return str(path)


def write_synthetic_shards(
    folder: Path, episodes: int = 6, image_dim: int = 12, text_dim: int = 8, seed: int = 0
) -> Path:
    """Random embeddings with a learnable rule (action = argmax of the first 6 image dims)."""
    rng = np.random.default_rng(seed)
    folder.mkdir(parents=True, exist_ok=True)
    for s in range(2):
        lengths = rng.integers(5, 30, size=episodes // 2)
        n = int(lengths.sum())
        image = rng.standard_normal((n, image_dim)).astype(np.float16)
        action = image[:, :6].astype(np.float32).argmax(1)
        episode = np.repeat(np.arange(len(lengths)), lengths)
        prev = np.concatenate(
            [np.r_[-1, action[o : o + n_][:-1]] for o, n_ in zip(np.r_[0, np.cumsum(lengths)[:-1]], lengths)]
        )
        torch.save(
            {
                "format": SHARD_FORMAT,
                "image": torch.from_numpy(image),
                "goal": torch.from_numpy(rng.standard_normal((len(lengths), text_dim)).astype(np.float32)),
                "goal_text": ["x"] * len(lengths),
                "episode": torch.from_numpy(episode),
                "prev_action": torch.from_numpy(prev).long(),
                "action": torch.from_numpy(action).long(),
                "lengths": torch.from_numpy(lengths).long(),
                "metrics": [{}] * len(lengths),
                "meta": {},
            },
            folder / f"shard_{s:05d}.pt",
        )
    return folder


def _losses(out: Path) -> list[float]:
    return [r["loss"] for r in read_metrics(out)]


# ----- checkpoint / resume ---------------------------------------------------------------------------
def test_bc_resume_reproduces_losses(tmp_path: Path) -> None:
    from ovon.train import train

    shards = write_synthetic_shards(tmp_path / "shards")
    cfg = train_preset("tiny", algo="bc", max_updates=8, checkpoint_every=2)
    cfg = dataclasses.replace(cfg, bc=dataclasses.replace(cfg.bc, shards=str(shards), batch_chunks=3))
    train(cfg, None, tmp_path / "straight")
    train(dataclasses.replace(cfg, max_updates=4), None, tmp_path / "split")
    train(cfg, None, tmp_path / "split", resume=True)
    a, b = _losses(tmp_path / "straight"), _losses(tmp_path / "split")
    assert len(a) == len(b) == 8
    assert a == b
    from ovon.models.policy import ActorCritic

    pa, pb = ActorCritic.load(tmp_path / "straight" / "policy.pt"), ActorCritic.load(tmp_path / "split" / "policy.pt")
    for (_, x), (_, y) in zip(pa.state_dict().items(), pb.state_dict().items()):
        assert torch.equal(x, y)


def test_bc_in_bfloat16_learns_what_float32_learns(tmp_path: Path) -> None:
    """`learn_dtype=bfloat16`: the forward/backward under autocast (other low bits than float32), the
    weights float32, and the synthetic rule learned as well."""
    from ovon.models.policy import ActorCritic
    from ovon.train import train

    shards = write_synthetic_shards(tmp_path / "shards")
    cfg = train_preset("tiny", algo="bc", max_updates=60, checkpoint_every=60)
    cfg = dataclasses.replace(cfg, bc=dataclasses.replace(cfg.bc, shards=str(shards), batch_chunks=3))
    train(cfg, None, tmp_path / "fp32")
    train(dataclasses.replace(cfg, learn_dtype="bfloat16"), None, tmp_path / "bf16")
    a, b = _losses(tmp_path / "fp32"), _losses(tmp_path / "bf16")
    assert a[0] != b[0] and a[0] == pytest.approx(b[0], rel=0.05)
    assert np.mean(b[-10:]) < 0.6 * b[0] and np.mean(b[-10:]) == pytest.approx(np.mean(a[-10:]), rel=0.05)
    policy = ActorCritic.load(tmp_path / "bf16" / "policy.pt")
    assert all(p.dtype == torch.float32 for p in policy.parameters())


@pytest.mark.parametrize("core", ["transformer", "lstm"])
def test_bfloat16_forward_stays_close_to_float32(core: str) -> None:
    """Under CPU autocast the transformer's attention (the bf16 backward is ~5x slower) and the LSTM (its bf16
    kernel did not repeat beside another thread) run in float32: outputs differ from float32 only by the
    bfloat16 input projection's rounding, and gradients flow."""
    from ovon.models.policy import build_policy

    cfg = train_preset("tiny")
    torch.manual_seed(0)
    policy = build_policy(dataclasses.replace(cfg.policy, core=core), 20, 16, cfg.encoder)
    obs = torch.randn(3, 10, 36)
    prev = torch.zeros(3, 10, dtype=torch.long)
    starts = torch.zeros(3, 10, dtype=torch.bool)
    starts[:, [0, 6]] = True
    ref, _ = policy(obs, prev, starts)
    with torch.autocast("cpu", dtype=torch.bfloat16):
        low, values = policy(obs, prev, starts)
    assert low.dtype == torch.bfloat16
    assert torch.allclose(low.float(), ref, atol=0.05) and not torch.equal(low.float(), ref)
    (low.float().sum() + values.float().sum()).backward()
    assert all(
        p.grad is not None and torch.isfinite(p.grad).all()
        for p in policy.parameters()
        if p.requires_grad and p.grad is not None
    )


def test_make_obs_widens_float16_embeddings_exactly() -> None:
    """The buffer's float16 embeddings are widened inside the concatenation: the same numbers as
    `.float()` first."""
    from ovon.models.policy import ActorCritic

    image = torch.randn(2, 5, 7).half()
    goal = torch.randn(2, 3)
    obs = ActorCritic.make_obs(image, goal)
    assert obs.dtype == torch.float32
    assert torch.equal(obs, torch.cat([image.float(), goal[:, None].expand(2, 5, 3)], -1))
    assert ActorCritic.make_obs(image, goal.half()).dtype == torch.float32
    assert ActorCritic.make_obs(image.double(), goal).dtype == torch.float64  # other dtypes: the image's, as before


@pytest.mark.parametrize(
    "algo",
    [
        "dagger",
        "dagger-aggregated",
        "dagger-context",
        "dagger-overlap",
        "dagger-frontier",
        "dagger-bf16",
        "dagger-bf16-overlap",
        "dagger-bf16-lstm-overlap",
        "ppo",
    ],
)
def test_online_resume_reproduces_losses(tmp_path: Path, house_specs, table_path: str, algo: str) -> None:
    """Envs replay their current episode, the acting memory, the DAgger buffer (with its chunks' context
    views) and every RNG are restored (with `dagger.overlap` also the acting copy and the learner's
    generator, between checkpoints that leave updates learning in the background)."""
    from ovon.train import train
    from ovon.train.config import DaggerConfig

    extra: dict = {}
    n, split = 4, 2
    expert = "shortest-path"
    if algo == "dagger-frontier":  # the cpu recipe's teacher: its chosen frontier and re-choice clock resume too
        from ovon.experts.config import FrontierExpertConfig

        algo, expert = "dagger", "frontier"
        extra = {
            "dagger": DaggerConfig(
                beta_start=1.0, beta_end=0.0, beta_updates=4, buffer_rollouts=3, grad_steps=2, sample_rollouts=2
            ),
            "frontier_expert": FrontierExpertConfig(turn_speed_deg=2.5, rechoose_every=5),
        }
    if algo == "dagger-aggregated":
        algo, extra = "dagger", {"dagger": DaggerConfig(buffer_rollouts=3, grad_steps=2, sample_rollouts=2)}
    if algo == "dagger-context":
        algo, extra = (
            "dagger",
            {"dagger": DaggerConfig(buffer_rollouts=2, grad_steps=2, sample_rollouts=2, context_prefix=True)},
        )
    if algo == "dagger-bf16":  # autocast state is per thread and per process: a resume must re-enter it
        algo, extra = (
            "dagger",
            {"dagger": DaggerConfig(buffer_rollouts=3, grad_steps=2, sample_rollouts=2), "learn_dtype": "bfloat16"},
        )
    if algo in ("dagger-bf16-overlap", "dagger-bf16-lstm-overlap"):  # the learner thread enters autocast itself
        from ovon.models.config import PolicyConfig

        lstm = algo.endswith("lstm-overlap")  # with the LSTM's kept (h, c) too
        algo, n, split = "dagger", 7, 3
        extra = {
            "dagger": DaggerConfig(
                buffer_rollouts=3, grad_steps=2, sample_rollouts=2, overlap=True, context_prefix=True
            ),
            "learn_dtype": "bfloat16",
            "checkpoint_every": 3,
        }
        if lstm:
            extra["policy"] = PolicyConfig(
                core="lstm", hidden=32, layers=1, heads=2, mlp=64, context=16, prev_action_dim=8
            )
    if algo == "dagger-overlap":
        algo, n, split = "dagger", 7, 3
        extra = {
            "dagger": DaggerConfig(buffer_rollouts=3, grad_steps=2, sample_rollouts=2, overlap=True),
            "checkpoint_every": 3,
        }
    if algo == "ppo":  # a PPO minibatch holds whole envs: one env, one minibatch
        extra = {"ppo": PPOConfig(minibatches=1)}
    cfg = train_preset(
        "tiny", algo=algo, expert=expert, num_envs=1, rollout_steps=6, max_updates=n, text_cache=table_path, **extra
    )
    train(cfg, house_specs, tmp_path / "straight")
    train(dataclasses.replace(cfg, max_updates=split), house_specs, tmp_path / "split")
    train(cfg, house_specs, tmp_path / "split", resume=True)
    a, b = _losses(tmp_path / "straight"), _losses(tmp_path / "split")
    assert len(a) == n and a == b
    if algo == "dagger" and cfg.dagger.overlap:  # the student acted one update stale: other data, other losses
        on_policy = dataclasses.replace(cfg, dagger=dataclasses.replace(cfg.dagger, overlap=False))
        train(on_policy, house_specs, tmp_path / "on_policy")
        assert _losses(tmp_path / "on_policy") != a
    if cfg.learn_dtype == "bfloat16":  # bfloat16 did run (other low bits), and learns the same thing
        train(dataclasses.replace(cfg, learn_dtype="float32"), house_specs, tmp_path / "float32")
        c = _losses(tmp_path / "float32")
        assert c[0] != a[0] and c[0] == pytest.approx(a[0], rel=0.05)


def test_atomic_checkpoint_leaves_no_temp(tmp_path: Path) -> None:
    from ovon.train.checkpoint import load_checkpoint, rng_state, save_checkpoint, set_rng_state

    save_checkpoint(tmp_path, {"update": 3, "ranks": [{"rng": rng_state()}]})
    x = torch.rand(3)
    ck = load_checkpoint(tmp_path)
    set_rng_state(ck["ranks"][0]["rng"])
    assert torch.equal(torch.rand(3), x)
    assert [p.name for p in tmp_path.iterdir()] == ["checkpoint.pt"]


def test_checkpoint_rng_states_restore_from_any_device(tmp_path: Path) -> None:
    """A checkpoint loaded with `map_location=cuda` carries its RNG byte tensors to the GPU; torch takes
    generator states only on the CPU (every resume on a GPU failed so). Emulated here with a stand-in
    whose `.cpu()` is the only way back to a CPU tensor."""
    from ovon.train.checkpoint import rng_state, set_rng_state

    class OnDevice:
        def __init__(self, t: torch.Tensor) -> None:
            self.t = t

        def cpu(self) -> torch.Tensor:
            return self.t

    state = rng_state()
    x = torch.rand(3)
    set_rng_state({**state, "torch": OnDevice(state["torch"])})
    assert torch.equal(torch.rand(3), x)


def test_to_device_moves_every_acting_state_kind() -> None:
    """Checkpoints load on the CPU; the acting memory (KV cache dataclass, LSTM (h, c), dicts) goes back to
    the policy's device whole ("meta" stands in for a GPU here), other fields unchanged."""
    from collections import namedtuple

    from ovon.models.transformer import KVState
    from ovon.train.checkpoint import to_device

    kv = KVState(
        k=torch.zeros(1, 2, 1, 3, 4),
        v=torch.zeros(1, 2, 1, 3, 4),
        valid=torch.zeros(2, 3, dtype=torch.bool),
        pos=torch.arange(2),
        slot=2,
    )
    Pair = namedtuple("Pair", "h c")
    moved = to_device(
        {"kv": kv, "lstm": (torch.ones(1), torch.ones(1)), "nt": Pair(torch.ones(1), 3), "n": [None]}, "meta"
    )
    assert isinstance(moved["kv"], KVState) and moved["kv"].slot == 2
    assert all(t.is_meta for t in (moved["kv"].k, moved["kv"].v, moved["kv"].valid, moved["kv"].pos))
    assert isinstance(moved["lstm"], tuple) and all(t.is_meta for t in moved["lstm"])
    assert isinstance(moved["nt"], Pair) and moved["nt"].h.is_meta and moved["nt"].c == 3
    assert moved["n"] == [None] and not kv.k.is_meta  # the original is untouched


def test_cuda_rng_states_of_more_gpus_than_this_machine_has(monkeypatch) -> None:
    """A checkpoint holds one CUDA generator state per GPU the saving process saw; resuming where fewer
    are visible restores those there are (torch raised IndexError)."""
    from ovon.train.checkpoint import rng_state, set_rng_state

    got: list = []
    state = {**rng_state(), "cuda": [torch.zeros(8, dtype=torch.uint8), torch.ones(8, dtype=torch.uint8)]}
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    monkeypatch.setattr(torch.cuda, "device_count", lambda: 1)
    monkeypatch.setattr(torch.cuda, "set_rng_state_all", lambda states: got.extend(states))
    set_rng_state(state)
    assert len(got) == 1 and torch.equal(got[0], torch.zeros(8, dtype=torch.uint8))


def test_a_rank_without_its_gpu_is_refused_in_one_line(monkeypatch) -> None:
    from ovon.config.base import ConfigError
    from ovon.train.distributed import resolve_device

    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    monkeypatch.setattr(torch.cuda, "device_count", lambda: 1)
    assert resolve_device("auto", 0) == torch.device("cuda:0")
    assert resolve_device("cuda", 0) == torch.device("cuda:0")
    assert resolve_device("cpu", 3) == torch.device("cpu")
    for pref, rank in (("auto", 1), ("cuda", 1), ("cuda:2", 0)):
        with pytest.raises(ConfigError, match=r"CUDA sees 1 GPU.*--nproc_per_node 1.*device=cpu"):
            resolve_device(pref, rank)
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    assert resolve_device("auto", 1) == torch.device("cpu")
    with pytest.raises(ConfigError, match=r"no GPU.*fix: --set device=auto"):
        resolve_device("cuda", 0)


def test_cli_train_on_a_missing_gpu_is_refused(tmp_path: Path, table_path: str, capsys) -> None:
    from tests.cli_errors import one_line, run

    if torch.cuda.is_available():
        pytest.skip("this machine has a GPU")
    rc, _, err = run(
        [
            "train",
            "--algo",
            "dagger",
            "--preset",
            "tiny",
            "--expert",
            "shortest-path",
            "--procedural",
            "0",
            "--episodes",
            "3",
            "--set",
            f"text_cache={table_path}",
            "--set",
            "device=cuda",
            "--out",
            str(tmp_path / "run"),
        ],
        capsys,
    )
    one_line(rc, err, "device = cuda", "no GPU")
    assert not (tmp_path / "run").exists()


# ----- distributed ------------------------------------------------------------------------------------
def test_torchrun_two_ranks_stay_in_sync(tmp_path: Path) -> None:
    shards = write_synthetic_shards(tmp_path / "shards", episodes=8)
    out = tmp_path / "run"
    env = {**os.environ, "OMP_NUM_THREADS": "1", "PYTHONPATH": str(ROOT)}
    cmd = [
        sys.executable,
        "-m",
        "torch.distributed.run",
        "--standalone",
        "--nproc_per_node",
        "2",
        "-m",
        "ovon.cli.main",
        "train",
        "--algo",
        "bc",
        "--preset",
        "tiny",
        "--out",
        str(out),
        "--set",
        f"bc.shards={shards}",
        "--set",
        "max_updates=3",
        "--set",
        "bc.batch_chunks=2",
        "--set",
        "device=cpu",
    ]  # gloo on any machine (a one-GPU machine refuses two ranks with device=auto)
    r = subprocess.run(cmd, env=env, cwd=ROOT, capture_output=True, text=True, timeout=300)
    if r.returncode != 0 and any(s in r.stderr for s in ("EADDRINUSE", "address already in use", "bind")):
        pytest.skip(f"cannot bind a rendezvous port: {r.stderr[-300:]}")
    assert r.returncode == 0, r.stderr[-3000:]
    ranks = [json.loads((out / "ranks" / f"rank{i}.json").read_text()) for i in range(2)]
    assert [x["world_size"] for x in ranks] == [2, 2]
    assert ranks[0]["checksum"] == ranks[1]["checksum"]
    assert len(read_metrics(out)) == 3  # rank 0 only logs
    from ovon.train.checkpoint import load_checkpoint

    assert len(load_checkpoint(out)["ranks"]) == 2


# ----- learning ---------------------------------------------------------------------------------------
def test_bc_overfits_recorded_expert_episodes(tmp_path: Path, house_specs, table_path: str) -> None:
    from ovon.train import train
    from ovon.train.bc import load_shards

    cfg = train_preset(
        "tiny",
        algo="bc",
        expert="shortest-path",
        max_updates=300,
        checkpoint_every=1000,
        lr=3e-3,
        text_cache=table_path,
    )
    cfg = dataclasses.replace(
        cfg,
        bc=dataclasses.replace(cfg.bc, record_episodes=3, episodes_per_shard=2, batch_chunks=8),
        policy=dataclasses.replace(cfg.policy, context=64),
    )  # whole episodes in context
    last = train(cfg, house_specs, tmp_path / "bc")
    data = load_shards(tmp_path / "bc" / "shards", cfg.policy.context)
    assert len(data.chunks) >= 3 and int(data.start.sum()) == 3
    losses = _losses(tmp_path / "bc")
    assert losses[0] > 1.0
    assert last["loss"] < 0.05, losses[-10:]
    assert last["accuracy"] > 0.97, last


# ----- DAgger / PPO end to end + the policy agent -----------------------------------------------------
def test_dagger_then_ppo_finetune_then_agent(tmp_path: Path, house_specs, table_path: str) -> None:
    from ovon.agents import make_agent
    from ovon.env import make_objectnav
    from ovon.evaluate.runner import run_episode
    from ovon.train import train

    cfg = train_preset("tiny", algo="dagger", expert="shortest-path", text_cache=table_path)
    train(cfg, house_specs, tmp_path / "dagger")
    for name in ("checkpoint.pt", "policy.pt", "metrics.jsonl"):
        assert (tmp_path / "dagger" / name).is_file()
    assert list((tmp_path / "dagger" / "tb").glob("events.out.tfevents.*"))
    assert [r["update"] for r in read_metrics(tmp_path / "dagger")] == [1, 2]

    ft = dataclasses.replace(cfg, algo="ppo")
    last = train(ft, house_specs, tmp_path / "ft", init=str(tmp_path / "dagger"))
    assert last["lr/actor"] == 0.0 and last["lr/critic"] > 0
    assert list((tmp_path / "ft" / "tb").glob("events.out.tfevents.*"))
    from ovon.models.policy import ActorCritic

    before, after = ActorCritic.load(tmp_path / "dagger" / "policy.pt"), ActorCritic.load(tmp_path / "ft" / "policy.pt")
    assert torch.equal(before.prev_action_emb.weight, after.prev_action_emb.weight)  # frozen
    assert torch.equal(before.action_head.weight, after.action_head.weight)  # actor lr 0 so far
    assert not torch.equal(before.critic_head.weight, after.critic_head.weight)

    agent = make_agent("policy", checkpoint=str(tmp_path / "ft" / "policy.pt"))
    assert agent.privileged
    env = make_objectnav(episodes=house_specs[:1], sim=cfg.sim, task=cfg.task, privileged=True)
    rec = run_episode(env, agent, house_specs[0], seed=0)
    env.close()
    assert 1 <= rec["steps"] <= cfg.task.max_steps


def test_ppo_from_scratch_lstm(tmp_path: Path, house_specs, table_path: str) -> None:
    from ovon.train import train

    cfg = train_preset("tiny", algo="ppo", text_cache=table_path)
    cfg = dataclasses.replace(cfg, policy=dataclasses.replace(cfg.policy, core="lstm"))
    last = train(cfg, house_specs, tmp_path / "ppo")
    assert np.isfinite(last["loss"]) and "lr/all" in last
    assert (tmp_path / "ppo" / "policy.pt").is_file()


def test_train_envs_workers_match_in_process(house_specs, table_path: str) -> None:
    """The training env stack (labels + oracle embeddings + sampler) gives the same batches in this
    process and on 2 workers; a saved state replays to the same observation."""
    from ovon.env.stack import EnvRecipe
    from ovon.train.envs import TrainEnvs
    from ovon.train.run import expert_config
    from ovon.train.text import text_table

    cfg = train_preset("tiny", algo="dagger", expert="shortest-path", num_envs=2, text_cache=table_path)
    table = text_table(cfg.encoder, needed_texts(house_specs), table_path, write=False)
    recipe = EnvRecipe(
        sim=cfg.sim,
        task=cfg.task,
        encoder=cfg.encoder,
        text_table={k: v.numpy() for k, v in table.items()},
        expert=cfg.expert,
        expert_cfg=expert_config(cfg),
        scene_repeat=cfg.scene_repeat,
    )
    runs = []
    for workers in (0, 2):
        envs = TrainEnvs(recipe, house_specs, 2, workers, base_seed=0)
        try:
            b = envs.reset()
            seq = [(b.image.clone(), b.label.clone())]
            for t in range(5):
                b = envs.step(torch.tensor([1, 2]))
                seq.append((b.image.clone(), b.label.clone()))
                if t == 2:
                    state = envs.get_state()
            replayed = envs.set_state(state)
            assert torch.equal(replayed.image, seq[3][0]) and torch.equal(replayed.label, seq[3][1])
            assert not replayed.first.any()
            runs.append(seq)
        finally:
            envs.close()
    for (ia, la), (ib, lb) in zip(*runs):
        assert torch.equal(ia, ib) and torch.equal(la, lb)


def test_dagger_with_trainable_cnn(tmp_path: Path, house_specs, table_path: str) -> None:
    """With the CNN encoder the workers send frames and the policy's own CNN is trained."""
    from ovon.models.policy import ActorCritic
    from ovon.train import train

    cfg = train_preset("tiny", algo="dagger", expert="shortest-path", max_updates=1, text_cache=table_path)
    cfg = dataclasses.replace(
        cfg, encoder=dataclasses.replace(cfg.encoder, image="cnn", cnn_dim=16, cnn_channels=(8, 16), cnn_depth=True)
    )
    train(cfg, house_specs, tmp_path / "cnn")
    policy = ActorCritic.load(tmp_path / "cnn" / "policy.pt")
    assert policy.image_encoder is not None


def test_cli_train_procedural(tmp_path: Path, table_path: str) -> None:
    from ovon.cli.main import main

    out = tmp_path / "run"
    args = [
        "train",
        "--algo",
        "dagger",
        "--preset",
        "tiny",
        "--expert",
        "shortest-path",
        "--procedural",
        "0",
        "--episodes",
        "3",
        "--set",
        f"text_cache={table_path}",
        "--out",
        str(out),
    ]
    assert main(args) == 0
    assert (out / "policy.pt").is_file() and (out / "config.json").is_file()
    assert main(args) == 2  # refuses to overwrite a run without --resume
    assert main([*args[:-2], "--set", "max_updates=3", "--resume", "--out", str(out)]) == 0
    assert [r["update"] for r in read_metrics(out)] == [1, 2, 3]


def test_cli_train_resume_refuses_another_run(tmp_path: Path, table_path: str, capsys) -> None:
    """`--resume` continues only the same run: another algorithm or model is one line naming it."""
    from ovon.cli.main import main
    from ovon.runfolder import FileLock

    out = tmp_path / "run"
    base = [
        "--preset",
        "tiny",
        "--expert",
        "shortest-path",
        "--procedural",
        "0",
        "--episodes",
        "3",
        "--set",
        f"text_cache={table_path}",
        "--out",
        str(out),
    ]
    assert main(["train", "--algo", "dagger", *base]) == 0
    capsys.readouterr()
    assert main(["train", "--algo", "ppo", *base, "--resume"]) == 2
    assert 'algo "dagger" -> "ppo"' in capsys.readouterr().err
    assert main(["train", "--algo", "dagger", *base, "--set", "policy.layers=3", "--resume"]) == 2
    assert "policy.layers 1 -> 3" in capsys.readouterr().err
    with FileLock(out / ".lock"):  # a second writer
        assert main(["train", "--algo", "dagger", *base, "--resume"]) == 2
        assert "in use by another ovon process" in capsys.readouterr().err


# ----- schedule / config / CLI ------------------------------------------------------------------------
def test_finetune_schedule_matches_baselines() -> None:
    from ovon.train.config import FinetuneConfig
    from ovon.train.finetune import finetune_lrs

    ft = FinetuneConfig()
    assert finetune_lrs(ft, 0) == (2.5e-4, 0.0)
    assert finetune_lrs(ft, 500) == (2.5e-4, 0.0)
    c, a = finetune_lrs(ft, 750)
    assert c == pytest.approx((2.5e-4 + 1.5e-5) / 2) and a == 0.0
    c, a = finetune_lrs(ft, 875)
    assert a == pytest.approx(1.5e-5 / 2)
    assert finetune_lrs(ft, 1000) == pytest.approx((1.5e-5, 1.5e-5))
    assert finetune_lrs(ft, 5000) == pytest.approx((1.5e-5, 1.5e-5))
    half = dataclasses.replace(ft, scale=0.5)
    assert finetune_lrs(half, 500) == pytest.approx((1.5e-5, 1.5e-5))
    step = dataclasses.replace(ft, critic_decay_start=500, critic_decay_end=500)  # allowed: a step at 500
    assert finetune_lrs(step, 499)[0] == 2.5e-4 and finetune_lrs(step, 500)[0] == pytest.approx(1.5e-5)


def test_paper_preset_has_upstream_hyperparameters() -> None:
    cfg = train_preset("paper")
    assert (cfg.num_envs, cfg.rollout_steps, cfg.ppo.epochs, cfg.ppo.minibatches) == (32, 100, 1, 2)
    assert (cfg.lr, cfg.adam_eps, cfg.max_grad_norm) == (2.5e-4, 1e-5, 0.2)
    assert (cfg.ppo.entropy_coef, cfg.ppo.clip, cfg.ppo.value_coef, cfg.ppo.gamma, cfg.ppo.gae_lambda) == (
        0.01,
        0.2,
        0.5,
        0.99,
        0.95,
    )
    assert cfg.total_steps == 150_000_000 and cfg.policy.context == 100 and cfg.encoder.image == "siglip"


def test_cli_config_overrides() -> None:
    import argparse

    from ovon.cli.train import build_config, register

    parser = argparse.ArgumentParser()
    register(parser.add_subparsers())
    args = parser.parse_args(
        [
            "train",
            "--algo",
            "ppo",
            "--policy",
            "lstm",
            "--encoder",
            "cnn",
            "--preset",
            "tiny",
            "--set",
            "ppo.clip=0.1",
            "--set",
            "num_envs=3",
            "--out",
            "x",
        ]
    )
    cfg = build_config(args)
    assert isinstance(cfg, TrainConfig)
    assert (cfg.algo, cfg.policy.core, cfg.encoder.image, cfg.ppo.clip, cfg.num_envs) == ("ppo", "lstm", "cnn", 0.1, 3)
    from ovon.config.base import ConfigError

    with pytest.raises(ConfigError):
        build_config(parser.parse_args(["train", "--algo", "bc", "--set", "nope=1", "--out", "x"]))


def test_imitation_loss_weights_stop_and_ignores_unlabelled() -> None:
    from ovon.train.batches import imitation_loss

    logits = torch.randn(2, 5, 6, generator=torch.Generator().manual_seed(0))
    target = torch.tensor([[0, 1, 2, -1, 3], [1, 1, 0, 2, -1]])
    valid = target >= 0
    plain = torch.nn.functional.cross_entropy(logits[valid], target[valid])
    assert torch.allclose(imitation_loss(logits, target), plain)
    per = torch.nn.functional.cross_entropy(logits[valid], target[valid], reduction="none")
    w = torch.where(target[valid] == 0, 4.0, 1.0)
    assert torch.allclose(imitation_loss(logits, target, stop_weight=4.0), (per * w).sum() / w.sum())


def test_dagger_buffer_keeps_its_checkpoint_form() -> None:
    """DAgger's buffered chunks go into a checkpoint as the plain tuples and dicts it has always held (a
    checkpoint from before context_prefix, without context or LSTM state, still loads); a context part two
    entries share stays one object, and a chunk is read after exactly `prefix` context steps."""
    from ovon.models.chunk import Chunk, last_steps
    from ovon.train.dagger import buffer_from_saved, buffer_to_saved

    def chunk(seed: int) -> Chunk:
        g = torch.Generator().manual_seed(seed)
        steps = (2, 3)
        return Chunk(
            torch.randn(*steps, 4, generator=g),
            torch.randn(*steps, 5, generator=g),
            torch.randint(0, 6, steps, generator=g),
            torch.zeros(steps, dtype=torch.bool),
            torch.randint(0, 6, steps, generator=g),
        )

    a, b, c = chunk(0), chunk(1), chunk(2)
    b.context = last_steps([a.observations()], 7)
    c.context = last_steps([*b.context, b.observations()], 7)  # all of a (b's part) and of b
    saved = buffer_to_saved([a, b, c])
    assert all(len(e) == 7 and isinstance(e, tuple) for e in saved)
    assert saved[1][5][0] is saved[2][5][0] and set(saved[2][5][1]) == {"images", "goals", "prevs", "starts"}
    back = buffer_from_saved(saved)
    assert back[1].context[0] is back[2].context[0] and torch.equal(back[2].labels, c.labels)
    seq = back[2].with_context(7)  # 6 context steps and 1 of padding (an episode start) before the chunk
    assert seq.prefix == 7 and seq.length == 10 and bool(seq.starts[:, 0].all())
    assert torch.equal(seq.goals[:, 1:], torch.cat([a.goals, b.goals, c.goals], 1))
    old = buffer_from_saved([(a.images, a.goals, a.prevs, a.starts, a.labels)])[0]
    assert old.context == [] and old.state0 is None and old.with_context(2).length == 5


def test_evaluate_uses_the_camera_a_policy_was_trained_with(tmp_path) -> None:
    from ovon.evaluate.config import checkpoint_facts
    from ovon.models.config import EncoderConfig, policy_preset
    from ovon.models.policy import build_policy

    policy = build_policy(policy_preset("tiny"), 8, 4, EncoderConfig())
    policy.save(
        tmp_path / "policy.pt",
        extra={"camera": {"width": 96, "height": 72, "hfov_deg": 42.0, "backend": "gl", "not_a_field": 1}},
    )
    assert checkpoint_facts(str(tmp_path), "objectnav") == {"width": 96, "height": 72, "hfov_deg": 42.0}
    policy.save(tmp_path / "bare.pt")
    assert checkpoint_facts(str(tmp_path / "bare.pt"), "objectnav") == {}
    with pytest.raises(FileNotFoundError, match="missing.pt"):
        checkpoint_facts(str(tmp_path / "missing.pt"), "objectnav")


def test_expert_config_reaches_the_labelling_expert() -> None:
    """`--set frontier_expert.KEY=V` changes the expert that labels DAgger / BC states."""
    from ovon.config.base import ConfigError, build
    from ovon.experts.factory import make_expert
    from ovon.train.config import TrainConfig, train_preset
    from ovon.train.run import expert_config

    cfg = build(
        TrainConfig,
        train_preset("tiny"),
        None,
        ["frontier_expert.turn_speed_deg=2.5", "shortest_path_expert.turn_threshold_deg=30"],
    )
    assert make_expert("frontier", expert_config(cfg)).cfg.turn_speed_deg == 2.5
    sp = dataclasses.replace(cfg, expert="shortest-path")
    assert make_expert("shortest-path", expert_config(sp)).cfg.turn_threshold_deg == 30
    assert make_expert("frontier").cfg.turn_speed_deg == 10.0  # spec default without a config
    with pytest.raises(ConfigError, match="turn_sped_deg"):
        build(TrainConfig, train_preset("tiny"), None, ["frontier_expert.turn_sped_deg=1"])


def test_expert_embodiment_follows_the_sim_and_task_config() -> None:
    """The labelling expert's turn angle, step, FOV and stop radius come from `sim.*` / `task.*`: they
    cannot disagree, and the experts' own configs no longer hold copies."""
    from ovon.config.base import ConfigError, build
    from ovon.env.stack import EnvRecipe, build_env
    from ovon.experts.rig import Embodiment
    from ovon.train.config import TrainConfig, train_preset

    cfg = build(
        TrainConfig,
        train_preset("tiny"),
        None,
        [
            "sim.agent.turn_angle_deg=15",
            "sim.agent.forward_step=0.2",
            "sim.camera.hfov_deg=79",
            "task.success_distance=0.1",
        ],
    )
    env = build_env(EnvRecipe(sim=cfg.sim, task=cfg.task, scene="procedural:0", goal="bed", expert="frontier"))
    body = env.expert.body
    assert body == Embodiment(turn_angle_deg=15.0, forward_step_m=0.2, fov_deg=79.0, stop_distance_m=0.1)
    env.close()
    for key in ("turn_angle_deg", "forward_step_m", "fov_deg", "stop_distance_m"):
        with pytest.raises(ConfigError, match=key):
            build(TrainConfig, train_preset("tiny"), None, [f"frontier_expert.{key}=1"])


def test_inner_viewpoints_keep_those_close_to_a_goal_box() -> None:
    from types import SimpleNamespace

    from ovon.env.labels import inner_viewpoints
    from ovon.task.episode import GoalViewpoint

    box = SimpleNamespace(id=7, aabb_min=np.array([0.0, 0.0, 0.0]), aabb_max=np.array([1.0, 1.0, 1.0]))
    other = SimpleNamespace(id=8, aabb_min=np.array([5.0, 0.0, 5.0]), aabb_max=np.array([6.0, 1.0, 6.0]))
    vps = [
        GoalViewpoint(np.array([1.3, 0.0, 0.5]), 0.0),  # 0.3 m from the goal box
        GoalViewpoint(np.array([0.5, 0.0, -0.9]), 0.0),  # 0.9 m
        GoalViewpoint(np.array([5.5, 0.0, 4.8]), 0.0),
    ]  # next to a non-goal object only
    p = SimpleNamespace(
        viewpoints=vps, goal_ids=frozenset({7}), world=SimpleNamespace(scene=SimpleNamespace(objects=[box, other]))
    )
    assert inner_viewpoints(p, 0.4) == [vps[0]]
    assert inner_viewpoints(p, 1.0) == vps[:2]
    assert inner_viewpoints(p, 0.0) == vps  # 0 = all
    assert inner_viewpoints(p, 0.1) == vps  # none that close: fall back to all


def test_cpu_small_features_end_to_end(tmp_path: Path, house_specs, table_path: str) -> None:
    """The inputs and labels that made cpu-small learn, at tiny size: goal similarity, depth grid and
    collision flag from the worker's encoder, no previous-action input, the inner-viewpoint frontier
    expert with a STOP weight; then a fine-tune that trains the (absent) prev-action group, and the agent."""
    from ovon.agents import make_agent
    from ovon.env import make_objectnav
    from ovon.evaluate.runner import run_episode
    from ovon.experts.config import FrontierExpertConfig
    from ovon.train import train

    cfg = train_preset(
        "tiny",
        algo="dagger",
        text_cache=table_path,
        stop_loss_weight=2.0,
        expert_viewpoint_radius_m=0.4,
        frontier_expert=FrontierExpertConfig(turn_speed_deg=2.5, rechoose_every=5),
    )
    cfg = dataclasses.replace(
        cfg,
        policy=dataclasses.replace(cfg.policy, prev_action_dim=0, goal_similarity=True),
        encoder=dataclasses.replace(cfg.encoder, oracle_depth_grid=(2, 2), oracle_collision=True),
        dagger=dataclasses.replace(cfg.dagger, beta_start=1.0, beta_updates=2, buffer_rollouts=4, grad_steps=2),
    )
    last = train(cfg, house_specs, tmp_path / "dagger")
    assert np.isfinite(last["loss"]) and 0.0 <= last["accuracy"] <= 1.0
    ft = dataclasses.replace(cfg, algo="ppo", finetune=dataclasses.replace(cfg.finetune, freeze_prev_action=False))
    train(ft, house_specs, tmp_path / "ft", init=str(tmp_path / "dagger"))
    agent = make_agent("policy", checkpoint=str(tmp_path / "ft" / "policy.pt"), deterministic=False, temperature=0.5)
    assert agent.policy.prev_action_emb is None and agent.policy.sim_parts == 1
    assert agent.image_encoder.dim == agent.policy.image_dim  # 1 text part + 8 depth + 1 collision
    env = make_objectnav(episodes=house_specs[:1], sim=cfg.sim, task=cfg.task, privileged=True)
    rec = run_episode(env, agent, house_specs[0], seed=0)
    env.close()
    assert 1 <= rec["steps"] <= cfg.task.max_steps


def test_cli_trains_dagger_in_bfloat16_and_refuses_it_for_ppo(tmp_path: Path, capsys) -> None:
    """`--set learn_dtype=bfloat16` from the command line: DAgger trains (the run's config records it, and no
    torch warning reaches the user); PPO is refused in one line before anything is written."""
    from ovon.cli.main import main

    base = [
        "train",
        "--preset",
        "tiny",
        "--procedural",
        "0",
        "--episodes",
        "2",
        "--expert",
        "shortest-path",
        "--set",
        "learn_dtype=bfloat16",
    ]
    assert main([*base, "--algo", "dagger", "--out", str(tmp_path / "dagger")]) == 0
    assert json.loads((tmp_path / "dagger" / "config.json").read_text())["learn_dtype"] == "bfloat16"
    assert "Mismatch dtype" not in capsys.readouterr().err
    assert main([*base, "--algo", "ppo", "--out", str(tmp_path / "ppo")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "learn_dtype float32 for algo ppo" in err[0] and "fix:" in err[0]
    assert not (tmp_path / "ppo").exists()


@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        (["--algos", "ppo-bf16"], "ppo takes no variant '-bf16'"),
        (["--algos", "bc-overlap"], "bc takes no variant '-overlap'"),
        (["--algos", "dagerr"], "unknown algorithm 'dagerr'"),
        (["--set", "learn_dtype=bfloat16"], "learn_dtype float32 for algo ppo"),  # the default algos include ppo
    ],
)
def test_train_throughput_refuses_a_bad_algorithm_before_any_work(tmp_path: Path, argv: list[str], needle: str) -> None:
    out = tmp_path / "bench.json"
    res = subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / "train_throughput.py"), *argv, "--out", str(out)],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=ROOT,
    )
    lines = res.stderr.strip().splitlines()
    assert res.returncode != 0 and len(lines) == 1 and needle in lines[0], res.stderr
    assert not out.exists()
