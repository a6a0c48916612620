"""DAgger: the student's sampled action drives the env, the expert labels every visited state online,
and the policy is trained with cross-entropy on those labels (baselines.md; upstream: beta = 0).

As upstream, training is on-policy: every update collects `rollout_steps` steps in each env and takes
one gradient step on those (num_envs x rollout_steps) chunks - no aggregated dataset. With
`dagger.beta_*` > 0, the expert's own action drives the env with probability beta (classic DAgger).

    python -m ovon.cli.main train --algo dagger --preset cpu-small --data D --scenes S --out runs/dagger
    torchrun --nproc_per_node 8 -m ovon.cli.main train --algo dagger --preset paper ...
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import torch

from ovon.task.episode import EpisodeSpec
from ovon.train import distributed as dist
from ovon.train.checkpoint import set_rng_state
from ovon.train.common import (
    episode_summary,
    features,
    imitation_loss,
    load_online,
    map_images,
    num_updates,
    open_online,
    save_online,
    stack_images,
    write_rank_report,
)
from ovon.train.config import TrainConfig, reward_for
from ovon.train.logging import RunLogger
from ovon.train.rollout import Batch


def beta_at(cfg: TrainConfig, update: int) -> float:
    d = cfg.dagger
    if d.beta_updates <= 0:
        return d.beta_start
    f = min(1.0, update / d.beta_updates)
    return d.beta_start + f * (d.beta_end - d.beta_start)


def train_dagger(cfg: TrainConfig, specs: list[EpisodeSpec], out_dir: str | Path, resume: bool = False,
                 init: str | None = None) -> dict:
    """Run DAgger; returns the last logged metrics. `init` starts from an IL/RL `policy.pt`."""
    out = Path(out_dir)
    cfg, info, envs, batch, policy = open_online(cfg, specs, out, reward_for(cfg, False), label=True, init=init)
    dev = info.device
    model = dist.wrap(policy, info)
    optimizer = torch.optim.Adam(policy.parameters(), lr=cfg.lr, eps=cfg.adam_eps)
    n_envs, T = cfg.num_envs, cfg.rollout_steps
    act_state = policy.init_state(n_envs, dev)
    prev_action = torch.full((n_envs,), -1, dtype=torch.long, device=dev)
    start_update, step = 0, 0
    buffer: list[tuple] = []  # aggregated labelled rollouts (cfg.dagger.buffer_rollouts most recent)
    if resume and (out / "checkpoint.pt").exists():
        ckpt, mine = load_online(out, info, policy, optimizer)
        start_update, step = ckpt["update"], ckpt["step"]
        act_state, prev_action = mine["act_state"], mine["prev_action"].to(dev)
        buffer = list(mine.get("buffer", []))
        batch = envs.set_state(mine["env"])
        set_rng_state(mine["rng"])
    total = num_updates(cfg, info.world_size)
    logger = RunLogger(out, total, "dagger", info.is_main, cfg.progress, start_update, step)
    last: dict = {}
    try:
        for update in range(start_update, total):
            t0 = time.perf_counter()
            beta = beta_at(cfg, update)
            images, goals, prevs, starts, labels, finished = [], [], [], [], [], []
            # ---- rollout: the student acts, the expert labels -------------------------------------
            policy.eval()
            for _ in range(T):
                b = batch
                with torch.no_grad():
                    obs = policy.make_obs(features(policy, map_images(b.image, lambda x: x.to(dev))), b.goal.to(dev))
                    logits, _, act_state = policy.act_step(obs, prev_action, act_state, b.first.to(dev))
                    action = policy.distribution(logits).sample()
                    if beta > 0:
                        use_expert = torch.rand(n_envs, device=dev) < beta
                        action = torch.where(use_expert, b.label.to(dev), action)
                images.append(b.image)
                goals.append(b.goal)
                prevs.append(prev_action.cpu())
                starts.append(b.first)
                labels.append(b.label)
                batch: Batch = envs.step(action.cpu())
                prev_action = torch.where(batch.first.to(dev), torch.full_like(action, -1), action)
                finished += batch.metrics
            t1 = time.perf_counter()
            # ---- learn: cross-entropy on the expert's labels over (num_envs, T) chunks -----------------
            buffer.append((_compact(stack_images(images, 1)), torch.stack(goals, 1), torch.stack(prevs, 1),
                           torch.stack(starts, 1), torch.stack(labels, 1)))
            del buffer[: max(0, len(buffer) - cfg.dagger.buffer_rollouts)]
            policy.train()
            losses, accs = [], []
            for _ in range(cfg.dagger.grad_steps):
                picks = [len(buffer) - 1]  # the newest rollout, plus random older ones
                older = torch.randperm(len(buffer) - 1)[: cfg.dagger.sample_rollouts - 1].tolist()
                parts = [buffer[i] for i in picks + older]
                img = map_images(_cat([p[0] for p in parts]), lambda x: x.to(dev))  # (N, T, ...)
                obs = policy.make_obs(features(policy, img), torch.cat([p[1] for p in parts]).to(dev))
                logits, values = model(obs, torch.cat([p[2] for p in parts]).to(dev),
                                       torch.cat([p[3] for p in parts]).to(dev))
                target = torch.cat([p[4] for p in parts]).to(dev)
                valid = target >= 0
                loss = imitation_loss(logits, target, cfg.stop_loss_weight) + 0.0 * values.sum()  # DDP sees critic
                optimizer.zero_grad(set_to_none=True)
                loss.backward()
                grad_norm = torch.nn.utils.clip_grad_norm_(policy.parameters(), cfg.max_grad_norm)
                optimizer.step()
                losses.append(loss.item())
                accs.append((logits[valid].argmax(-1) == target[valid]).float().mean().item())
            t2 = time.perf_counter()
            step += n_envs * T * info.world_size
            scalars = dist.all_reduce_mean({"loss": float(np.mean(losses)), "accuracy": float(np.mean(accs)),
                                            "grad_norm": float(grad_norm), "time/rollout_s": t1 - t0,
                                            "time/learn_s": t2 - t1}, info)
            eps = [m for part in dist.gather_objects(finished, info) for m in part]
            if (update + 1) % cfg.log_every == 0 or update + 1 == total:
                last = {**scalars, **episode_summary(eps), "beta": beta,
                        "steps_per_s": n_envs * T * info.world_size / max(t2 - t0, 1e-9)}
                logger.log(update + 1, step, last)
            if (update + 1) % cfg.checkpoint_every == 0 or update + 1 == total:
                save_online(out, info, cfg, "dagger", policy, optimizer, update + 1, step,
                            {"env": envs.get_state(), "act_state": act_state, "prev_action": prev_action.cpu(),
                             "buffer": buffer})
        write_rank_report(out, info, policy, total)
    finally:
        logger.close()
        envs.close()
    return last


def _compact(images: object) -> object:
    """Frozen-encoder embeddings are kept in float16 in the buffer (half the memory of a long DAgger
    dataset); `features` turns them back into float32."""
    return images.half() if isinstance(images, torch.Tensor) and images.is_floating_point() else images


def _cat(items: list) -> object:
    """Concatenate rollouts along the env dimension (tensors or dicts of tensors for raw frames)."""
    if isinstance(items[0], torch.Tensor):
        return torch.cat(items)
    return {k: torch.cat([x[k] for x in items]) for k in items[0]}
