"""PPO with the dense reward (RL from scratch), or - with `--init CKPT` - BC->RL / DAgger->RL
fine-tuning: re-initialised critic, sparse reward, and the fine-tune schedule of docs/spec.md#fine-tune-schedule.

Fine-tune schedule (updates, all multiplied by `finetune.scale`): critic lr `critic_lr` until
`critic_decay_start`, then linear to `critic_lr_final` at `critic_decay_end`; actor + core + input
projection frozen (lr 0) until `actor_unfreeze` (and, with `critic_warmup_ev`, until the critic
explains that much of the returns' variance), then linear warm-up from 0 to `actor_lr` at
`actor_warmup_end`; the prev-action embedding is frozen throughout. `finetune.anchor` adds a decaying
term that keeps the imitation policy: cross-entropy to the expert's online labels, or KL to the frozen
initial policy.

Sequences: each update collects `rollout_steps` steps per env (`ovon.train.collect`). Old log-probs and
values are recomputed by one forward pass over the rollout chunk (the same context the update sees);
`behaviour_kl` logs how far that is from the log-probs the actions were sampled with (0 when acting and
the update see the same context: a transformer's update re-reads the chunk after the layers x (context - 1)
steps before it, the receptive field of KV-cached acting). Minibatches split the envs, keeping whole
sequences; an LSTM starts each chunk from its acting state at the chunk's start.
"""

from __future__ import annotations

import time
from pathlib import Path

import torch

from ovon.task.episode import EpisodeSpec
from ovon.train import distributed as dist
from ovon.train.batches import episode_summary, features, imitation_loss, map_images
from ovon.train.checkpoint import to_device
from ovon.train.collect import RolloutCollector, acting_context, explained_variance, gae
from ovon.train.config import FinetuneConfig, TrainConfig, reward_for
from ovon.train.run import TrainRun, num_updates


def finetune_lrs(ft: FinetuneConfig, update: int) -> tuple[float, float]:
    """(critic lr, actor lr) at `update` (0-based) of the fine-tune schedule."""
    s = ft.scale

    def ramp(u: float, a: float, b: float) -> float:
        if b <= a:  # a step at b (the config allows start == end)
            return 1.0 if u >= b else 0.0
        return min(1.0, max(0.0, (u - a) / (b - a)))

    critic = ft.critic_lr + ramp(update, ft.critic_decay_start * s, ft.critic_decay_end * s) * (
        ft.critic_lr_final - ft.critic_lr
    )
    if update < ft.actor_unfreeze * s:
        actor = 0.0
    else:
        actor = ft.actor_lr * (
            ramp(update, ft.actor_unfreeze * s, ft.actor_warmup_end * s)
            if ft.actor_warmup_end > ft.actor_unfreeze
            else 1.0
        )
    return critic, actor


def _index_state(state, idx: torch.Tensor):
    return None if state is None else tuple(s[:, idx] for s in state)


def anchor_weight(ft: FinetuneConfig, update: int) -> float:
    """Weight of the imitation anchor at `update` (0-based): anchor_coef decaying linearly to 0."""
    if ft.anchor == "none":
        return 0.0
    if ft.anchor_decay_updates <= 0:
        return ft.anchor_coef
    return ft.anchor_coef * max(0.0, 1.0 - update / (ft.anchor_decay_updates * ft.scale))


def kl_to(ref_logits: torch.Tensor, logits: torch.Tensor) -> torch.Tensor:
    """Mean KL(softmax(ref) || softmax(logits)) over the leading dims."""
    ref = torch.log_softmax(ref_logits, -1)
    return (ref.exp() * (ref - torch.log_softmax(logits, -1))).sum(-1).mean()


def reference_logits(
    reference,
    img,
    goal_seq: torch.Tensor,
    prev_seq: torch.Tensor,
    start_seq: torch.Tensor,
    prefix: int,
    steps: int,
    state,
) -> tuple[torch.Tensor, object]:
    """The frozen initial policy's logits on the chunk's `steps` steps after `prefix` context steps, and its
    memory after them. An LSTM reference needs its own (h, c) carried from chunk to chunk: the policy's
    acting state is what the *fine-tuned* LSTM remembers, and read by the reference it gives logits that
    drift away from the initial policy's (an anchor to something neither policy would do). A transformer
    keeps no state (None): the prefix is its memory."""
    n = prefix + steps  # the bootstrap observation after the chunk is the next chunk's first step
    obs = reference.make_obs(features(reference, map_images(img, lambda x: x[:, :n])), goal_seq[:, :n])
    logits, _, state = reference.forward_seq(obs, prev_seq[:, :n], start_seq[:, :n], state)
    return logits[:, prefix:], state


def critic_values(
    critic, img, goal_seq: torch.Tensor, prev_seq: torch.Tensor, start_seq: torch.Tensor, prefix: int, steps: int, state
) -> tuple[torch.Tensor, object]:
    """A separate critic's values on the chunk's `steps` steps after `prefix` context steps and on the
    bootstrap observation after them, and its memory at the next chunk's start. Like the reference policy,
    an LSTM critic carries its own (h, c) from chunk to chunk; a transformer's memory is the prefix."""
    n = prefix + steps

    def values(lo: int, hi: int, st):
        obs = critic.make_obs(features(critic, map_images(img, lambda x: x[:, lo:hi])), goal_seq[:, lo:hi])
        return critic.forward_seq(obs, prev_seq[:, lo:hi], start_seq[:, lo:hi], st)[1:]

    if state is None:  # transformer: one pass over context, chunk and bootstrap step
        v, _ = values(0, n + 1, None)
        return v[:, prefix:], None
    v, after = values(0, n, state)  # LSTM: the memory after the chunk, then the bootstrap step from it
    v_boot, _ = values(n, n + 1, after)
    return torch.cat([v, v_boot], 1)[:, prefix:], after


def train_ppo(
    cfg: TrainConfig, specs: list[EpisodeSpec], out_dir: str | Path, resume: bool = False, init: str | None = None
) -> dict:
    """Run PPO (from scratch, or fine-tuning `init`); returns the last logged metrics."""
    finetune = init is not None
    algo = "ppo-finetune" if finetune else "ppo"
    run = TrainRun(cfg, out_dir, algo, init=init, resume=resume)
    cfg, dev, pc, ft = run.cfg, run.device, run.cfg.ppo, run.cfg.finetune
    anchor = ft.anchor if finetune else "none"
    try:
        envs, batch = run.open_envs(specs, reward_for(cfg, finetune), label=anchor == "expert")
        policy = run.policy_for(batch)
        reference = critic_net = None
        if finetune:
            if anchor == "kl":  # the initial policy, frozen, before the critic is re-initialised
                reference = policy.clone().eval().requires_grad_(False)
            if ft.reinit_critic:
                policy.reinit_critic()
            groups = policy.parameter_groups()
            if ft.freeze_prev_action:
                for p in groups["prev_action"]:
                    p.requires_grad_(False)
            if ft.critic == "separate":  # its own copy of the initial network; the policy's head goes unused
                critic_net = policy.clone().requires_grad_(True)
                critic_net.reinit_critic()
                critic_net.action_head.requires_grad_(False)
                policy.critic_head.requires_grad_(False)
                groups["critic"] = [p for p in critic_net.parameters() if p.requires_grad]
            critic_lr, actor_lr = finetune_lrs(ft, 0)
            param_groups = [
                {"params": groups["critic"], "lr": critic_lr, "name": "critic"},
                {"params": groups["actor"], "lr": actor_lr, "name": "actor"},
            ]
            if not ft.freeze_prev_action and groups["prev_action"]:
                param_groups.append({"params": groups["prev_action"], "lr": actor_lr, "name": "prev_action"})
            optimizer = torch.optim.Adam(param_groups, eps=cfg.adam_eps)
        else:
            optimizer = torch.optim.Adam(policy.parameters(), lr=cfg.lr, eps=cfg.adam_eps)
        model = dist.wrap(policy, run.info)
        critic_model = dist.wrap(critic_net, run.info) if critic_net is not None else None
        n_envs, T = cfg.num_envs, cfg.rollout_steps
        prefix = acting_context(policy.cfg) if pc.context_prefix else 0
        collector = RolloutCollector(envs, batch, policy, dev, prefix=prefix)
        gate_open = ft.critic_warmup_ev <= 0  # the explained-variance gate of the actor (latched)
        ref_state = None  # the reference LSTM's memory at the next chunk's start
        critic_state = None  # the separate LSTM critic's, likewise
        saved = run.restore(optimizer)
        if saved is not None:
            collector.restore(saved)
            gate_open = saved.get("actor_gate_open", gate_open)
            ref_state = to_device(saved.get("ref_state"), dev)
            if critic_net is not None:
                critic_net.load_state_dict(saved["critic_net"])
                critic_state = to_device(saved.get("critic_state"), dev)
            run.restore_rng(saved)
        total = num_updates(cfg, run.info.world_size)
        run.open_logger(total)
        trainable = [p for net in (policy, critic_net) if net is not None for p in net.parameters() if p.requires_grad]

        def choose(logits: torch.Tensor, b) -> tuple[torch.Tensor, torch.Tensor]:
            d = policy.distribution(logits / pc.temperature)
            action = d.sample()
            return action, d.log_prob(action)

        last: dict = {}
        for update in range(run.start_update, total):
            t0 = time.perf_counter()
            if finetune:
                lrs = finetune_lrs(ft, update)
                for g in optimizer.param_groups:
                    g["lr"] = lrs[0] if g["name"] == "critic" else (lrs[1] if gate_open else 0.0)
            # ---- rollout ----------------------------------------------------------------------
            with run.acting():
                ro = collector.collect(policy, T, choose, bootstrap=True)
            t1 = time.perf_counter()
            # ---- advantages (GAE) from one forward over [prefix +] chunk -------------------------
            P = ro.prefix  # context steps before the chunk: read, never trained on
            img = map_images(ro.images, lambda x: x.to(dev))  # (N, P + T + 1, ...)
            goal_seq, prev_seq, start_seq = ro.goals.to(dev), ro.prevs.to(dev), ro.starts.to(dev)
            act_seq, rew, state0 = ro.actions.to(dev), ro.rewards.to(dev), ro.state0
            with torch.no_grad():
                obs = policy.make_obs(features(policy, img), goal_seq)
                logits, values, _ = policy.forward_seq(obs, prev_seq, start_seq, state0)
                logits, values = logits[:, P:], values[:, P:]
                critic_state0 = critic_state
                if critic_net is not None:  # its memory at the first chunk is the policy's (fresh: zeros)
                    if critic_state0 is None and state0 is not None:
                        critic_state0 = state0
                    values, critic_state = critic_values(
                        critic_net, img, goal_seq, prev_seq, start_seq, P, T, critic_state0
                    )
                old_logp = policy.distribution(logits[:, :T] / pc.temperature).log_prob(act_seq)
                adv, returns = gae(rew, values, ro.dones.to(dev), pc.gamma, pc.gae_lambda)
                ev = explained_variance(values[:, :T], returns)
                log_ratio = old_logp - ro.behaviour_logp.to(dev)  # update vs acting, same weights
                behaviour_kl = (log_ratio.exp() - 1 - log_ratio).mean().item()
                ref_logits = None
                if reference is not None:  # its memory at the first chunk is the policy's: they are equal
                    ref_logits, ref_state = reference_logits(
                        reference, img, goal_seq, prev_seq, start_seq, P, T, state0 if ref_state is None else ref_state
                    )
            if not gate_open:  # every rank opens the gate at the same update (their weights stay equal)
                gate_open = dist.all_reduce_mean({"ev": ev}, run.info)["ev"] >= ft.critic_warmup_ev
            labels = ro.labels[:, :T].to(dev)
            w_anchor = anchor_weight(ft, update) if finetune else 0.0
            # ---- PPO epochs over env minibatches ------------------------------------------------
            policy.train()
            n_mb = max(1, min(pc.minibatches, n_envs))
            stats: dict[str, list[float]] = {
                k: []
                for k in (
                    "loss",
                    "policy_loss",
                    "value_loss",
                    "entropy",
                    "approx_kl",
                    "clipfrac",
                    "grad_norm",
                    "anchor_loss",
                )
            }
            for _ in range(pc.epochs):
                perm = torch.randperm(n_envs)
                for mb in perm.chunk(n_mb):
                    mbd = mb.to(dev)
                    mb_img = map_images(img, lambda x, i=mbd, n=P + T: x[i, :n])
                    obs = policy.make_obs(features(policy, mb_img), goal_seq[mbd, : P + T])
                    logits, v = model(obs, prev_seq[mbd, : P + T], start_seq[mbd, : P + T], _index_state(state0, mbd))
                    logits, v = logits[:, P:], v[:, P:]
                    if critic_model is not None:
                        cobs = critic_net.make_obs(features(critic_net, mb_img), goal_seq[mbd, : P + T])
                        v = critic_model(
                            cobs, prev_seq[mbd, : P + T], start_seq[mbd, : P + T], _index_state(critic_state0, mbd)
                        )[1][:, P:]
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
                    if w_anchor > 0:
                        a_loss = (
                            imitation_loss(logits, labels[mbd], cfg.stop_loss_weight)
                            if anchor == "expert"
                            else kl_to(ref_logits[mbd], logits)
                        )
                        loss = loss + w_anchor * a_loss
                        stats["anchor_loss"].append(a_loss.item())
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
            scalars.update(
                {
                    "reward/mean": rew.mean().item(),
                    "time/rollout_s": t1 - t0,
                    "time/learn_s": t2 - t1,
                    "behaviour_kl": behaviour_kl,
                    "explained_variance": ev,
                }
            )
            if finetune:
                scalars.update({"anchor/weight": w_anchor, "actor_gate_open": float(gate_open)})
            for g in optimizer.param_groups:
                scalars[f"lr/{g.get('name', 'all')}"] = g["lr"]
            scalars = dist.all_reduce_mean(scalars, run.info)
            eps = [m for part in dist.gather_objects(ro.finished, run.info) for m in part]
            if run.due(update + 1, total, cfg.log_every):
                last = {
                    **scalars,
                    **episode_summary(eps),
                    "steps_per_s": n_envs * T * run.info.world_size / max(t2 - t0, 1e-9),
                }
                run.log(update + 1, last)
            if run.checkpoint_due(update + 1, total):
                extra = (
                    {} if critic_net is None else {"critic_net": critic_net.state_dict(), "critic_state": critic_state}
                )
                run.save(
                    update + 1,
                    optimizer,
                    {**collector.state(), "actor_gate_open": gate_open, "ref_state": ref_state, **extra},
                )
                run.stop_if_requested()
        run.finish(total)
    finally:
        run.close()
    return last
