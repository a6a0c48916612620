"""PPO with the dense reward (RL from scratch), or - with `--init CKPT` - BC->RL / DAgger->RL
fine-tuning: re-initialised critic, sparse reward, and the fine-tune schedule of docs/spec.md#fine-tune-schedule.

Fine-tune schedule (updates, all multiplied by `finetune.scale`): critic lr `critic_lr` until
`critic_decay_start`, then linear to `critic_lr_final` at `critic_decay_end`; actor + core + input
projection frozen (lr 0) until `actor_unfreeze`, then linear warm-up from 0 to `actor_lr` at
`actor_warmup_end`; the prev-action embedding is frozen throughout.

Sequences: each update collects `rollout_steps` steps per env. Old log-probs and values are recomputed
by one forward pass over the rollout chunk (the same context the update sees), so the first PPO ratio
is exactly 1 even though acting used a longer sliding window. Minibatches split the envs, keeping
whole sequences; an LSTM starts each chunk from its acting state at the chunk's start.
"""

from __future__ import annotations

import time
from pathlib import Path

import torch

from ovon.task.episode import EpisodeSpec
from ovon.train import distributed as dist
from ovon.train.batches import episode_summary, features, map_images, stack_images
from ovon.train.config import FinetuneConfig, TrainConfig, reward_for
from ovon.train.run import TrainRun, num_updates


def finetune_lrs(ft: FinetuneConfig, update: int) -> tuple[float, float]:
    """(critic lr, actor lr) at `update` (0-based) of the fine-tune schedule."""
    s = ft.scale

    def ramp(u: float, a: float, b: float) -> float:
        return 0.0 if b <= a else min(1.0, max(0.0, (u - a) / (b - a)))

    critic = ft.critic_lr + ramp(update, ft.critic_decay_start * s, ft.critic_decay_end * s) * (
        ft.critic_lr_final - ft.critic_lr)
    if update < ft.actor_unfreeze * s:
        actor = 0.0
    else:
        actor = ft.actor_lr * (ramp(update, ft.actor_unfreeze * s, ft.actor_warmup_end * s)
                               if ft.actor_warmup_end > ft.actor_unfreeze else 1.0)
    return critic, actor


def _clone_state(state):
    """Detached copy of an LSTM (h, c) acting state (the transformer needs none: chunks carry starts)."""
    if isinstance(state, tuple):
        return tuple(s.detach().clone() for s in state)
    return None


def _index_state(state, idx: torch.Tensor):
    return None if state is None else tuple(s[:, idx] for s in state)


def train_ppo(cfg: TrainConfig, specs: list[EpisodeSpec], out_dir: str | Path, resume: bool = False,
              init: str | None = None) -> dict:
    """Run PPO (from scratch, or fine-tuning `init`); returns the last logged metrics."""
    finetune = init is not None
    algo = "ppo-finetune" if finetune else "ppo"
    run = TrainRun(cfg, out_dir, algo, init=init, resume=resume)
    cfg, dev, pc = run.cfg, run.device, run.cfg.ppo
    try:
        envs, batch = run.open_envs(specs, reward_for(cfg, finetune), label=False)
        policy = run.build_policy(int(batch.image.shape[-1]) if isinstance(batch.image, torch.Tensor) else 0,
                                  int(batch.goal.shape[-1]))
        if finetune:
            if cfg.finetune.reinit_critic:
                policy.reinit_critic()
            groups = policy.parameter_groups()
            if cfg.finetune.freeze_prev_action:
                for p in groups["prev_action"]:
                    p.requires_grad_(False)
            critic_lr, actor_lr = finetune_lrs(cfg.finetune, 0)
            param_groups = [{"params": groups["critic"], "lr": critic_lr, "name": "critic"},
                            {"params": groups["actor"], "lr": actor_lr, "name": "actor"}]
            if not cfg.finetune.freeze_prev_action and groups["prev_action"]:
                param_groups.append({"params": groups["prev_action"], "lr": actor_lr, "name": "prev_action"})
            optimizer = torch.optim.Adam(param_groups, eps=cfg.adam_eps)
        else:
            optimizer = torch.optim.Adam(policy.parameters(), lr=cfg.lr, eps=cfg.adam_eps)
        model = dist.wrap(policy, run.info)
        n_envs, T = cfg.num_envs, cfg.rollout_steps
        act_state = policy.init_state(n_envs, dev)
        prev_action = torch.full((n_envs,), -1, dtype=torch.long, device=dev)
        saved = run.restore(optimizer)
        if saved is not None:
            act_state, prev_action = saved["act_state"], saved["prev_action"].to(dev)
            batch = envs.set_state(saved["env"])
            run.restore_rng(saved)
        total = num_updates(cfg, run.info.world_size)
        run.open_logger(total)
        trainable = [p for p in policy.parameters() if p.requires_grad]
        last: dict = {}
        for update in range(run.start_update, total):
            t0 = time.perf_counter()
            if finetune:
                lrs = finetune_lrs(cfg.finetune, update)
                for g in optimizer.param_groups:
                    g["lr"] = lrs[0] if g["name"] == "critic" else lrs[1]
            state0 = _clone_state(act_state)
            images, goals, prevs, starts, actions, rewards, dones, finished = [], [], [], [], [], [], [], []
            # ---- rollout ----------------------------------------------------------------------
            policy.eval()
            with run.acting():
                for t in range(T + 1):
                    b = batch
                    images.append(b.image)
                    goals.append(b.goal)
                    prevs.append(prev_action.cpu())
                    starts.append(b.first)
                    if t == T:  # the bootstrap observation: value only, no action
                        break
                    with torch.no_grad():
                        obs = policy.make_obs(features(policy, map_images(b.image, lambda x: x.to(dev))),
                                              b.goal.to(dev))
                        logits, _, act_state = policy.act_step(obs, prev_action, act_state, b.first.to(dev))
                        action = policy.distribution(logits / pc.temperature).sample()
                    actions.append(action.cpu())
                    batch = envs.step(action.cpu())
                    rewards.append(batch.reward)
                    dones.append(batch.done)
                    prev_action = torch.where(batch.first.to(dev), torch.full_like(action, -1), action)
                    finished += batch.metrics
            t1 = time.perf_counter()
            # ---- advantages (GAE) from one forward over the chunk --------------------------------
            img = map_images(stack_images(images, 1), lambda x: x.to(dev))  # (N, T+1, ...)
            goal_seq = torch.stack(goals, 1).to(dev)
            prev_seq = torch.stack(prevs, 1).to(dev)
            start_seq = torch.stack(starts, 1).to(dev)
            act_seq = torch.stack(actions, 1).to(dev)
            rew = torch.stack(rewards, 1).to(dev)
            done = torch.stack(dones, 1).to(dev).float()
            with torch.no_grad():
                obs = policy.make_obs(features(policy, img), goal_seq)
                logits, values, _ = policy.forward_seq(obs, prev_seq, start_seq, state0)
                old_logp = policy.distribution(logits[:, :T] / pc.temperature).log_prob(act_seq)
                adv = torch.zeros_like(rew)
                gae = torch.zeros(n_envs, device=dev)
                for t in reversed(range(T)):
                    nonterminal = 1.0 - done[:, t]
                    delta = rew[:, t] + pc.gamma * values[:, t + 1] * nonterminal - values[:, t]
                    gae = delta + pc.gamma * pc.gae_lambda * nonterminal * gae
                    adv[:, t] = gae
                returns = adv + values[:, :T]
            # ---- PPO epochs over env minibatches ------------------------------------------------
            policy.train()
            n_mb = max(1, min(pc.minibatches, n_envs))
            stats: dict[str, list[float]] = {k: [] for k in ("loss", "policy_loss", "value_loss", "entropy",
                                                             "approx_kl", "clipfrac", "grad_norm")}
            for _ in range(pc.epochs):
                perm = torch.randperm(n_envs)
                for mb in perm.chunk(n_mb):
                    mbd = mb.to(dev)
                    mb_img = map_images(img, lambda x, i=mbd: x[i, :T])
                    obs = policy.make_obs(features(policy, mb_img), goal_seq[mbd, :T])
                    logits, v = model(obs, prev_seq[mbd, :T], start_seq[mbd, :T], _index_state(state0, mbd))
                    d = policy.distribution(logits / pc.temperature)
                    logp = d.log_prob(act_seq[mbd])
                    ratio = (logp - old_logp[mbd]).exp()
                    a = adv[mbd]
                    if pc.normalize_advantages and a.numel() > 1:
                        a = (a - a.mean()) / (a.std() + 1e-8)
                    pg = torch.max(-a * ratio, -a * ratio.clamp(1 - pc.clip, 1 + pc.clip)).mean()
                    v_loss = 0.5 * (v - returns[mbd]).pow(2).mean()
                    ent = d.entropy().mean()
                    loss = pg + pc.value_coef * v_loss - pc.entropy_coef * ent
                    optimizer.zero_grad(set_to_none=True)
                    loss.backward()
                    gn = torch.nn.utils.clip_grad_norm_(trainable, cfg.max_grad_norm)
                    optimizer.step()
                    with torch.no_grad():
                        stats["approx_kl"].append(((ratio - 1) - (logp - old_logp[mbd])).mean().item())
                        stats["clipfrac"].append(((ratio - 1).abs() > pc.clip).float().mean().item())
                    for k, val in (("loss", loss), ("policy_loss", pg), ("value_loss", v_loss), ("entropy", ent)):
                        stats[k].append(val.item())
                    stats["grad_norm"].append(float(gn))
            t2 = time.perf_counter()
            run.step += n_envs * T * run.info.world_size
            scalars = {k: sum(v) / len(v) for k, v in stats.items() if v}
            scalars.update({"reward/mean": rew.mean().item(), "time/rollout_s": t1 - t0, "time/learn_s": t2 - t1})
            for g in optimizer.param_groups:
                scalars[f"lr/{g.get('name', 'all')}"] = g["lr"]
            scalars = dist.all_reduce_mean(scalars, run.info)
            eps = [m for part in dist.gather_objects(finished, run.info) for m in part]
            if run.due(update + 1, total, cfg.log_every):
                last = {**scalars, **episode_summary(eps),
                        "steps_per_s": n_envs * T * run.info.world_size / max(t2 - t0, 1e-9)}
                run.log(update + 1, last)
            if run.due(update + 1, total, cfg.checkpoint_every):
                run.save(update + 1, optimizer, {"env": envs.get_state(), "act_state": act_state,
                                                 "prev_action": prev_action.cpu()})
        run.finish(total)
    finally:
        run.close()
    return last
