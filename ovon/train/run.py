"""The run object: all scaffolding of a training run, so that each algorithm file reads top to bottom.

It owns the process group (one process, or one rank under torchrun), seeding, the run folder, the
goal-text table, the envs, building or loading the policy, exact resume, logging, checkpoints and the
rank report. The algorithm owns its loop, its optimiser and the state it needs to resume (acting
memory, DAgger buffer), which it hands to `save` as `rank_state`.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import warnings
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import torch

from ovon.config.task import TaskConfig
from ovon.task.episode import EpisodeSpec
from ovon.train import distributed as dist
from ovon.train.checkpoint import export_policy, load_checkpoint, rng_state, save_checkpoint, seed_everything, to_device
from ovon.train.checkpoint import set_rng_state as _set_rng_state
from ovon.train.config import TrainConfig
from ovon.train.logging import RunLogger
from ovon.train.stop import StopRequest


class TrainRun:
    """`TrainRun(cfg, out_dir, algo, init=...)`: joins the process group, seeds this rank, prepares the
    folder; with `init` (a policy.pt or run folder) the policy and encoder configs become the init's."""

    def __init__(
        self, cfg: TrainConfig, out_dir: str | Path, algo: str, init: str | None = None, resume: bool = False
    ) -> None:
        self.info = dist.setup(cfg.device)
        self.device = self.info.device
        if cfg.threads > 0:
            torch.set_num_threads(cfg.threads)
        self.learn_threads = torch.get_num_threads()
        if cfg.learn_dtype == "bfloat16":
            _quiet_rms_norm_dtype_warning()
        seed_everything(cfg.seed + 7919 * self.info.rank)
        self.out = Path(out_dir)
        self.out.mkdir(parents=True, exist_ok=True)
        self.algo = algo
        self.resume_requested = resume
        self.init_policy = load_init_policy(init, cfg.encoder, cfg.task.kind) if init else None
        if self.init_policy is not None:
            cfg = dataclasses.replace(
                cfg, policy=self.init_policy.cfg, encoder=self.init_policy.encoder_cfg or cfg.encoder
            )
        self.cfg = cfg
        self.table: dict = {}
        self.envs = None
        self.logger: RunLogger | None = None
        self.start_update, self.step = 0, 0
        self.stop = StopRequest()
        self.stopping = False

    @property
    def is_main(self) -> bool:
        return self.info.is_main

    # -- inputs -------------------------------------------------------------------------------------
    def text_table(self, specs: list[EpisodeSpec]) -> dict:
        """Rank 0 computes and caches the goal-text table; the other ranks read the cache after a barrier."""
        from ovon.train.text import needed_texts, text_table

        path = Path(self.cfg.text_cache) if self.cfg.text_cache else self.out / "text_cache.pt"
        texts = needed_texts(specs)
        if self.is_main:
            self.table = text_table(self.cfg.encoder, texts, path, write=True)
        dist.barrier(self.info)
        if not self.is_main:
            self.table = text_table(self.cfg.encoder, texts, path, write=False)
        return self.table

    def open_envs(self, specs: list[EpisodeSpec], task: TaskConfig, label: bool):
        """This rank's share of the episodes in the training env stack (labelled by the expert when
        `label`); returns (envs, first batch)."""
        from ovon.env.stack import EnvRecipe
        from ovon.train.envs import TrainEnvs

        cfg = self.cfg
        mine = dist.shard(list(specs), self.info)
        # PointNav: the goal input is the env's goal vector (from odometry), so there is no text table.
        table = {} if task.kind == "pointnav" else self.text_table(list(specs))
        recipe = EnvRecipe(
            sim=cfg.sim,
            task=task,
            encoder=cfg.encoder,
            text_table={k: torch.as_tensor(v).float().numpy() for k, v in table.items()},
            expert=cfg.expert if label else None,
            expert_cfg=expert_config(cfg) if label else None,
            expert_viewpoint_radius=cfg.expert_viewpoint_radius_m,
            scene_repeat=cfg.scene_repeat,
            **schedule(cfg, task, num_updates(cfg, self.info.world_size)),
        )
        self.envs = TrainEnvs(recipe, mine, cfg.num_envs, cfg.env_workers, cfg.seed * 1000 + self.info.rank)
        return self.envs, self.envs.reset()

    def begin_update(self, update: int) -> None:
        """Tell the envs which update starts (0-based): the clock of the curriculum and of the STOP rule."""
        if self.envs is not None:
            self.envs.set_update(update)

    def policy_for(self, batch):
        """`build_policy` with the image / goal dims of the envs' first batch."""
        image = batch.image
        return self.build_policy(
            int(image.shape[-1]) if isinstance(image, torch.Tensor) else 0, int(batch.goal.shape[-1])
        )

    def build_policy(self, image_dim: int, text_dim: int):
        """The init policy (fine-tuning) or a new one, checked against the envs' dims, on this device."""
        from ovon.models.policy import build_policy

        cfg = self.cfg
        if cfg.encoder.image == "cnn":
            image_dim = cfg.encoder.cnn_dim
        policy = self.init_policy or build_policy(cfg.policy, image_dim, text_dim, cfg.encoder)
        if (policy.image_dim, policy.text_dim) != (image_dim, text_dim):
            raise ValueError(
                f"policy expects image/text dims {(policy.image_dim, policy.text_dim)}, "
                f"the envs give {(image_dim, text_dim)}"
            )
        policy.text_table = self.table
        self.policy = policy.to(self.device)
        return self.policy

    # -- threads ------------------------------------------------------------------------------------
    @contextlib.contextmanager
    def acting(self) -> Iterator[None]:
        """Rollouts: the env workers need the cores, so the learner acts with `rollout_threads` (an idle
        multi-threaded torch pool spins and steals CPU from the workers on a small machine)."""
        if self.cfg.rollout_threads > 0 and self.cfg.rollout_threads != self.learn_threads:
            torch.set_num_threads(self.cfg.rollout_threads)
            try:
                yield
            finally:
                torch.set_num_threads(self.learn_threads)
        else:
            yield

    @contextlib.contextmanager
    def learning(self) -> Iterator[None]:
        """The imitation learners' forward passes in `learn_dtype` (autocast; a no-op for float32)."""
        if self.cfg.learn_dtype == "float32":
            yield
            return
        with torch.autocast(self.device.type, dtype=torch.bfloat16):
            yield

    # -- resume / log / checkpoint -------------------------------------------------------------------
    def restore(self, optimizer) -> dict | None:
        """With `resume` and a checkpoint: weights, optimiser, counters; returns this rank's saved state
        (the caller restores its own parts, then `restore_rng(state)` last). None on a fresh run."""
        if not (self.resume_requested and (self.out / "checkpoint.pt").exists()):
            return None
        ckpt = load_checkpoint(self.out)  # on the CPU: load_state_dict copies weights and optimiser state over
        if ckpt["world_size"] != self.info.world_size:
            raise ValueError(
                f"checkpoint was written by {ckpt['world_size']} ranks; this run has {self.info.world_size}"
            )
        if ckpt.get("algo") not in (None, self.algo):
            raise ValueError(
                f"{self.out} holds a {ckpt['algo']!r} run; resume it with that algorithm or choose another --out"
            )
        self.policy.load_state_dict(ckpt["policy"])
        optimizer.load_state_dict(ckpt["optimizer"])
        self.start_update, self.step = ckpt["update"], ckpt["step"]
        return ckpt["ranks"][self.info.rank]

    @staticmethod
    def restore_rng(state: dict) -> None:
        _set_rng_state(state["rng"])

    def open_logger(self, total: int, description: str | None = None) -> RunLogger:
        """Called as the update loop starts: from here on the first Ctrl-C / SIGTERM is a stop request
        that the loop honours at the end of its update (`checkpoint_due`, `stop_if_requested`)."""
        self.stop.arm()
        self.logger = RunLogger(
            self.out, total, description or self.algo, self.is_main, self.cfg.progress, self.start_update, self.step
        )
        return self.logger

    def log(self, update: int, metrics: dict, step: int | None = None) -> None:
        """Log `update` (1-based) at env step `step` (default: the run's current step)."""
        assert self.logger is not None
        self.logger.log(update, self.step if step is None else step, metrics)

    def save(self, update: int, optimizer, rank_state: dict) -> None:
        """Gather every rank's state (RNG, envs, acting memory) and let rank 0 write checkpoint + policy."""
        from ovon.config.base import to_dict

        # on the CPU first: a CUDA tensor unpickled by another rank would land on this rank's GPU
        ranks = dist.gather_objects(to_device({**rank_state, "rng": rng_state()}, "cpu"), self.info)
        if self.is_main:
            with self.stop.writing():  # a second Ctrl-C here waits for the files to be in place
                cfg = self.cfg
                save_checkpoint(
                    self.out,
                    {
                        "algo": self.algo,
                        "config": to_dict(cfg),
                        "policy": self.policy.state_dict(),
                        "optimizer": optimizer.state_dict(),
                        "update": update,
                        "step": self.step,
                        "world_size": self.info.world_size,
                        "ranks": ranks,
                        "extra": {},
                    },
                )
                export_policy(
                    self.policy,
                    self.out,
                    policy_extra(cfg, self.algo, update, self.step, self.policy),
                    update,
                    cfg.keep_checkpoints,
                )
        dist.barrier(self.info)

    def due(self, update: int, total: int, every: int) -> bool:
        """Whether update `update` (1-based) is a logging / checkpoint point."""
        return update % every == 0 or update == total

    def checkpoint_due(self, update: int, total: int) -> bool:
        """Whether update `update` (1-based) ends with a checkpoint: a scheduled one, or a stop request
        on any rank (a collective: under torchrun every rank must call it on every update)."""
        stop = self.stop.requested
        if self.info.enabled:
            stop = dist.all_reduce_sum(float(stop), self.info) > 0
        self.stopping = stop
        return stop or self.due(update, total, self.cfg.checkpoint_every)

    def stop_if_requested(self) -> None:
        """After `save`: a requested stop ends the run here as an interrupt (the same command resumes)."""
        if self.stopping:
            raise KeyboardInterrupt

    def finish(self, update: int) -> None:
        """Per-rank parameter checksum (DDP ranks must agree; the torchrun test reads it)."""
        d = self.out / "ranks"
        d.mkdir(parents=True, exist_ok=True)
        (d / f"rank{self.info.rank}.json").write_text(
            json.dumps(
                {
                    "rank": self.info.rank,
                    "world_size": self.info.world_size,
                    "update": update,
                    "checksum": param_checksum(self.policy),
                }
            )
        )

    def close(self) -> None:
        self.stop.disarm()
        if self.logger is not None:
            self.logger.close()
        if self.envs is not None:
            self.envs.close()


# ----- helpers ---------------------------------------------------------------------------------------
def expert_config(cfg: TrainConfig) -> Any:
    """The `TrainConfig`'s config for its labelling expert."""
    return cfg.frontier_expert if cfg.expert == "frontier" else cfg.shortest_path_expert


def load_init_policy(path: str | Path, encoder_cfg, task_kind: str | None = None):
    """The IL policy to fine-tune: a `policy.pt`, or a run folder holding one; refused in one line when it
    is not a policy, or was trained with another image encoder or for another task."""
    from ovon.models.policy import ActorCritic

    policy = ActorCritic.load(path, flag="--init")
    if policy.encoder_cfg is not None and policy.encoder_cfg.image != encoder_cfg.image:
        raise ValueError(
            f"--init {str(path)!r} was trained with encoder {policy.encoder_cfg.image!r}, not {encoder_cfg.image!r}"
        )
    trained_for = ((policy.checkpoint_extra or {}).get("task") or {}).get("kind")
    if task_kind is not None and trained_for is not None and trained_for != task_kind:
        raise ValueError(
            f"--init {str(path)!r} is a {trained_for} policy, this run trains {task_kind}; fix: pass "
            f"a policy trained with --task {task_kind}"
        )
    return policy


def schedule(cfg: TrainConfig, task: TaskConfig, total: int) -> dict[str, Any]:
    """The env sampler's schedule in updates of this run: when the curriculum reaches every episode, and from
    which update a failed STOP ends a training episode (evaluation's rule; only when the task says it does not)."""
    cur = cfg.curriculum
    by_updates = cur.start_m > 0 and cur.unit == "updates"
    strict = None
    if not task.failed_stop_ends and cfg.failed_stop_ends_from < 1.0:
        strict = int(round(cfg.failed_stop_ends_from * total))
    return {
        "curriculum_start_m": cur.start_m,
        "curriculum_episodes": cur.episodes if cur.unit == "episodes" else 0,
        "curriculum_updates": max(1, int(round(cur.fraction * total))) if by_updates else 0,
        "strict_stop_from": strict,
    }


def num_updates(cfg: TrainConfig, world_size: int) -> int:
    if cfg.max_updates > 0:
        return cfg.max_updates
    return max(1, cfg.total_steps // (cfg.num_envs * world_size * cfg.rollout_steps))


def policy_extra(cfg: TrainConfig, algo: str, update: int, step: int, policy) -> dict:
    """What `PolicyAgent` needs besides weights: the goal-text table and the camera it was trained with."""
    from ovon.config.base import to_dict

    table = getattr(policy, "text_table", None) or {}
    return {
        "algo": algo,
        "update": update,
        "step": step,
        "expert": cfg.expert,
        "task": to_dict(cfg.task),
        # the temperature the policy last acted at in training (PPO's, else the cross-entropy's 1): what
        # `PolicyAgent` samples at unless told otherwise, so a policy is scored as it was trained
        "acting_temperature": cfg.ppo.temperature if algo.startswith("ppo") else 1.0,
        "text_table": {k: torch.as_tensor(v).float() for k, v in table.items()},
        "camera": {k: v for k, v in to_dict(cfg.sim.camera).items() if isinstance(v, int | float | str)},
    }


def param_checksum(module: torch.nn.Module) -> float:
    """Sum over parameters in float64: identical across DDP ranks when they stay in sync."""
    with torch.no_grad():
        return float(sum(p.detach().double().sum().item() for p in module.parameters()))


_RMS_NORM_WARNING = "Mismatch dtype between input and weight"


def _quiet_rms_norm_dtype_warning() -> None:
    """RMSNorm's float32 weight on a bfloat16 input takes torch's unfused path, which torch warns about on
    every call: expected under `learn_dtype=bfloat16`, not the user's to fix. Installed once per process
    (installing a filter resets which once-per-place warnings were already shown)."""
    if not any(f[1] is not None and f[1].pattern == _RMS_NORM_WARNING for f in warnings.filters):
        warnings.filterwarnings("ignore", message=_RMS_NORM_WARNING, category=UserWarning)
