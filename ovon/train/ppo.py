"""PPO with the dense reward (RL from scratch), or - with `--init CKPT` - BC->RL / DAgger->RL fine-tuning
(`ovon.train.finetune`: re-initialised critic, sparse reward, the fine-tune schedule, anchor, separate critic).

Each update: collect `rollout_steps` steps per env (`ovon.train.collect`); recompute old log-probs and values
by one forward pass over the rollout chunk (the same context the update sees) and take GAE; then
`ppo.epochs` passes over env minibatches with the clipped objective. `behaviour_kl` logs how far the
recomputed log-probs are from those the actions were sampled with (0 when acting and the update see the
same context: a transformer's update re-reads the chunk after the layers x (context - 1) steps before it,
the receptive field of KV-cached acting). Minibatches split the envs, keeping whole sequences; an LSTM
starts each chunk from its acting state at the chunk's start.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import torch

from ovon.models.chunk import Chunk
from ovon.task.episode import EpisodeSpec
from ovon.train import distributed as dist
from ovon.train.batches import episode_summary
from ovon.train.collect import Rollout, RolloutCollector, acting_context, explained_variance, gae
from ovon.train.config import TrainConfig, reward_for
from ovon.train.finetune import Finetune, index_state
from ovon.train.run import TrainRun, num_updates

STATS = ("loss", "policy_loss", "value_loss", "entropy", "approx_kl", "clipfrac", "grad_norm", "anchor_loss")


def train_ppo(
    cfg: TrainConfig, specs: list[EpisodeSpec], out_dir: str | Path, resume: bool = False, init: str | None = None
) -> dict:
    """Run PPO (from scratch, or fine-tuning `init`); returns the last logged metrics."""
    run = TrainRun(cfg, out_dir, "ppo" if init is None else "ppo-finetune", init=init, resume=resume)
    cfg, dev, pc = run.cfg, run.device, run.cfg.ppo
    tuner = Finetune(cfg, active=init is not None)
    try:
        envs, batch = run.open_envs(specs, reward_for(cfg, tuner.active), label=tuner.anchor == "expert")
        policy = run.policy_for(batch)
        optimizer = tuner.setup(policy, cfg.lr, cfg.adam_eps)
        model = dist.wrap(policy, run.info)
        tuner.wrap(run.info)
        prefix = acting_context(policy.cfg) if pc.context_prefix else 0
        collector = RolloutCollector(envs, batch, policy, dev, prefix=prefix)
        saved = run.restore(optimizer)
        if saved is not None:
            collector.restore(saved)
            tuner.restore(saved, dev)
            run.restore_rng(saved)
        total = num_updates(cfg, run.info.world_size)
        run.open_logger(total)
        trainable = tuner.trainable(policy)
        steps_per_update = cfg.num_envs * cfg.rollout_steps * run.info.world_size

        def choose(logits: torch.Tensor, b) -> tuple[torch.Tensor, torch.Tensor]:
            d = policy.distribution(logits / pc.temperature)
            action = d.sample()
            return action, d.log_prob(action)

        last: dict = {}
        for update in range(run.start_update, total):
            t0 = time.perf_counter()
            tuner.begin(update, optimizer)
            run.begin_update(update)
            with run.acting():
                ro = collector.collect(policy, cfg.rollout_steps, choose, bootstrap=True)
            t1 = time.perf_counter()
            data = advantages(policy, tuner, ro, cfg, dev)
            tuner.open_gate(data.explained_variance, run.info)
            stats = optimise(policy, model, tuner, optimizer, trainable, data, cfg)
            t2 = time.perf_counter()
            run.step += steps_per_update
            scalars = {k: sum(v) / len(v) for k, v in stats.items() if v}
            scalars.update(
                {
                    "reward/mean": data.rewards.mean().item(),
                    "time/rollout_s": t1 - t0,
                    "time/learn_s": t2 - t1,
                    "behaviour_kl": data.behaviour_kl,
                    "explained_variance": data.explained_variance,
                }
            )
            scalars.update(tuner.scalars())
            for g in optimizer.param_groups:
                scalars[f"lr/{g.get('name', 'all')}"] = g["lr"]
            scalars = dist.all_reduce_mean(scalars, run.info)
            eps = [m for part in dist.gather_objects(ro.finished, run.info) for m in part]
            if run.due(update + 1, total, cfg.log_every):
                last = {**scalars, **episode_summary(eps), "steps_per_s": steps_per_update / max(t2 - t0, 1e-9)}
                run.log(update + 1, last)
            if run.checkpoint_due(update + 1, total):
                run.save(update + 1, optimizer, {**collector.state(), **tuner.state()})
                run.stop_if_requested()
        run.finish(total)
    finally:
        run.close()
    return last


@dataclass
class Advantages:
    """A rollout on the device with what PPO's epochs need from it, computed once with the weights that acted."""

    chunk: Chunk  # [prefix +] T steps + the bootstrap step
    actions: torch.Tensor  # (N, T)
    rewards: torch.Tensor  # (N, T)
    old_logp: torch.Tensor  # (N, T): log-probs of the actions, recomputed over the chunk
    adv: torch.Tensor  # (N, T)
    returns: torch.Tensor  # (N, T)
    labels: torch.Tensor  # (N, T): the expert's labels (anchor=expert)
    explained_variance: float
    behaviour_kl: float


def advantages(policy, tuner: Finetune, ro: Rollout, cfg: TrainConfig, dev: torch.device) -> Advantages:
    """GAE from one forward over [prefix +] chunk + bootstrap step (the fine-tune's separate critic gives the
    values when there is one); old log-probs from the same pass."""
    pc, T = cfg.ppo, cfg.rollout_steps
    chunk = ro.chunk.to(dev)  # (N, P + T + 1, ...)
    actions, rewards = ro.actions.to(dev), ro.rewards.to(dev)
    with torch.no_grad():
        logits, values, _ = policy.evaluate(chunk, chunk.state0)
        values = tuner.values(chunk, T, values)
        old_logp = policy.distribution(logits[:, :T] / pc.temperature).log_prob(actions)
        adv, returns = gae(rewards, values, ro.dones.to(dev), pc.gamma, pc.gae_lambda)
        ev = explained_variance(values[:, :T], returns)
        log_ratio = old_logp - ro.behaviour_logp.to(dev)  # update vs acting, same weights
        behaviour_kl = (log_ratio.exp() - 1 - log_ratio).mean().item()
        tuner.read_reference(chunk, T)
    return Advantages(chunk, actions, rewards, old_logp, adv, returns, chunk.labels[:, :T], ev, behaviour_kl)


def optimise(policy, model, tuner: Finetune, optimizer, trainable: list, data: Advantages, cfg: TrainConfig) -> dict:
    """`ppo.epochs` passes over env minibatches (whole sequences) with the clipped objective, the value loss,
    the entropy bonus and the fine-tune's anchor; returns each loss term per minibatch."""
    pc, n_envs = cfg.ppo, cfg.num_envs
    steps = data.chunk.prefix + cfg.rollout_steps  # [prefix +] chunk: the bootstrap step is not trained on
    policy.train()
    n_mb = max(1, min(pc.minibatches, n_envs))
    stats: dict[str, list[float]] = {k: [] for k in STATS}
    for _ in range(pc.epochs):
        perm = torch.randperm(n_envs)
        for mb in perm.chunk(n_mb):
            rows = mb.to(data.adv.device)
            seq = data.chunk.select(rows, hi=steps)
            logits, v, _ = policy.evaluate(seq, index_state(data.chunk.state0, rows), via=model)
            v = tuner.minibatch_values(seq, rows, v)
            d = policy.distribution(logits / pc.temperature)
            logp = d.log_prob(data.actions[rows])
            ratio = (logp - data.old_logp[rows]).exp()
            a = data.adv[rows]
            if pc.normalize_advantages and a.numel() > 1:
                a = (a - a.mean()) / (a.std() + 1e-8)
            pg = torch.max(-a * ratio, -a * ratio.clamp(1 - pc.clip, 1 + pc.clip)).mean()
            v_loss = 0.5 * (v - data.returns[rows]).pow(2).mean()
            ent = d.entropy().mean()
            loss = pg + pc.value_coef * v_loss - pc.entropy_coef * ent
            anchor = tuner.anchor_loss(logits, data.labels, rows)
            if anchor is not None:
                loss = loss + tuner.weight * anchor
                stats["anchor_loss"].append(anchor.item())
            optimizer.zero_grad(set_to_none=True)
            loss.backward()
            gn = torch.nn.utils.clip_grad_norm_(trainable, cfg.max_grad_norm)
            optimizer.step()
            with torch.no_grad():
                stats["approx_kl"].append(((ratio - 1) - (logp - data.old_logp[rows])).mean().item())
                stats["clipfrac"].append(((ratio - 1).abs() > pc.clip).float().mean().item())
            for k, val in (("loss", loss), ("policy_loss", pg), ("value_loss", v_loss), ("entropy", ent)):
                stats[k].append(val.item())
            stats["grad_norm"].append(float(gn))
    return stats
