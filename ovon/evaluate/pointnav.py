"""`ovon evaluate --task pointnav` (`task.kind=pointnav` in `ovon.evaluate.harness`): an agent on point
goals in procedural houses (held-out ones for a trained PointNav policy), with the ObjectNav harness's
workers, records, resume and table. This module holds only what differs: the defaults, where the
episodes come from, and what identifies the run folder.

Why no dataset: a PointNav episode is (house, index); its start/goal pair is sampled at reset from the
episode seed (`ovon.evaluate.runner.episode_seed`), so a seed fixes every pair, every agent gets the same
ones, and the records replay like any other. The task (success radius, distance range, step limit) is the
one the checkpoint was trained with unless `--set task.*` changes it.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

from ovon.config.base import to_dict
from ovon.config.sim import CameraConfig, SimConfig
from ovon.config.task import TaskConfig

if TYPE_CHECKING:
    from ovon.evaluate.plan import RunPlan

SPLIT = "val"
# The EvalConfig fields a PointNav run folder is identified by (run.json), in this order.
KEYS = ("agent", "agent_kwargs", "procedural", "seeds", "episodes", "workers", "executor", "chunk", "sim", "task",
        "name")  # fmt: skip


def pointnav_defaults() -> dict[str, Any]:
    """The `EvalConfig` fields whose PointNav defaults differ from ObjectNav's: no dataset, the four
    held-out houses, 50 episodes per house, the cpu-small policies' depth-only 72x128 camera."""
    return {
        "data": "",
        "scenes": "",
        "splits": (SPLIT,),
        "procedural": "80000-80003",
        "episodes": 50,
        "chunk": 10,
        "sim": SimConfig(camera=CameraConfig(width=72, height=128, rgb=False)),
        "task": TaskConfig(kind="pointnav"),
    }


def checkpoint_task(checkpoint: str | None) -> TaskConfig:
    """The task a PointNav checkpoint was trained with, else the cpu-small PointNav preset's; under the
    evaluation's rule that every STOP ends the episode (`failed_stop_ends` false is a training setting)."""
    import dataclasses

    from ovon.config.base import from_dict
    from ovon.config.task import pointnav_task

    if checkpoint:
        from ovon.models.policy import policy_task_kind, read_policy_file

        ckpt = read_policy_file(checkpoint, "--checkpoint")
        if policy_task_kind(ckpt) == "pointnav":
            return dataclasses.replace(from_dict(TaskConfig, ckpt["extra"]["task"]), failed_stop_ends=True)
    return pointnav_task()


def pointnav_plan(cfg: Any) -> RunPlan:
    """The harness's `RunPlan` of a PointNav evaluation (`cfg`: the harness's `EvalConfig`, which this module
    does not import: the harness imports it): `cfg.episodes` point-goal episodes per house of
    `cfg.procedural`, all in split "val"; the run folder is identified by the houses and the checkpoint's
    content."""
    from ovon.agents import check_agent
    from ovon.config.base import ConfigError, parse_seed_list
    from ovon.evaluate.plan import RunPlan
    from ovon.runfolder import file_sha256
    from ovon.task.pointgoal import pointnav_specs

    if tuple(cfg.splits) != (SPLIT,):
        raise ConfigError(
            f"splits = {list(cfg.splits)}: --task pointnav has one split, {SPLIT!r}; fix: leave "
            f"splits out (Python: ovon.evaluate.harness.pointnav_config)"
        )
    if cfg.episodes is None:
        raise ConfigError("episodes = None: --task pointnav samples a given number per house; fix: pass --episodes N")
    houses = parse_seed_list(cfg.procedural)
    check_agent(cfg.agent, cfg.agent_kwargs)
    name = cfg.name or cfg.agent
    specs = pointnav_specs([f"procedural:{h}" for h in houses], cfg.episodes, SPLIT)
    inputs: dict = {"procedural": houses}
    ckpt = cfg.agent_kwargs.get("checkpoint")
    if isinstance(ckpt, str) and ckpt:
        p = Path(ckpt) / "policy.pt" if Path(ckpt).is_dir() else Path(ckpt)
        if p.is_file():
            inputs["checkpoint"] = {"sha256": file_sha256(p)}
    fields = to_dict(cfg)
    return RunPlan({SPLIT: specs}, name, {k: fields[k] for k in KEYS}, inputs, None, f"evaluate {name} (pointnav)")
