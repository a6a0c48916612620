"""One code path from a CPU process to `torchrun`: rank detection, process group, DDP, data split.

Why: the same trainer runs as a plain `python` process (world size 1, no process group) and under
`torchrun --nproc_per_node N` (RANK/WORLD_SIZE/LOCAL_RANK set): gloo on CPU, nccl on GPUs. Each rank
owns its own environments (episodes are split across ranks); gradients are averaged by DDP; only
rank 0 logs and writes checkpoints.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Any, TypeVar

import torch
import torch.distributed as dist
from torch import nn

from ovon.config.base import ConfigError

T = TypeVar("T")


@dataclass(frozen=True)
class DistInfo:
    rank: int = 0
    world_size: int = 1
    local_rank: int = 0
    device: torch.device = torch.device("cpu")

    @property
    def enabled(self) -> bool:
        return self.world_size > 1

    @property
    def is_main(self) -> bool:
        return self.rank == 0


def launched_by_torchrun() -> bool:
    return "RANK" in os.environ and "WORLD_SIZE" in os.environ


def resolve_device(pref: str, local_rank: int = 0) -> torch.device:
    """`auto` = this rank's GPU when CUDA is available, else CPU. A rank whose GPU does not exist is refused
    here, in one line, instead of failing inside CUDA at its first tensor (torchrun started more processes
    per node than the node has GPUs; NCCL also refuses two ranks on one GPU)."""
    if pref == "auto":
        if not torch.cuda.is_available():
            return torch.device("cpu")
        dev = torch.device(f"cuda:{local_rank}")
    else:
        dev = torch.device(pref)
        if dev.type == "cuda" and dev.index is None:
            dev = torch.device(f"cuda:{local_rank}")
    if dev.type == "cuda":
        n = torch.cuda.device_count() if torch.cuda.is_available() else 0
        if n == 0:
            raise ConfigError(
                f"device = {pref}: CUDA sees no GPU on this machine; fix: --set device=auto "
                "(the GPU where there is one, else the CPU) or --set device=cpu"
            )
        if dev.index >= n:
            raise ConfigError(
                f"device = {pref}: this process (local rank {local_rank}) needs cuda:{dev.index} "
                f"but CUDA sees {n} GPU(s); fix: start at most {n} processes per node "
                f"(torchrun --nproc_per_node {n}), or train on the CPU with --set device=cpu"
            )
    return dev


def local_rank() -> int:
    """This process's rank on its node (0 outside torchrun)."""
    return int(os.environ.get("LOCAL_RANK", os.environ.get("RANK", 0))) if launched_by_torchrun() else 0


def check_device(device: str) -> torch.device:
    """The device this process would train on; a missing GPU is a ConfigError (see `resolve_device`)."""
    return resolve_device(device, local_rank())


def setup(device: str = "auto") -> DistInfo:
    """Read torchrun's env vars and join the process group (no-op for a single process)."""
    if not launched_by_torchrun() or int(os.environ["WORLD_SIZE"]) <= 1:
        return DistInfo(device=resolve_device(device))
    rank, world = int(os.environ["RANK"]), int(os.environ["WORLD_SIZE"])
    local = local_rank()
    dev = resolve_device(device, local)
    if dev.type == "cuda":
        torch.cuda.set_device(dev)
    if not dist.is_initialized():
        # GPU ranks: nccl for the model's CUDA tensors, gloo for the CPU scalars of logging and stop requests
        # (nccl alone refuses a CPU tensor)
        dist.init_process_group("cpu:gloo,cuda:nccl" if dev.type == "cuda" else "gloo")
    return DistInfo(rank, world, local, dev)


def cleanup() -> None:
    if dist.is_available() and dist.is_initialized():
        dist.destroy_process_group()


def wrap(model: nn.Module, info: DistInfo) -> nn.Module:
    """DDP-wrap for multi-rank runs (the plain module otherwise). Call after freezing parameters."""
    if not info.enabled:
        return model
    from torch.nn.parallel import DistributedDataParallel

    ids = [info.device.index] if info.device.type == "cuda" else None
    return DistributedDataParallel(model, device_ids=ids)


def unwrap(model: nn.Module) -> nn.Module:
    return model.module if hasattr(model, "module") else model


def shard(items: list[T], info: DistInfo) -> list[T]:
    """This rank's share (round-robin, so every rank sees a mix of scenes when items are interleaved)."""
    if not info.enabled:
        return list(items)
    part = items[info.rank :: info.world_size]
    if not part:
        raise ValueError(f"rank {info.rank}: nothing to train on ({len(items)} items for {info.world_size} ranks)")
    return part


def all_reduce_mean(values: dict[str, float], info: DistInfo) -> dict[str, float]:
    """Average scalar metrics over ranks (for logging on rank 0)."""
    if not info.enabled or not values:
        return values
    keys = sorted(values)
    t = torch.tensor([float(values[k]) for k in keys], dtype=torch.float64)
    dist.all_reduce(t)
    return {k: float(v) / info.world_size for k, v in zip(keys, t.tolist())}


def all_reduce_sum(x: float, info: DistInfo) -> float:
    if not info.enabled:
        return x
    t = torch.tensor([float(x)], dtype=torch.float64)
    dist.all_reduce(t)
    return float(t.item())


def gather_objects(obj: Any, info: DistInfo) -> list[Any]:
    """Every rank's `obj` (e.g. finished-episode metrics) on every rank."""
    if not info.enabled:
        return [obj]
    out: list[Any] = [None] * info.world_size
    dist.all_gather_object(out, obj)
    return out


def barrier(info: DistInfo) -> None:
    if info.enabled:
        dist.barrier()
