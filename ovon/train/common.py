"""Pieces every trainer shares: goal-text tables, episode lists, policy construction, image features.

Why here and not in each algorithm file: they are plumbing (which text encoder, how a CNN frame batch is
fed), while the algorithm files keep their loops readable top to bottom.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch

from ovon.models.config import EncoderConfig, PolicyConfig
from ovon.models.encoders.base import CachedTextEncoder
from ovon.task.episode import EpisodeSpec

# An image batch: precomputed embeddings (..., D) float, or raw frames {"rgb": (..., H, W, 3) uint8,
# "depth": (..., H, W) float} for a trainable CNN that lives inside the policy.
Images = torch.Tensor | dict[str, torch.Tensor]


# ----- goal / category text embeddings ------------------------------------------------------------
class TableTextEncoder(CachedTextEncoder):
    """Text encoder backed by a precomputed {text: embedding} table; misses go to the real encoder
    (built lazily, so worker processes never load a language model when the table covers the scene)."""

    def __init__(self, table: dict[str, Any], cfg: EncoderConfig | None = None) -> None:
        super().__init__()
        self.cfg = cfg
        self._model = None
        for k, v in table.items():
            self._cache[k] = torch.as_tensor(np.asarray(v, dtype=np.float32))
        first = next(iter(self._cache.values()), None)
        self.dim = int(first.shape[-1]) if first is not None else 0
        self.name = f"table({cfg.text if cfg else 'fixed'})"

    def _embed(self, texts: list[str]) -> torch.Tensor:
        if self.cfg is None:
            raise KeyError(f"text(s) {texts[:5]} are not in the embedding table and no text encoder is configured")
        if self._model is None:
            from ovon.models.encoders import make_text_encoder

            self._model = make_text_encoder(self.cfg)
            self.dim = int(self._model.dim)
        return self._model.encode(texts)

    def table(self) -> dict[str, torch.Tensor]:
        return dict(self._cache)


def needed_texts(specs: Iterable[EpisodeSpec]) -> list[str]:
    """Goal texts of the episodes + every vocabulary category (what oracle perception may show)."""
    from ovon.scenes.vocabulary import load_vocabulary

    out = dict.fromkeys(load_vocabulary().names)
    for s in specs:
        for c in s.goal_categories:
            out.setdefault(c)
    return list(out)


def text_table(cfg: EncoderConfig, texts: Sequence[str], cache_path: str | Path, write: bool = True) -> dict:
    """{text: float32 embedding} for `texts`, read from / added to the `.pt` cache at `cache_path`.

    The cache key is the text encoder's config: a cache written by another encoder is ignored."""
    from ovon.train.checkpoint import atomic_torch_save

    key = {"text": cfg.text, "siglip_model": cfg.siglip_model, "siglip_normalize": cfg.siglip_normalize}
    path = Path(cache_path)
    table: dict[str, torch.Tensor] = {}
    if path.is_file():
        data = torch.load(path, weights_only=True)
        if data.get("key") == key or data.get("key") is None:
            table = dict(data["table"])
    missing = [t for t in dict.fromkeys(texts) if t not in table]
    if missing:
        from ovon.models.encoders import make_text_encoder

        emb = make_text_encoder(cfg).encode(missing)
        table.update({t: e.clone() for t, e in zip(missing, emb)})
        if write:
            atomic_torch_save({"key": key, "table": table}, path)
    return table


def write_text_table(path: str | Path, table: dict[str, Any], cfg: EncoderConfig | None = None) -> Path:
    """Write a table in `text_table`'s format (e.g. a hand-made one for tests); key None matches any."""
    from ovon.train.checkpoint import atomic_torch_save

    key = None if cfg is None else {"text": cfg.text, "siglip_model": cfg.siglip_model,
                                    "siglip_normalize": cfg.siglip_normalize}
    tab = {k: torch.as_tensor(np.asarray(v, dtype=np.float32)) for k, v in table.items()}
    return atomic_torch_save({"key": key, "table": tab}, path)


# ----- episodes -------------------------------------------------------------------------------
def adhoc_specs(scene_seeds: Sequence[int], categories: Sequence[str] | None = None,
                per_scene: int = 0) -> list[EpisodeSpec]:
    """Episodes without a dataset: one per (procedural house, goal category), random starts.

    `categories` restricts the goals; `per_scene` > 0 keeps that many categories per house."""
    from ovon.scenes.procedural import generate_house

    specs = []
    for seed in scene_seeds:
        cats = generate_house(int(seed)).categories
        if categories is not None:
            cats = [c for c in cats if c in set(categories)]
        if per_scene > 0:
            cats = cats[:per_scene]
        specs += [EpisodeSpec(episode_id=f"adhoc-{seed}-{c}", scene=f"procedural:{seed}", goal_category=c,
                              split="train") for c in cats]
    return specs


def parse_seed_list(text: str) -> list[int]:
    """`0-3,7` -> [0, 1, 2, 3, 7]."""
    out: list[int] = []
    for part in (p.strip() for p in text.split(",") if p.strip()):
        a, _, b = part.partition("-")
        out += list(range(int(a), int(b) + 1)) if b else [int(a)]
    return out


# ----- policy -------------------------------------------------------------------------------
def build_train_policy(policy_cfg: PolicyConfig, encoder_cfg: EncoderConfig, image_dim: int, text_dim: int):
    from ovon.models.policy import build_policy

    if encoder_cfg.image == "cnn":
        image_dim = encoder_cfg.cnn_dim
    return build_policy(policy_cfg, image_dim, text_dim, encoder_cfg)


def load_init_policy(path: str | Path, encoder_cfg: EncoderConfig):
    """The IL policy to fine-tune: a `policy.pt`, or a run folder holding one."""
    from ovon.models.policy import ActorCritic

    path = Path(path)
    if path.is_dir():
        path = path / "policy.pt"
    policy = ActorCritic.load(path)
    if policy.encoder_cfg is not None and policy.encoder_cfg.image != encoder_cfg.image:
        raise ValueError(f"--init {path} was trained with encoder {policy.encoder_cfg.image!r}, "
                         f"not {encoder_cfg.image!r}")
    return policy


def replace_encoder(cfg: Any, encoder: EncoderConfig) -> Any:
    return dataclasses.replace(cfg, encoder=encoder)


# ----- image batches ------------------------------------------------------------------------
def features(policy, images: Images) -> torch.Tensor:
    """Image embeddings for a batch with any leading dims: a tensor passes through; raw frames go
    through the policy's trainable CNN (with gradients when called under grad)."""
    if isinstance(images, torch.Tensor):
        return images.float()
    rgb = images["rgb"]
    lead = rgb.shape[:-3]
    flat = {k: v.reshape(-1, *v.shape[len(lead):]) for k, v in images.items()}
    return policy.encode_images(flat).reshape(*lead, -1)


def stack_images(items: list[Images], dim: int = 0) -> Images:
    if isinstance(items[0], torch.Tensor):
        return torch.stack(items, dim)
    return {k: torch.stack([x[k] for x in items], dim) for k in items[0]}


def map_images(images: Images, fn) -> Images:
    return fn(images) if isinstance(images, torch.Tensor) else {k: fn(v) for k, v in images.items()}


def imitation_loss(logits: torch.Tensor, target: torch.Tensor, stop_weight: float = 1.0) -> torch.Tensor:
    """Cross-entropy on expert labels (entries < 0 are ignored); STOP (action 0) weighted by `stop_weight`.

    A weighted mean (divided by the summed weights), so `stop_weight=1` is the plain cross-entropy."""
    weight = None
    if stop_weight != 1.0:
        weight = torch.ones(logits.shape[-1], dtype=logits.dtype, device=logits.device)
        weight[0] = stop_weight
    return torch.nn.functional.cross_entropy(logits.reshape(-1, logits.shape[-1]), target.reshape(-1),
                                             weight=weight, ignore_index=-1)


def episode_summary(metrics: list[dict]) -> dict[str, float | None]:
    """Mean success / SPL / SoftSPL / length over finished episodes (None when none finished)."""
    if not metrics:
        return {"episode/count": 0.0}
    out: dict[str, float | None] = {"episode/count": float(len(metrics))}
    for k in ("success", "spl", "soft_spl", "steps", "distance_to_goal"):
        vals = [float(m[k]) for m in metrics if k in m and m[k] is not None]
        out[f"episode/{k}"] = float(np.mean(vals)) if vals else None
    return out


def set_threads(n: int) -> None:
    if n > 0:
        torch.set_num_threads(n)


def param_checksum(module: torch.nn.Module) -> float:
    """Sum over parameters in float64: identical across DDP ranks when they stay in sync."""
    with torch.no_grad():
        return float(sum(p.detach().double().sum().item() for p in module.parameters()))


# ----- online (DAgger / PPO) run set-up, checkpoints and resume ------------------------------------
def open_online(cfg, specs: list[EpisodeSpec], out_dir: str | Path, task, label: bool, init: str | None = None):
    """Join the process group, take this rank's episodes, start its envs and build (or load) the policy.

    Returns (cfg, info, envs, first batch, policy on the rank's device). `cfg` gets the policy/encoder
    config actually used (from `init` when fine-tuning)."""
    from ovon.train import distributed as dist
    from ovon.train.checkpoint import seed_everything
    from ovon.train.rollout import make_vec_env

    info = dist.setup(cfg.device)
    set_threads(cfg.threads)
    seed_everything(cfg.seed + 7919 * info.rank)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    init_policy = load_init_policy(init, cfg.encoder) if init else None
    if init_policy is not None:
        cfg = dataclasses.replace(cfg, policy=init_policy.cfg, encoder=init_policy.encoder_cfg or cfg.encoder)
    mine = dist.shard(list(specs), info)
    table = rank_text_table(cfg, list(specs), out, info)
    envs = make_vec_env(cfg, mine, task, table, label, info.rank)
    batch = envs.reset()
    text_dim = int(batch.goal.shape[-1])
    image_dim = int(batch.image.shape[-1]) if isinstance(batch.image, torch.Tensor) else cfg.encoder.cnn_dim
    policy = init_policy or build_train_policy(cfg.policy, cfg.encoder, image_dim, text_dim)
    if (policy.image_dim, policy.text_dim) != (image_dim, text_dim):
        raise ValueError(f"policy expects image/text dims {(policy.image_dim, policy.text_dim)}, "
                         f"the envs give {(image_dim, text_dim)}")
    policy.text_table = table
    return cfg, info, envs, batch, policy.to(info.device)


def rank_text_table(cfg, specs: list[EpisodeSpec], out: Path, info) -> dict:
    """Rank 0 computes and caches the text table; the other ranks read the cache after a barrier."""
    from ovon.train import distributed as dist

    path = Path(cfg.text_cache) if cfg.text_cache else out / "text_cache.pt"
    texts = needed_texts(specs)
    if info.is_main:
        table = text_table(cfg.encoder, texts, path, write=True)
    dist.barrier(info)
    if not info.is_main:
        table = text_table(cfg.encoder, texts, path, write=False)
    return table


def num_updates(cfg, world_size: int) -> int:
    if cfg.max_updates > 0:
        return cfg.max_updates
    return max(1, cfg.total_steps // (cfg.num_envs * world_size * cfg.rollout_steps))


def save_online(out: Path, info, cfg, algo: str, policy, optimizer, update: int, step: int, rank_state: dict,
                extra: dict | None = None) -> None:
    """Gather every rank's state (RNG, envs, acting memory) and let rank 0 write checkpoint + policy."""
    from ovon.config.base import to_dict
    from ovon.train import distributed as dist
    from ovon.train.checkpoint import export_policy, rng_state, save_checkpoint

    ranks = dist.gather_objects({**rank_state, "rng": rng_state()}, info)
    if info.is_main:
        save_checkpoint(out, {"algo": algo, "config": to_dict(cfg), "policy": policy.state_dict(),
                              "optimizer": optimizer.state_dict(), "update": update, "step": step,
                              "world_size": info.world_size, "ranks": ranks, "extra": extra or {}})
        export_policy(policy, out, policy_extra(cfg, algo, update, step, policy), update, cfg.keep_checkpoints)
    dist.barrier(info)


def policy_extra(cfg, algo: str, update: int, step: int, policy) -> dict:
    """What `PolicyAgent` needs besides weights: the goal-text table and the sim it was trained in."""
    from ovon.config.base import to_dict

    table = getattr(policy, "text_table", None) or {}
    return {"algo": algo, "update": update, "step": step, "expert": cfg.expert,
            "text_table": {k: torch.as_tensor(v).float() for k, v in table.items()},
            "camera": {k: v for k, v in to_dict(cfg.sim.camera).items() if isinstance(v, int | float | str)}}


def load_online(out: Path, info, policy, optimizer):
    """Resume: weights, optimiser, counters and this rank's state (RNG restored last, by the caller)."""
    from ovon.train.checkpoint import load_checkpoint

    ckpt = load_checkpoint(out, map_location=info.device)
    if ckpt["world_size"] != info.world_size:
        raise ValueError(f"checkpoint was written by {ckpt['world_size']} ranks; this run has {info.world_size}")
    policy.load_state_dict(ckpt["policy"])
    optimizer.load_state_dict(ckpt["optimizer"])
    return ckpt, ckpt["ranks"][info.rank]


def write_rank_report(out: Path, info, policy, update: int) -> None:
    """Per-rank parameter checksum (DDP ranks must agree) - cheap, and what the torchrun test reads."""
    import json

    d = out / "ranks"
    d.mkdir(parents=True, exist_ok=True)
    (d / f"rank{info.rank}.json").write_text(json.dumps(
        {"rank": info.rank, "world_size": info.world_size, "update": update, "checksum": param_checksum(policy)}))
