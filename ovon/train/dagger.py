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

import copy
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import torch

from ovon.task.episode import EpisodeSpec
from ovon.train import distributed as dist
from ovon.train.batches import cat_images, episode_summary, features, imitation_loss, map_images
from ovon.train.collect import RolloutCollector
from ovon.train.config import TrainConfig, reward_for
from ovon.train.run import TrainRun, num_updates


def beta_at(cfg: TrainConfig, update: int) -> float:
    d = cfg.dagger
    if d.beta_updates <= 0:
        return d.beta_start
    f = min(1.0, update / d.beta_updates)
    return d.beta_start + f * (d.beta_end - d.beta_start)


def train_dagger(cfg: TrainConfig, specs: list[EpisodeSpec], out_dir: str | Path, resume: bool = False,
                 init: str | None = None) -> dict:
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
        actor = copy.deepcopy(policy) if overlap else policy
        learn_rng = torch.Generator().manual_seed(cfg.seed * 7919 + 1) if overlap else None
        n_envs, T = cfg.num_envs, cfg.rollout_steps
        collector = RolloutCollector(envs, batch, policy, dev)
        buffer: list[tuple] = []  # aggregated labelled rollouts (cfg.dagger.buffer_rollouts most recent)
        saved = run.restore(optimizer)
        if saved is not None:
            collector.restore(saved)
            buffer = list(saved.get("buffer", []))
            if overlap:
                actor.load_state_dict(saved["actor"])
                learn_rng.set_state(saved["learn_rng"])
            run.restore_rng(saved)
        total = num_updates(cfg, run.info.world_size)
        run.open_logger(total)

        def learn(data: list[tuple]) -> dict:
            """`grad_steps` cross-entropy steps on the expert's labels over (num_envs, T) chunks."""
            t = time.perf_counter()
            policy.train()
            losses, accs, grad_norm = [], [], 0.0
            for _ in range(cfg.dagger.grad_steps):
                picks = [len(data) - 1]  # the newest rollout, plus random older ones
                older = torch.randperm(len(data) - 1, generator=learn_rng)[: cfg.dagger.sample_rollouts - 1]
                parts = [data[i] for i in picks + older.tolist()]
                img = map_images(cat_images([p[0] for p in parts]), lambda x: x.to(dev))  # (N, T, ...)
                obs = policy.make_obs(features(policy, img), torch.cat([p[1] for p in parts]).to(dev))
                logits, values = model(obs, torch.cat([p[2] for p in parts]).to(dev),
                                       torch.cat([p[3] for p in parts]).to(dev))
                target = torch.cat([p[4] for p in parts]).to(dev)
                valid = target >= 0
                loss = imitation_loss(logits, target, cfg.stop_loss_weight) + 0.0 * values.sum()  # DDP sees critic
                optimizer.zero_grad(set_to_none=True)
                loss.backward()
                grad_norm = float(torch.nn.utils.clip_grad_norm_(policy.parameters(), cfg.max_grad_norm))
                optimizer.step()
                losses.append(loss.item())
                accs.append((logits[valid].argmax(-1) == target[valid]).float().mean().item())
            return {"loss": float(np.mean(losses)), "accuracy": float(np.mean(accs)), "grad_norm": grad_norm,
                    "time/learn_s": time.perf_counter() - t}

        last: dict = {}
        pending = None  # overlap: (update, future of its learning, its rollout record)

        def finish(u: int, learned: dict, record: dict) -> None:
            """Log update `u` (0-based) once its learning is done."""
            nonlocal last
            scalars = dist.all_reduce_mean({**learned, "time/rollout_s": record["rollout_s"]}, run.info)
            eps = [m for part in dist.gather_objects(record["finished"], run.info) for m in part]
            if run.due(u + 1, total, cfg.log_every):
                last = {**scalars, **episode_summary(eps), "beta": record["beta"],
                        "steps_per_s": n_envs * T * run.info.world_size / max(record["wall_s"], 1e-9)}
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
                return action, None

            # ---- rollout: the student acts, the expert labels -------------------------------------
            with run.acting():
                ro = collector.collect(actor, T, choose)
            t1 = time.perf_counter()
            buffer.append((_compact(ro.images), ro.goals, ro.prevs, ro.starts, ro.labels))
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
                    learned = learn(list(buffer))
                    record["wall_s"] = time.perf_counter() - t_prev
                    t_prev = time.perf_counter()
                    finish(update, learned, record)
                else:
                    pending = (update, pool.submit(learn, list(buffer)), record)
            else:
                learned = learn(buffer)
                record["wall_s"] = time.perf_counter() - t0
                finish(update, learned, record)
            if checkpoint:
                state = {**collector.state(), "buffer": buffer}
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


def _compact(images: object) -> object:
    """Frozen-encoder embeddings are kept in float16 in the buffer (half the memory of a long DAgger
    dataset); `features` turns them back into float32."""
    return images.half() if isinstance(images, torch.Tensor) and images.is_floating_point() else images
