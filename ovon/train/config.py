"""Training configs: one dataclass tree for BC, DAgger and PPO (+ BC->RL / DAgger->RL fine-tuning).

Why one tree: every number of docs/spec.md#baselines is a config value reachable from YAML or `--set key=value`
(`ovon.config.base.build`), and a checkpoint stores the whole tree so `--resume` and the policy agent
rebuild exactly what was trained. Presets: `paper` (upstream hyperparameters), `cpu-small` (learns on
a 2-core CPU in tens of minutes), `tiny` (tests: seconds).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any, ClassVar, Literal

from ovon.config.base import Pattern, constrained, in_range, less, non_negative, positive, rule
from ovon.config.sim import CameraConfig, SimConfig, cpu_sim_config
from ovon.config.task import RewardConfig, TaskConfig, pointnav_task
from ovon.experts.config import FrontierExpertConfig, ShortestPathExpertConfig
from ovon.models.config import EncoderConfig, PolicyConfig

Algo = Literal["bc", "dagger", "ppo"]
ExpertName = Literal["frontier", "shortest-path"]


@dataclass(frozen=True)
class PPOConfig:
    """PPO (upstream values). Minibatches split the envs, so each minibatch holds whole sequences."""

    epochs: int = positive(1)
    minibatches: int = positive(2)
    clip: float = positive(0.2)
    value_coef: float = non_negative(0.5)
    entropy_coef: float = non_negative(0.01)
    gamma: float = in_range(0.99, 0.0, 1.0)
    gae_lambda: float = in_range(0.95, 0.0, 1.0)
    normalize_advantages: bool = True
    # The policy PPO acts with and optimises is softmax(logits / temperature). A fine-tune of an imitation
    # policy that is evaluated at temperature 0.5 (docs/concepts/learned-policies.md) should be trained at 0.5
    # too: at 1 its rollouts rarely succeed, the sparse reward gives no signal and the policy drifts away from
    # what worked.
    temperature: float = positive(1.0)
    # A transformer acts with a key/value cache of `policy.context` steps per layer that crosses rollout
    # chunks; each cached key was computed from its own step's window, so acting sees layers x (context - 1)
    # steps back. The update re-reads each chunk after that many earlier steps (no loss on them), so the
    # logits it optimises are the ones the actions were sampled from (costs layers x context extra steps of
    # forward/backward per chunk). false: the chunk alone (the update then optimises a shorter-context
    # policy than the one that acted).
    context_prefix: bool = True


@dataclass(frozen=True)
class FinetuneConfig:
    """BC->RL / DAgger->RL schedule (docs/spec.md#fine-tune-schedule), in updates; `scale` stretches or shrinks it.

    critic lr: `critic_lr` until `critic_decay_start`, then linear to `critic_lr_final` at
    `critic_decay_end`. actor (+ core + input projection) lr: 0 until `actor_unfreeze`, then linear
    from 0 to `actor_lr` at `actor_warmup_end`. The prev-action embedding stays frozen.
    """

    critic_lr: float = non_negative(2.5e-4)
    critic_lr_final: float = non_negative(1.5e-5)
    critic_decay_start: int = non_negative(500)
    critic_decay_end: int = non_negative(1000)
    actor_lr: float = non_negative(1.5e-5)
    actor_unfreeze: int = non_negative(750)
    actor_warmup_end: int = non_negative(1000)
    freeze_prev_action: bool = True
    reinit_critic: bool = True
    reward: Literal["sparse", "dense"] = "sparse"
    scale: float = positive(1.0)  # multiplies every update number above and below
    # What keeps the imitation policy while RL takes over (kickstarting / DAPG): a loss term
    # anchor_coef x (cross-entropy to the expert's online labels | KL(initial policy || policy)),
    # its weight decaying linearly to 0 over `anchor_decay_updates` (0: constant).
    anchor: Literal["none", "expert", "kl"] = "none"
    anchor_coef: float = non_negative(1.0)
    anchor_decay_updates: int = non_negative(0)
    # The actor stays frozen (beyond `actor_unfreeze`) until the critic's explained variance on a
    # rollout reaches this; once reached the gate stays open. 0: no gate.
    critic_warmup_ev: float = in_range(0.0, 0.0, 1.0, hi_open=True)
    # shared: the value is a fresh linear head on the imitation policy's features (upstream). Those features
    # were trained to pick the expert's action; a linear read of them explains ~0 of the returns' variance
    # (measured: DAgRL's explained variance stayed in -0.1..0.05 for 300 updates), so the actor learns from
    # advantages that are nearly noise. separate: the critic is its own copy of the initial network (core +
    # fresh value head), every weight of it at the critic lr; the actor's weights get no value gradient.
    critic: Literal["shared", "separate"] = "shared"
    rules: ClassVar = (
        less("critic_decay_start", "critic_decay_end", strict=False),
        less("actor_unfreeze", "actor_warmup_end", strict=False),
    )


@dataclass(frozen=True)
class DaggerConfig:
    """beta = probability that the expert's label (not the student's sample) drives the env.

    Linear from `beta_start` to `beta_end` over `beta_updates` updates; upstream used beta = 0.
    """

    beta_start: float = in_range(0.0, 0.0, 1.0)
    beta_end: float = in_range(0.0, 0.0, 1.0)
    beta_updates: int = non_negative(0)
    # Dataset aggregation: keep the last `buffer_rollouts` labelled rollouts (1 = on-policy only, as
    # upstream) and take `grad_steps` optimiser steps per update, each on `sample_rollouts` of them (the
    # newest always included). On a CPU the rollout costs ~40x a gradient step, so reusing labels is
    # what makes DAgger learn in minutes.
    buffer_rollouts: int = positive(1)
    grad_steps: int = positive(1)
    sample_rollouts: int = positive(1)
    # Learn while the envs step: the gradient steps of update u run in a thread during rollout u+1, which
    # acts with the weights of update u-1 (one update staler than on-policy DAgger; deterministic, since
    # the schedule, not the timing, decides which weights act). On a small CPU the learner uses a core
    # the env workers leave idle. One process only (not under torchrun).
    overlap: bool = False
    # Learn from what acting saw: each buffered chunk keeps (as views of the chunks before it, no copy) the
    # `layers x (context - 1)` earlier steps a KV-cached transformer's acting read, or the LSTM's acting
    # (h, c) at its start, and the update re-reads the chunk after them (loss on the chunk only), as PPO's
    # `ppo.context_prefix`. false: each chunk is re-read alone (an LSTM from a zero state), so the update
    # fits a shorter-memory policy than the one that acts; the transformer's update then costs ~3x less
    # on cpu-small (64-step chunks, 126 steps of context).
    context_prefix: bool = False
    rules: ClassVar = (less("sample_rollouts", "buffer_rollouts", strict=False),)


@dataclass(frozen=True)
class BCConfig:
    """Offline BC: record expert episodes as shards, then cross-entropy on chunks of <= context steps."""

    shards: str = ""  # folder of recorded shards; "" = <out>/shards (recorded when missing)
    record_episodes: int = positive(1000)  # episodes to record when the shards are missing
    episodes_per_shard: int = positive(50)
    record_workers: int = non_negative(2)
    batch_chunks: int = positive(32)  # chunks per update (per rank)
    epochs: int = positive(10)  # passes over the chunks (unless `max_updates` > 0 caps it)


@dataclass(frozen=True)
class CurriculumConfig:
    """Start-distance curriculum (RL from scratch): an env's first episodes start within `start_m` of the goal
    (geodesic, the dataset's `info.geodesic_distance`); the cap grows linearly to every episode. `start_m` 0 = off.

    unit `updates` (default): the cap covers every episode after `fraction` of the run's updates, the same
    update for every env, so the curriculum ends when the schedule says, whatever the episode lengths.
    unit `episodes`: each env's cap grows with the episodes it has started and covers every episode after
    `episodes` of them (how it was counted before; a 1000-update run ended with ~237 of 300 per env).
    """

    start_m: float = non_negative(0.0)
    unit: Literal["updates", "episodes"] = "updates"
    fraction: float = in_range(0.5, 0.0, 1.0, lo_open=True)
    episodes: int = positive(300)


@dataclass(frozen=True)
class TrainConfig:
    algo: Algo = "dagger"
    policy: PolicyConfig = field(default_factory=PolicyConfig)
    # learned perception unless a preset or `--encoder` names another: ovon's pretrained world-vl (shipped
    # weights); the oracle (`oracle-vl`, ORACLE PERCEPTION) only when asked for by name
    encoder: EncoderConfig = field(default_factory=lambda: EncoderConfig(image="world-vl"))
    sim: SimConfig = field(default_factory=cpu_sim_config)
    task: TaskConfig = field(default_factory=TaskConfig)
    expert: ExpertName = "frontier"
    frontier_expert: FrontierExpertConfig = field(default_factory=FrontierExpertConfig)
    shortest_path_expert: ShortestPathExpertConfig = field(default_factory=ShortestPathExpertConfig)
    # > 0: the labelling expert aims at goal viewpoints within this distance (m) of a goal object's box
    # (all viewpoints when none is), so its STOP labels come where the goal fills the view. 0 = all.
    expert_viewpoint_radius_m: float = non_negative(0.0)
    # Environments / rollouts (per rank).
    num_envs: int = positive(32)
    env_workers: int = in_range(-1, -1, None)  # processes for the envs: -1 = one per env, 0 = in this process
    rollout_steps: int = positive(100)
    scene_repeat: int = positive(16)  # episodes sampled from a scene before an env may switch scene (world reloads)
    curriculum: CurriculumConfig = field(default_factory=CurriculumConfig)
    # Evaluation's STOP rule for the last part of training: from this fraction of the run's updates on, a STOP
    # outside the success region ends a training episode as a failure even with `task.failed_stop_ends` false
    # (the rule every evaluated episode follows), so the policy is scored by the rules it last trained under.
    # 1 = never (the whole run under `task.failed_stop_ends`); no effect when that is true.
    failed_stop_ends_from: float = in_range(0.75, 0.0, 1.0)
    # Budget: environment steps over all ranks; `max_updates` > 0 caps the number of updates instead.
    total_steps: int = positive(150_000_000)
    max_updates: int = non_negative(0)
    # Optimiser.
    lr: float = non_negative(2.5e-4)  # 0 = a frozen policy (the ratio-1 diagnostic of PPO)
    adam_eps: float = positive(1e-5)
    max_grad_norm: float = positive(0.2)
    # Imitation (BC, DAgger): weight of the STOP class in the cross-entropy. STOP is ~1% of the labels
    # but one missing STOP turns a found goal into a failure.
    stop_loss_weight: float = positive(1.0)
    # Precision of BC's and DAgger's forward and backward passes (torch autocast; weights, optimiser, loss
    # and acting stay float32). bfloat16 halved DAgger's update on this project's CPU (AVX512-BF16; the
    # throughput table in benchmarks/README.md) with the same SR, and changes the learned low bits; a CPU without bf16
    # instructions can be slower (`benchmarks/train_throughput.py --algos dagger,dagger-bf16` tells).
    # PPO keeps float32: its importance ratio compares the update's log-probs with the acting ones.
    learn_dtype: Literal["float32", "bfloat16"] = "float32"
    ppo: PPOConfig = field(default_factory=PPOConfig)
    finetune: FinetuneConfig = field(default_factory=FinetuneConfig)
    dagger: DaggerConfig = field(default_factory=DaggerConfig)
    bc: BCConfig = field(default_factory=BCConfig)
    # Bookkeeping.
    seed: int = non_negative(0)
    # auto = cuda:<local rank> when available, else cpu
    device: str = constrained("auto", Pattern(r"auto|cpu|cuda(:[0-9]+)?|mps", "auto, cpu, cuda, cuda:N or mps"))
    threads: int = non_negative(0)  # torch threads of the learner's updates (0 = leave torch's default)
    # torch threads while acting during rollouts: the env workers need the cores meanwhile, and an idle
    # multi-threaded pool spins and steals their CPU (0 = same as `threads`)
    rollout_threads: int = non_negative(1)
    log_every: int = positive(1)  # updates
    checkpoint_every: int = positive(50)  # updates
    keep_checkpoints: int = non_negative(3)  # numbered policy snapshots kept besides the latest
    text_cache: str = ""  # .pt table {text: embedding}; "" = <out>/text_cache.pt
    progress: bool = True
    rules: ClassVar = (
        # a PPO minibatch holds whole envs; BC and DAgger never read `ppo`
        rule(
            ("algo", "ppo.minibatches", "num_envs"),
            lambda a, m, n: a != "ppo" or m <= n,
            "ppo.minibatches <= num_envs for algo ppo",
        ),
        rule(
            ("learn_dtype", "algo"),
            lambda d, a: d == "float32" or a != "ppo",
            "learn_dtype float32 for algo ppo (its ratio compares the update's log-probs with acting's)",
        ),
        rule(
            ("task.kind", "algo"),
            lambda k, a: k != "pointnav" or a == "ppo",
            "algo ppo for task.kind pointnav (there is no PointNav expert)",
        ),
        rule(
            ("task.kind", "encoder.image", "policy.goal_similarity"),
            lambda k, i, g: k != "pointnav" or (i == "depth-grid" and not g),
            "encoder.image depth-grid and policy.goal_similarity false for task.kind pointnav",
        ),
    )


def _paper() -> TrainConfig:
    return TrainConfig(sim=SimConfig(), encoder=EncoderConfig(image="siglip", text="siglip-text"))


def _cpu_small() -> TrainConfig:
    """What learns on a 2-core CPU in tens of minutes; each departure from `paper` is there because a
    run without it failed (docs/concepts/learned-policies.md)."""
    return TrainConfig(
        # No previous-action input: with this little data the policy copies its last action (copycat).
        policy=PolicyConfig(
            hidden=128, layers=2, heads=4, mlp=256, context=64, prev_action_dim=0, goal_similarity=True
        ),
        # learned perception (world-vl, frozen; the shipped weights); --encoder oracle-vl is the oracle upper bound
        encoder=EncoderConfig(
            image="world-vl",
            text="minilm-text",
            oracle_grid=2,
            oracle_global=True,
            oracle_depth_grid=(6, 4),
            oracle_collision=True,
        ),
        # The CPU camera: portrait like the Stretch camera (paper: 360x640, 42 deg HFOV) at 72x128; a landscape
        # frame hides the floor and low furniture in front of the agent.
        sim=cpu_sim_config(),
        # task: the evaluation's (500 steps): a policy trained on 300-step episodes never learned what its
        # last 200 evaluated steps are for
        num_envs=8,
        env_workers=2,
        rollout_steps=64,
        total_steps=2_000_000,
        max_updates=400,  # 205k steps, ~16 min at ~220 steps/s on 2 cores
        lr=5e-4,
        max_grad_norm=0.5,
        stop_loss_weight=2.0,  # 5 made the student STOP next to the wrong objects
        # Frontiers ahead preferred (turning "costs" 2.5 deg/s instead of 10): the teacher's choices then
        # follow what the camera sees, which a small student can imitate.
        frontier_expert=FrontierExpertConfig(turn_speed_deg=2.5, rechoose_every=5),
        expert_viewpoint_radius_m=0.4,  # STOP labels where the goal fills the view (see TrainConfig)
        finetune=FinetuneConfig(critic_lr=5e-4, actor_lr=1e-4, scale=0.1),
        bc=BCConfig(record_episodes=200, record_workers=2, batch_chunks=16, epochs=20),
        # beta 1 -> 0: a randomly initialised student that drives alone just spins (turn labels only) and
        # never visits the states where the expert says "forward" or STOP. The buffer keeps the last 300
        # labelled rollouts (150k steps, float16): with a short buffer the expert-driven states are
        # forgotten as soon as beta reaches 0 and the student collapses to turning in place.
        dagger=DaggerConfig(
            beta_start=1.0, beta_end=0.0, beta_updates=200, buffer_rollouts=300, grad_steps=8, sample_rollouts=4
        ),
        checkpoint_every=50,
        # One learner thread: on 2 cores a second torch thread only helps while nothing else runs, and
        # an idle multi-threaded pool spinning next to the env workers slows everything 3-4x.
        threads=1,
    )


def _tiny() -> TrainConfig:
    """Seconds per run for the tests; the oracle encoder by name (no RGB to render, no network to run)."""
    return TrainConfig(
        policy=PolicyConfig(hidden=32, layers=1, heads=2, mlp=64, context=16, prev_action_dim=8),
        encoder=EncoderConfig(image="oracle-vl", text="minilm-text", oracle_grid=1, oracle_global=False),
        sim=SimConfig(camera=CameraConfig(width=32, height=32)),
        task=TaskConfig(max_steps=40),
        num_envs=2,
        env_workers=0,
        rollout_steps=8,
        total_steps=10_000,
        max_updates=2,
        lr=1e-3,
        max_grad_norm=1.0,
        finetune=FinetuneConfig(scale=0.002),
        bc=BCConfig(record_episodes=4, record_workers=1, episodes_per_shard=2, batch_chunks=4, epochs=50),
        checkpoint_every=1,
        progress=False,
    )


def _pointnav(scale: str) -> TrainConfig:
    """PointNav with PPO (`ovon train --task pointnav`): depth + the goal vector from odometry.

    Why these values (docs/concepts/learned-policies.md): the depth-grid encoder (coarse depth + bump
    flag, ~65 numbers) instead of a CNN, because on a 2-core CPU the env steps are the budget and a CNN's
    forward/backward would halve them; the camera of the cpu-small policies and of the modular agents'
    measurements (72x128 portrait, 42 deg) so the learned navigator sees in VLFM what it trained on; no
    camera tilt; success within 0.36 m (2 agent radii, habitat's PointNav challenge; habitat's original
    PointNav used 0.2 m, VLFM stops within 0.9 m of a goal point and its navigator keeps that radius);
    habitat's dense reward (success 2.5, minus the change of geodesic distance, slack -0.01) with a cost for
    a STOP outside the success radius (below); PPO as
    DD-PPO's PointNav (lr 2.5e-4, 2 minibatches, 2 epochs, clip 0.2, entropy 0.01, grad norm 0.2)."""
    base = _tiny() if scale == "tiny" else TrainConfig()
    # A failed STOP costs 1 (habitat: 0): without it PPO collapsed to STOP-at-once here (mean episode length
    # 33 -> 6 steps within 10 updates), since a STOP ends the slack and the random walk's distance losses.
    task = pointnav_task()
    encoder = EncoderConfig(image="depth-grid", oracle_depth_grid=(8, 4), oracle_collision=True)
    policy = PolicyConfig(
        hidden=128, layers=2, heads=4, mlp=256, context=32, prev_action_dim=16, num_actions=4, stop_bias=-3.0
    )
    cpu = cpu_sim_config()
    sim = dataclasses.replace(cpu, camera=dataclasses.replace(cpu.camera, rgb=False))  # the CPU camera, depth only
    # DD-PPO's PointNav values (2 epochs, grad norm 0.2). With 4 epochs and grad norm 0.5 a run reached 82%
    # SR on its training episodes at 340k steps, then entropy fell to 0.1, approx_kl spiked to 1e4 and SR
    # fell to 45% within 100k steps.
    ppo = PPOConfig(epochs=2, minibatches=2)
    if scale == "tiny":
        return dataclasses.replace(
            base,
            algo="ppo",
            task=dataclasses.replace(task, max_steps=30),
            encoder=encoder,
            policy=dataclasses.replace(policy, hidden=32, heads=2, mlp=64, context=16),
            sim=SimConfig(camera=CameraConfig(width=36, height=64, rgb=False)),
            ppo=PPOConfig(epochs=1, minibatches=2),
        )
    if scale == "paper":
        return dataclasses.replace(
            base,
            algo="ppo",
            task=task,
            encoder=encoder,
            policy=policy,
            lr=2.5e-4,
            ppo=ppo,
            rollout_steps=128,
            total_steps=100_000_000,
        )
    return dataclasses.replace(
        base,
        algo="ppo",
        task=task,
        encoder=encoder,
        policy=policy,
        sim=sim,
        ppo=ppo,
        num_envs=16,
        env_workers=2,
        rollout_steps=64,
        scene_repeat=64,
        total_steps=5_000_000,
        max_updates=0,
        lr=2.5e-4,
        max_grad_norm=0.2,
        threads=1,
        checkpoint_every=20,
        keep_checkpoints=3,
    )


PRESETS = {"paper": _paper, "cpu-small": _cpu_small, "tiny": _tiny}
POINTNAV_PRESETS = {name: (lambda n=name: _pointnav(n)) for name in PRESETS}
TASKS = ("objectnav", "pointnav")


def train_preset(name: str, task: str = "objectnav", **changes: object) -> TrainConfig:
    """Named preset of a task (+ top-level field changes); an unknown name lists the valid ones. PointNav
    presets share the ObjectNav presets' names and scales."""
    if task not in TASKS:
        raise KeyError(f"unknown task {task!r}; valid: {list(TASKS)}")
    presets = POINTNAV_PRESETS if task == "pointnav" else PRESETS
    if name not in presets:
        raise KeyError(f"unknown train preset {name!r}; valid: {sorted(presets)}")
    return dataclasses.replace(presets[name](), **changes)


def build_config(options: Any) -> TrainConfig:
    """The `TrainConfig` of `ovon train`'s options (`algo`, `task`, `preset`, `expert`, `policy`, `encoder`,
    `config`, `set`; an argparse namespace or any object with them): the preset, the named choices, then the YAML file
    and `key=value` overrides, each validated. One function, so `ovon train` and the experiment runner's
    check of a training cell build the same config from the same command line."""
    from ovon.config.base import build

    changes: dict = {"algo": options.algo}
    if options.expert:
        changes["expert"] = options.expert
    task = getattr(options, "task", None) or "objectnav"  # experiment cells name no task: ObjectNav
    if task == "pointnav" and options.algo != "ppo":
        raise ValueError(f"--task pointnav trains with --algo ppo, not {options.algo!r} (there is no PointNav expert)")
    preset = train_preset(options.preset, task, **changes)
    if options.policy:
        preset = dataclasses.replace(preset, policy=dataclasses.replace(preset.policy, core=options.policy))
    if options.encoder:
        preset = dataclasses.replace(preset, encoder=dataclasses.replace(preset.encoder, image=options.encoder))
    return build(type(preset), preset, options.config, options.set)


def reward_for(cfg: TrainConfig, finetune: bool) -> TaskConfig:
    """Task config with the reward kind the algorithm uses (dense for RL, sparse when fine-tuning)."""
    kind = cfg.finetune.reward if finetune else "dense"
    return dataclasses.replace(cfg.task, reward=dataclasses.replace(cfg.task.reward, kind=kind))


__all__ = [
    "BCConfig",
    "DaggerConfig",
    "FinetuneConfig",
    "PPOConfig",
    "PRESETS",
    "RewardConfig",
    "TrainConfig",
    "build_config",
    "reward_for",
    "train_preset",
]
