"""DAgger: the student's sampled action drives the env, the expert labels every visited state online,
and the policy is trained with cross-entropy on those labels (docs/spec.md#training-algorithms; upstream: beta = 0).

Upstream trains on-policy: every update collects `rollout_steps` steps in each env and takes one
gradient step on those (num_envs x rollout_steps) chunks. `dagger.buffer_rollouts` > 1 aggregates the
last rollouts into a dataset and `dagger.grad_steps` > 1 reuses it (what makes DAgger learn in minutes
on a CPU); with `dagger.beta_*` > 0 the expert's own action drives the env with probability beta.

    python -m ovon.cli.main train --algo dagger --preset cpu-small --data D --scenes S --out runs/dagger
    torchrun --nproc_per_node 8 -m ovon.cli.main train --algo dagger --preset paper ...
"""

from __future__ import annotations

import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import torch

from ovon.models.chunk import Chunk, last_steps
from ovon.task.episode import EpisodeSpec
from ovon.train import distributed as dist
from ovon.train.batches import episode_summary, imitation_loss
from ovon.train.collect import Rollout, RolloutCollector, acting_context
from ovon.train.config import TrainConfig, reward_for
from ovon.train.run import TrainRun, num_updates


def beta_at(cfg: TrainConfig, update: int) -> float:
    d = cfg.dagger
    if d.beta_updates <= 0:
        return d.beta_start
    f = min(1.0, update / d.beta_updates)
    return d.beta_start + f * (d.beta_end - d.beta_start)


def train_dagger(
    cfg: TrainConfig, specs: list[EpisodeSpec], out_dir: str | Path, resume: bool = False, init: str | None = None
) -> dict:
    """Run DAgger; returns the last logged metrics. `init` starts from an IL/RL `policy.pt`."""
    run = TrainRun(cfg, out_dir, "dagger", init=init, resume=resume)
    cfg, dev = run.cfg, run.device
    overlap = cfg.dagger.overlap
    if overlap and run.info.world_size > 1:
        raise ValueError("dagger.overlap=true runs in one process; fix: --set dagger.overlap=false under torchrun")
    pool = ThreadPoolExecutor(1, thread_name_prefix="dagger-learn") if overlap else None
    try:
        envs, batch = run.open_envs(specs, reward_for(cfg, False), label=True)
        policy = run.policy_for(batch)
        model = dist.wrap(policy, run.info)
        optimizer = torch.optim.Adam(policy.parameters(), lr=cfg.lr, eps=cfg.adam_eps)
        # With overlap the student acts with its own copy (the weights of the update before last) and the
        # learner draws its minibatches from its own generator, so acting and learning never race.
        actor = policy.clone() if overlap else policy
        learn_rng = torch.Generator().manual_seed(cfg.seed * 7919 + 1) if overlap else None
        n_envs, T = cfg.num_envs, cfg.rollout_steps
        collector = RolloutCollector(envs, batch, policy, dev)
        # context steps before each chunk (transformer) and the acting memory at its start (LSTM)
        P = acting_context(policy.cfg) if cfg.dagger.context_prefix else 0
        keep_state = cfg.dagger.context_prefix and policy.cfg.core == "lstm"
        buffer: list[Chunk] = []  # aggregated labelled rollouts (cfg.dagger.buffer_rollouts most recent)
        saved = run.restore(optimizer)
        if saved is not None:
            collector.restore(saved)
            buffer = buffer_from_saved(saved.get("buffer", []))
            if overlap:
                actor.load_state_dict(saved["actor"])
                learn_rng.set_state(saved["learn_rng"])
            run.restore_rng(saved)
        total = num_updates(cfg, run.info.world_size)
        run.open_logger(total)

        def learn(data: list[Chunk], acted: tuple) -> dict:
            """`grad_steps` cross-entropy steps on the expert's labels over (num_envs, T) chunks. `acted`: the
            newest rollout's (actions, their log-probs when acting), for `behaviour_kl` (as PPO's: 0 when the
            first step's update reads the policy that acted; with `dagger.overlap` it also holds the one
            update by which the actor is staler)."""
            t = time.perf_counter()
            policy.train()
            losses, accs, grad_norm, behaviour_kl = [], [], 0.0, 0.0
            for g in range(cfg.dagger.grad_steps):
                picks = [len(data) - 1]  # the newest rollout, plus random older ones
                older = torch.randperm(len(data) - 1, generator=learn_rng)[: cfg.dagger.sample_rollouts - 1]
                parts = [data[i] for i in picks + older.tolist()]
                # (N, P + T, ...): context, then the chunk (no loss on the context)
                seq = Chunk.cat([p.with_context(P) for p in parts]).to(dev)
                state0 = start_states(policy, parts, dev) if keep_state else None
                with run.learning():
                    logits, values, _ = policy.evaluate(seq, state0, via=model)
                logits, values, target = logits.float(), values.float(), seq.labels
                if g == 0:  # rows 0..num_envs: the newest rollout
                    with torch.no_grad():
                        actions, acted_logp = (x.to(dev) for x in acted)
                        logp = policy.distribution(logits[: actions.shape[0]]).log_prob(actions)
                        log_ratio = logp - acted_logp
                        behaviour_kl = float((log_ratio.exp() - 1 - log_ratio).mean())
                valid = target >= 0
                loss = imitation_loss(logits, target, cfg.stop_loss_weight) + 0.0 * values.sum()  # DDP sees critic
                optimizer.zero_grad(set_to_none=True)
                loss.backward()
                grad_norm = float(torch.nn.utils.clip_grad_norm_(policy.parameters(), cfg.max_grad_norm))
                optimizer.step()
                losses.append(loss.item())
                accs.append((logits[valid].argmax(-1) == target[valid]).float().mean().item())
            return {
                "loss": float(np.mean(losses)),
                "accuracy": float(np.mean(accs)),
                "grad_norm": grad_norm,
                "behaviour_kl": behaviour_kl,
                "time/learn_s": time.perf_counter() - t,
            }

        last: dict = {}
        pending = None  # overlap: (update, future of its learning, its rollout record)

        def finish(u: int, learned: dict, record: dict) -> None:
            """Log update `u` (0-based) once its learning is done."""
            nonlocal last
            scalars = dist.all_reduce_mean({**learned, "time/rollout_s": record["rollout_s"]}, run.info)
            eps = [m for part in dist.gather_objects(record["finished"], run.info) for m in part]
            if run.due(u + 1, total, cfg.log_every):
                last = {
                    **scalars,
                    **episode_summary(eps),
                    "beta": record["beta"],
                    "steps_per_s": n_envs * T * run.info.world_size / max(record["wall_s"], 1e-9),
                }
                run.log(u + 1, last, step=record["step"])

        t_prev = time.perf_counter()
        for update in range(run.start_update, total):
            t0 = time.perf_counter()
            beta = beta_at(cfg, update)

            def choose(logits: torch.Tensor, b, beta: float = beta):
                """The student's sample; with probability beta the expert's label instead."""
                action = actor.distribution(logits).sample()
                if beta > 0:
                    use_expert = torch.rand(n_envs, device=dev) < beta
                    action = torch.where(use_expert, b.label.to(dev), action)
                return action, actor.distribution(logits).log_prob(action)

            # ---- rollout: the student acts, the expert labels -------------------------------------
            run.begin_update(update)
            with run.acting():
                ro = collector.collect(actor, T, choose)
            t1 = time.perf_counter()
            buffer.append(buffer_entry(ro, buffer[-1] if buffer else None, P, keep_state))
            acted = (ro.actions, ro.behaviour_logp)
            del buffer[: max(0, len(buffer) - cfg.dagger.buffer_rollouts)]
            finished = ro.finished
            run.step += n_envs * T * run.info.world_size
            record = {"beta": beta, "finished": finished, "rollout_s": t1 - t0, "step": run.step}
            # ---- learn: now, or (overlap) in the thread while the next rollout runs ---------------------
            checkpoint = run.checkpoint_due(update + 1, total)
            if overlap:
                if pending is not None:
                    u, future, rec = pending
                    learned = future.result()
                    rec["wall_s"] = time.perf_counter() - t_prev
                    t_prev = time.perf_counter()
                    finish(u, learned, rec)
                    pending = None
                actor.load_state_dict(policy.state_dict())  # the weights after the previous update
                if checkpoint:  # a checkpoint holds a finished update, so learn this one now
                    learned = learn(list(buffer), acted)
                    record["wall_s"] = time.perf_counter() - t_prev
                    t_prev = time.perf_counter()
                    finish(update, learned, record)
                else:
                    pending = (update, pool.submit(learn, list(buffer), acted), record)
            else:
                learned = learn(buffer, acted)
                record["wall_s"] = time.perf_counter() - t0
                finish(update, learned, record)
            if checkpoint:
                state = {**collector.state(), "buffer": buffer_to_saved(buffer)}
                if overlap:
                    state |= {"actor": actor.state_dict(), "learn_rng": learn_rng.get_state()}
                run.save(update + 1, optimizer, state)
                run.stop_if_requested()
        if pending is not None:  # (the last update always checkpoints; kept for clarity)
            u, future, rec = pending
            rec["wall_s"] = time.perf_counter() - t_prev
            finish(u, future.result(), rec)
        run.finish(total)
    finally:
        if pool is not None:
            pool.shutdown(wait=True, cancel_futures=True)
        run.close()
    return last


def buffer_entry(ro: Rollout, previous: Chunk | None, prefix: int, keep_state: bool) -> Chunk:
    """A rollout as the buffer keeps it: its chunk with images compacted, the LSTM's acting (h, c) at its start
    (`keep_state`), and as `context` the `prefix` steps acted before it, as views of the previous entries'
    tensors (no copy; a dropped entry's storage lives on only while a later entry's context needs it); before
    the first rollout there is none, and every env's first step there is an episode start."""
    context: list[Chunk] = []
    if prefix > 0 and previous is not None:
        context = last_steps([*previous.context, previous.observations()], prefix)
    c = ro.chunk
    return Chunk(
        _compact(c.images), c.goals, c.prevs, c.starts, c.labels, c.state0 if keep_state else None, context=context
    )


def buffer_to_saved(buffer: list[Chunk]) -> list[tuple]:
    """The buffer as checkpoints hold it, plain tuples and dicts: (images, goals, prevs, starts, labels, context,
    state0), each context part {images, goals, prevs, starts}. A part shared by several entries stays one object."""
    parts: dict[int, dict] = {}

    def part(c: Chunk) -> dict:
        return parts.setdefault(id(c), {"images": c.images, "goals": c.goals, "prevs": c.prevs, "starts": c.starts})

    return [(e.images, e.goals, e.prevs, e.starts, e.labels, [part(c) for c in e.context], e.state0) for e in buffer]


def buffer_from_saved(saved: list[tuple]) -> list[Chunk]:
    """The buffer of a checkpoint (`buffer_to_saved`; written before context_prefix: no context, no state0)."""
    parts: dict[int, Chunk] = {}

    def part(d: dict) -> Chunk:
        return parts.setdefault(id(d), Chunk(d["images"], d["goals"], d["prevs"], d["starts"]))

    return [
        Chunk(
            *e[:5],
            state0=e[6] if len(e) > 6 else None,
            context=[part(d) for d in (e[5] if len(e) > 5 else [])],
        )
        for e in saved
    ]


def start_states(policy, entries: list[Chunk], dev) -> tuple:
    """The LSTM (h, c) of the entries' chunks at their starts, joined over envs (zeros where none was kept)."""
    states = [policy.init_state(e.goals.shape[0], "cpu") if e.state0 is None else e.state0 for e in entries]
    return tuple(torch.cat([s[j].to(dev) for s in states], 1) for j in range(2))


def _compact(images: object) -> object:
    """Frozen-encoder embeddings are kept in float16 in the buffer (half the memory of a long DAgger
    dataset); `make_obs` widens them back to float32."""
    return images.half() if isinstance(images, torch.Tensor) and images.is_floating_point() else images
