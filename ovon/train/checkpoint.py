"""Training checkpoints that resume exactly: weights, optimiser, schedule, counters, every RNG state
and the environment-sampling state, written atomically (temp file + `os.replace`).

Why atomic: a run killed while saving must leave the previous checkpoint intact. Why every RNG: with
the same seeds, `--resume` after N updates gives the same losses as an uninterrupted run.
The policy alone is also exported as `policy.pt` (`ActorCritic.save` format) for `PolicyAgent`.
"""

from __future__ import annotations

import dataclasses
import os
import random
from pathlib import Path
from typing import Any

import numpy as np
import torch

STATE_NAME = "checkpoint.pt"
POLICY_NAME = "policy.pt"
FORMAT = "ovon-train-v1"


def rng_state() -> dict[str, Any]:
    state = {"python": random.getstate(), "numpy": np.random.get_state(), "torch": torch.get_rng_state()}
    if torch.cuda.is_available():
        state["cuda"] = torch.cuda.get_rng_state_all()
    return state


def set_rng_state(state: dict[str, Any]) -> None:
    """Why `.cpu()`: a checkpoint loaded with `map_location=cuda` moves the RNG byte tensors to the GPU too,
    and torch takes generator states only as CPU byte tensors."""
    random.setstate(state["python"])
    np.random.set_state(state["numpy"])
    torch.set_rng_state(state["torch"].cpu())
    if "cuda" in state and torch.cuda.is_available():
        # one state per GPU the saving process saw; a machine that shows fewer restores those it has
        torch.cuda.set_rng_state_all([s.cpu() for s in state["cuda"][: torch.cuda.device_count()]])


def to_device(obj: Any, device: str | torch.device) -> Any:
    """`obj` with every tensor inside (tuples, named tuples, lists, dicts, dataclasses) moved to `device`.

    Why: checkpoints load onto the CPU, where most of a run's saved state (DAgger's buffer, the acting
    tail, RNG states) lives during training; only the acting memory goes back to the policy's device."""
    if isinstance(obj, torch.Tensor):
        return obj.to(device)
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return dataclasses.replace(
            obj, **{f.name: to_device(getattr(obj, f.name), device) for f in dataclasses.fields(obj) if f.init}
        )
    if isinstance(obj, tuple):
        items = [to_device(x, device) for x in obj]
        return type(obj)(*items) if hasattr(obj, "_fields") else tuple(items)
    if isinstance(obj, list):
        return [to_device(x, device) for x in obj]
    if isinstance(obj, dict):
        return {k: to_device(v, device) for k, v in obj.items()}
    return obj


def seed_everything(seed: int) -> None:
    random.seed(seed)
    np.random.seed(seed % 2**32)
    torch.manual_seed(seed)


def atomic_torch_save(obj: Any, path: str | Path) -> Path:
    """`torch.save` through the project's atomic writer (temp file, fsync, rename)."""
    from ovon.atomic import atomic_write_with

    return atomic_write_with(path, lambda f: torch.save(obj, f))


def save_checkpoint(out_dir: str | Path, payload: dict[str, Any]) -> Path:
    """`payload` holds model/optimizer state dicts, counters and per-rank state (RNG, envs, acting)."""
    payload = {"format": FORMAT, **payload}
    return atomic_torch_save(payload, Path(out_dir) / STATE_NAME)


def load_checkpoint(path: str | Path, map_location: str | torch.device = "cpu") -> dict[str, Any]:
    """A training checkpoint (a folder holding `checkpoint.pt`, or the file itself)."""
    path = Path(path)
    if path.is_dir():
        path = path / STATE_NAME
    if not path.is_file():
        raise FileNotFoundError(f"no training checkpoint at {path}")
    # Our own file: it pickles RNG states and acting-state dataclasses, so weights_only cannot hold it.
    try:
        ckpt = torch.load(path, map_location=map_location, weights_only=False)
    except Exception as e:  # noqa: BLE001 - torch raises many types for a torn or foreign file
        detail = " ".join(str(e).split())[:100]
        raise ValueError(
            f"{path} is not a readable training checkpoint ({type(e).__name__}: {detail}); fix: restore "
            "it, or delete it (and policy.pt) to start the run over"
        ) from None
    if not isinstance(ckpt, dict) or ckpt.get("format") != FORMAT:
        raise ValueError(f"{path} is not an ovon training checkpoint ({FORMAT})")
    return ckpt


def export_policy(policy: torch.nn.Module, out_dir: str | Path, extra: dict[str, Any], update: int, keep: int) -> Path:
    """Write `policy.pt` (atomically) and a numbered snapshot, keeping the newest `keep` snapshots."""
    out_dir = Path(out_dir)
    policy.save(out_dir / POLICY_NAME, extra)  # atomic (ovon.atomic)
    if keep > 0:
        snaps = out_dir / "snapshots"
        snaps.mkdir(exist_ok=True)
        snap = snaps / f"policy_{update:07d}.pt"
        try:
            os.link(out_dir / POLICY_NAME, snap)
        except OSError:
            import shutil

            shutil.copyfile(out_dir / POLICY_NAME, snap)
        for old in sorted(snaps.glob("policy_*.pt"))[:-keep]:
            old.unlink()
    return out_dir / POLICY_NAME
