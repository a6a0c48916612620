"""Behaviour cloning: record expert trajectories (frontier or shortest-path expert) as shards, then
cross-entropy training on episode chunks of at most `policy.context` steps.

Shards (`shard_00000.pt`, written atomically, one recording job each) hold per-step frozen-encoder
embeddings (float16) or, for a trainable CNN, the frames; plus previous actions, expert actions and
episode boundaries - so training never touches a simulator. Chunks are shuffled with a permutation
that depends only on (seed, epoch), so a resumed run sees the same batches as an uninterrupted one.

    python -m ovon.cli.main train --algo bc --preset cpu-small --data D --scenes S --out runs/bc
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch

from ovon.config.base import to_dict
from ovon.models.chunk import Chunk
from ovon.task.episode import EpisodeSpec
from ovon.train import distributed as dist
from ovon.train.batches import imitation_loss
from ovon.train.checkpoint import atomic_torch_save
from ovon.train.config import TrainConfig, reward_for
from ovon.train.run import TrainRun, expert_config

SHARD_FORMAT = "ovon-bc-shard-v1"


# ----- recording ----------------------------------------------------------------------------------
def _record_job(job: dict) -> dict:
    """Worker: run the expert on a list of (spec, seed) episodes of one scene and write one shard.

    The env is the training stack (expert labels + frozen encoder), driven by its own labels."""
    from ovon.env.encode import GOAL, IMAGE
    from ovon.env.labels import KEY as LABEL
    from ovon.env.stack import EnvRecipe, build_env
    from ovon.parallel import init_worker

    init_worker()
    path = Path(job["path"])
    if path.exists():
        return {"path": str(path), "episodes": -1}
    env = build_env(
        EnvRecipe(
            sim=job["sim"],
            task=job["task"],
            encoder=job["encoder"],
            text_table=job["table"],
            expert=job["expert"],
            expert_cfg=job.get("expert_cfg"),
            expert_viewpoint_radius=job.get("expert_viewpoint_radius", 0.0),
            episodes=job["specs"][:1],
            sample_episodes=False,
        )
    )
    cnn = job["encoder"].image == "cnn"
    images: list[Any] = []
    prev, act, ep_of, lengths, goals, goal_text, metrics = [], [], [], [], [], [], []
    try:
        for spec_index, seed in job["items"]:
            spec = job["specs"][spec_index]
            try:
                obs, _ = env.reset(seed=seed, options={"episode": spec})
            except ValueError:  # no reachable goal from this floor: skip the episode
                continue
            e = len(lengths)
            goals.append(obs[GOAL])
            goal_text.append(spec.goal_category)
            n, last, done, info = 0, -1, False, {}
            while not done:
                label = int(obs[LABEL])
                images.append({"rgb": obs["rgb"], "depth": obs["depth"]} if cnn else obs[IMAGE])
                prev.append(last)
                act.append(label)
                ep_of.append(e)
                last = label
                n += 1
                obs, _, term, trunc, info = env.step(label)
                done = term or trunc
            lengths.append(n)
            metrics.append(info["metrics"])
    finally:
        env.close()
    if not lengths:
        return {"path": str(path), "episodes": 0}
    shard: dict[str, Any] = {
        "format": SHARD_FORMAT,
        "goal": torch.from_numpy(np.stack(goals).astype(np.float32)),
        "goal_text": goal_text,
        "episode": torch.tensor(ep_of, dtype=torch.long),
        "prev_action": torch.tensor(prev, dtype=torch.long),
        "action": torch.tensor(act, dtype=torch.long),
        "lengths": torch.tensor(lengths, dtype=torch.long),
        "metrics": metrics,
        "meta": {"expert": job["expert"], "encoder": to_dict(job["encoder"]), "sim": to_dict(job["sim"])},
    }
    if isinstance(images[0], dict):
        shard["rgb"] = torch.from_numpy(np.stack([i["rgb"] for i in images]))
        shard["depth"] = torch.from_numpy(np.stack([i["depth"] for i in images]).astype(np.float16))
    else:
        shard["image"] = torch.from_numpy(np.stack(images).astype(np.float16))
    atomic_torch_save(shard, path)
    return {
        "path": str(path),
        "episodes": len(lengths),
        "steps": len(act),
        "success": float(np.mean([m["success"] for m in metrics])),
    }


def record_shards(
    cfg: TrainConfig,
    specs: list[EpisodeSpec],
    shard_dir: str | Path,
    table: dict,
    episodes: int | None = None,
    workers: int | None = None,
    progress: bool = False,
) -> list[dict]:
    """Record `episodes` expert episodes (specs cycled, seeded) into shards of `bc.episodes_per_shard`,
    grouped by scene (one world load per shard). Existing shards are kept (resumable)."""
    from ovon.parallel import progress_bar, run_jobs

    shard_dir = Path(shard_dir)
    shard_dir.mkdir(parents=True, exist_ok=True)
    episodes = cfg.bc.record_episodes if episodes is None else episodes
    rng = np.random.default_rng(cfg.seed)
    order = rng.permutation(len(specs))
    items = [(int(order[i % len(specs)]), int(rng.integers(2**31 - 1))) for i in range(episodes)]
    by_scene: dict[str, list[tuple[int, int]]] = {}
    for it in items:
        by_scene.setdefault(specs[it[0]].scene, []).append(it)
    jobs = []
    tab = {k: np.asarray(v, dtype=np.float32) for k, v in table.items()}
    for scene in sorted(by_scene):
        its = by_scene[scene]
        for i in range(0, len(its), cfg.bc.episodes_per_shard):
            part = its[i : i + cfg.bc.episodes_per_shard]
            idx = sorted({p[0] for p in part})
            remap = {old: new for new, old in enumerate(idx)}
            jobs.append(
                {
                    "path": str(shard_dir / f"shard_{len(jobs):05d}.pt"),
                    "specs": [specs[j] for j in idx],
                    "items": [(remap[a], s) for a, s in part],
                    "sim": cfg.sim,
                    "task": reward_for(cfg, False),
                    "encoder": cfg.encoder,
                    "table": tab,
                    "expert": cfg.expert,
                    "seed": cfg.seed + len(jobs),
                    "expert_cfg": expert_config(cfg),
                    "expert_viewpoint_radius": cfg.expert_viewpoint_radius_m,
                }
            )
    results = []
    with progress_bar("recording expert shards", len(jobs), progress) as bar:
        for r in run_jobs(_record_job, jobs, workers=cfg.bc.record_workers if workers is None else workers):
            results.append(r)
            bar.advance()
    return results


# ----- dataset of chunks --------------------------------------------------------------------------
@dataclasses.dataclass
class ChunkData:
    """All shards concatenated; `chunks` (C, 2) = (first step index, length <= context)."""

    image: Any  # (N, Di) float16 tensor, or {"rgb": (N,H,W,3), "depth": (N,H,W)}
    goal: torch.Tensor  # (E, Dg)
    episode: torch.Tensor  # (N,) global episode index
    prev_action: torch.Tensor  # (N,)
    action: torch.Tensor  # (N,)
    start: torch.Tensor  # (N,) bool: first step of an episode
    chunks: torch.Tensor  # (C, 2)
    meta: dict

    @property
    def image_dim(self) -> int | None:
        return int(self.image.shape[-1]) if isinstance(self.image, torch.Tensor) else None


def load_shards(shard_dir: str | Path, context: int) -> ChunkData:
    paths = sorted(Path(shard_dir).glob("shard_*.pt"))
    if not paths:
        raise FileNotFoundError(f"no BC shards (shard_*.pt) in {shard_dir}")
    parts = [torch.load(p, weights_only=False) for p in paths]
    for p, s in zip(paths, parts):
        if s.get("format") != SHARD_FORMAT:
            raise ValueError(f"{p} is not a BC shard ({SHARD_FORMAT})")
    offsets = np.cumsum([0] + [len(s["lengths"]) for s in parts])
    episode = torch.cat([s["episode"] + int(o) for s, o in zip(parts, offsets)])
    if "image" in parts[0]:
        image: Any = torch.cat([s["image"] for s in parts])
    else:
        image = {k: torch.cat([s[k] for s in parts]) for k in ("rgb", "depth")}
    lengths = torch.cat([s["lengths"] for s in parts])
    first = torch.cat([torch.zeros(1, dtype=torch.long), lengths.cumsum(0)[:-1]])
    start = torch.zeros(len(episode), dtype=torch.bool)
    start[first] = True
    chunks = [(int(f) + a, min(context, int(n) - a)) for f, n in zip(first, lengths) for a in range(0, int(n), context)]
    return ChunkData(
        image,
        torch.cat([s["goal"] for s in parts]),
        episode,
        torch.cat([s["prev_action"] for s in parts]),
        torch.cat([s["action"] for s in parts]),
        start,
        torch.tensor(chunks, dtype=torch.long).reshape(-1, 2),
        parts[0].get("meta", {}),
    )


def make_batch(data: ChunkData, chunk_ids: torch.Tensor, device: torch.device) -> Chunk:
    """The chosen chunks padded to the longest (B, L, ...); the padding's labels are -1."""
    c = data.chunks[chunk_ids]
    L = int(c[:, 1].max())
    ar = torch.arange(L)
    mask = ar[None, :] < c[:, 1:2]
    idx = torch.where(mask, c[:, :1] + ar[None, :], c[:, :1])
    if isinstance(data.image, torch.Tensor):
        image: Any = data.image[idx].to(device).float()
    else:
        image = {k: v[idx].to(device) for k, v in data.image.items()}
    action = data.action[idx].to(device)
    return Chunk(
        image,
        data.goal[data.episode[idx]].to(device),
        data.prev_action[idx].to(device),
        data.start[idx].to(device),
        labels=torch.where(mask.to(device), action, torch.full_like(action, -1)),
    )


def epoch_permutation(n: int, seed: int, epoch: int) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed * 1_000_003 + epoch)
    return torch.randperm(n, generator=g)


# ----- training -----------------------------------------------------------------------------------
def train_bc(
    cfg: TrainConfig,
    specs: list[EpisodeSpec] | None,
    out_dir: str | Path,
    resume: bool = False,
    init: str | None = None,
) -> dict:
    """Record shards if missing (needs `specs`), then train; returns the last logged metrics."""
    run = TrainRun(cfg, out_dir, "bc", init=init, resume=resume)
    cfg, dev, info = run.cfg, run.device, run.info
    try:
        shard_dir = Path(cfg.bc.shards) if cfg.bc.shards else run.out / "shards"
        if not list(shard_dir.glob("shard_*.pt")):
            if not specs:
                raise ValueError(f"no BC shards in {shard_dir} and no episodes to record them from (--data/--scenes)")
            table = run.text_table(specs)
            if run.is_main:
                record_shards(cfg, specs, shard_dir, table, progress=cfg.progress)
            dist.barrier(info)
        elif specs or cfg.text_cache:
            run.text_table(specs or [])
        data = load_shards(shard_dir, cfg.policy.context)
        policy = run.build_policy(data.image_dim or cfg.encoder.cnn_dim, int(data.goal.shape[-1]))
        model = dist.wrap(policy, info)
        optimizer = torch.optim.Adam(policy.parameters(), lr=cfg.lr, eps=cfg.adam_eps)
        B, W = cfg.bc.batch_chunks, info.world_size
        n_chunks = len(data.chunks)
        per_epoch = max(1, n_chunks // (B * W))
        total = cfg.max_updates if cfg.max_updates > 0 else cfg.bc.epochs * per_epoch
        saved = run.restore(optimizer)
        if saved is not None:
            run.restore_rng(saved)
        run.open_logger(total)
        last: dict = {}
        for update in range(run.start_update, total):
            t0 = time.perf_counter()
            epoch, k = divmod(update, per_epoch)
            perm = epoch_permutation(n_chunks, cfg.seed, epoch)
            lo = (k * W + info.rank) * B
            ids = perm[torch.arange(lo, lo + B) % n_chunks]
            b = make_batch(data, ids, dev)
            with run.learning():
                logits, values, _ = policy.evaluate(b, via=model)
            logits, values, target = logits.float(), values.float(), b.labels
            loss = imitation_loss(logits, target, cfg.stop_loss_weight) + 0.0 * values.sum()
            optimizer.zero_grad(set_to_none=True)
            loss.backward()
            grad_norm = torch.nn.utils.clip_grad_norm_(policy.parameters(), cfg.max_grad_norm)
            optimizer.step()
            m = target >= 0  # the chunks' steps (not padding)
            run.step += int(m.sum()) * W
            acc = (logits[m].argmax(-1) == target[m]).float().mean()
            scalars = dist.all_reduce_mean(
                {"loss": loss.item(), "accuracy": acc.item(), "grad_norm": float(grad_norm)}, info
            )
            if run.due(update + 1, total, cfg.log_every):
                last = {**scalars, "epoch": float(epoch), "time/update_s": time.perf_counter() - t0}
                run.log(update + 1, last)
            if run.checkpoint_due(update + 1, total):
                run.save(update + 1, optimizer, {})
                run.stop_if_requested()
        run.finish(total)
    finally:
        run.close()
    return last
