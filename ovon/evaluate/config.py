"""What an evaluation runs (`EvalConfig`) and how it is built: from `ovon evaluate`'s options
(`eval_config`), from a policy checkpoint (its camera and, for PointNav, its task), from `--noise` and
`--set`. The command line and the experiment runner only call these, so a cell resolves to the config its
command would run.

Why PointNav is a task option here and not a second config: it runs through the same harness (workers,
records, resume, table); only its defaults (`pointnav_defaults`) and where its episodes come from differ.
"""

from __future__ import annotations

import dataclasses
import math
import typing
from dataclasses import dataclass, field
from typing import Any, ClassVar, Literal

import yaml

from ovon.agents.base import ROW_NAME
from ovon.agents.remote import RemoteConfig
from ovon.config.base import (
    ConfigError,
    ExistingDir,
    NonNegative,
    Pattern,
    constrained,
    from_dict,
    in_range,
    merge,
    non_empty,
    parse_overrides,
    positive,
    rule,
    validate,
)
from ovon.config.sim import CameraConfig, NoiseConfig, SimConfig, cpu_sim_config
from ovon.config.task import TaskConfig
from ovon.dataset.io import SPLIT_NAME_PATTERN, VAL_SPLITS

SPLIT_NAME = Pattern(SPLIT_NAME_PATTERN, "split folder names (letters, digits, _ . -)")
HOUSE_SEEDS = Pattern(r" *([0-9]+(-[0-9]+)? *(, *[0-9]+(-[0-9]+)? *)*)?", "house seeds like 80000-80003 or 0,5-7")
POINTNAV_SPLIT = "val"  # PointNav episodes are sampled in held-out houses: one split
SUBSET = Pattern(r"[^\n]*", "a named subset (mini) or a subset file")


@dataclass
class EvalConfig:
    agent: str = non_empty("random", flag="--agent")
    agent_kwargs: dict = field(default_factory=dict)
    # objectnav: the episode dataset and scenes roots; pointnav: "" (episodes sampled in `procedural` houses)
    data: str = constrained("data/datasets/ovon", ExistingDir(True, "with --task pointnav"), flag="--data")
    scenes: str = constrained("data/scene_datasets", ExistingDir(True, "with --task pointnav"), flag="--scenes")
    procedural: str = constrained("", HOUSE_SEEDS, flag="--procedural")  # pointnav only: house seeds, e.g. 80000-80003
    splits: tuple[str, ...] = non_empty(VAL_SPLITS, each=SPLIT_NAME, distinct=True, flag="--splits")
    seeds: tuple[int, ...] = non_empty((0,), each=NonNegative(), distinct=True, flag="--seeds")
    episodes: int | None = positive(None, flag="--episodes")  # per split; None = all
    workers: int = in_range(1, 1, 1024, flag="--workers")
    executor: Literal["process", "ray"] = constrained("process", flag="--executor")
    chunk: int = in_range(4, 1, 100_000)  # episodes per work unit (same scene)
    sim: SimConfig = field(default_factory=cpu_sim_config)
    task: TaskConfig = field(default_factory=TaskConfig)
    # row name in tables; default = agent (its own name if remote)
    name: str | None = constrained(None, ROW_NAME, flag="--name")
    remote: RemoteConfig = field(default_factory=RemoteConfig)  # --agent remote:HOST:PORT only
    strict: bool = False  # refuse a split holding an invalid episode instead of skipping it (counted)
    # The episodes to run: "" = the splits (or their first `episodes`), a named subset (`mini`) or a subset file
    # written by `ovon dataset subset` (ovon.dataset.subset: chosen by content, the same for everyone).
    subset: str = constrained("", SUBSET, flag="--subset")
    rules: ClassVar = (
        rule(
            ("task.failed_stop_ends",),
            bool,
            "task.failed_stop_ends true (false is a training-only setting: every STOP ends an evaluated episode)",
        ),
    )


def with_camera(cfg: EvalConfig, camera: dict) -> EvalConfig:
    """`cfg` with these camera fields changed (e.g. the camera a policy checkpoint was trained with)."""
    return dataclasses.replace(
        cfg, sim=dataclasses.replace(cfg.sim, camera=dataclasses.replace(cfg.sim.camera, **camera))
    )


def pointnav_defaults() -> dict[str, Any]:
    """The `EvalConfig` fields whose PointNav defaults differ from ObjectNav's: no dataset, the four
    held-out houses, 50 episodes per house, the CPU camera without colour (PointNav policies read depth)."""
    cpu = cpu_sim_config()
    return {
        "data": "",
        "scenes": "",
        "splits": (POINTNAV_SPLIT,),
        "procedural": "80000-80003",
        "episodes": 50,
        "chunk": 10,
        "sim": dataclasses.replace(cpu, camera=dataclasses.replace(cpu.camera, rgb=False)),
        "task": TaskConfig(kind="pointnav"),
    }


def pointnav_config(**fields: Any) -> EvalConfig:
    """An `EvalConfig` for PointNav: `pointnav_defaults()` updated with `fields`, validated."""
    return validate(EvalConfig(**{**pointnav_defaults(), **fields}))


def checkpoint_task(checkpoint: str | None) -> TaskConfig:
    """The task a PointNav checkpoint was trained with, else the cpu-small PointNav preset's; under the
    evaluation's rule that every STOP ends the episode (`failed_stop_ends` false is a training setting)."""
    from ovon.config.task import pointnav_task

    if checkpoint:
        from ovon.models.policy import policy_task_kind, read_policy_file

        ckpt = read_policy_file(checkpoint, "--checkpoint")
        if policy_task_kind(ckpt) == "pointnav":
            return dataclasses.replace(from_dict(TaskConfig, ckpt["extra"]["task"]), failed_stop_ends=True)
    return pointnav_task()


def parse_noise(spec: str | None) -> NoiseConfig:
    """`actuation,odometry`, `actuation:movebase`, `actuation:ilqr*2` (multiplier), `odometry:drift`
    (dead-reckoning drift instead of the paper's bounded per-reading error) or empty."""
    cfg = NoiseConfig()
    if not spec:
        return cfg
    models = typing.get_args(typing.get_type_hints(NoiseConfig)["actuation"])
    odo_modes = typing.get_args(typing.get_type_hints(NoiseConfig)["odometry_mode"])
    fix = "fix: use e.g. --noise actuation,odometry or --noise actuation:movebase*0.5"
    seen: dict[str, str] = {}
    for item in [s.strip() for s in spec.split(",") if s.strip()]:
        name, _, arg = item.partition(":")
        if name in seen:  # the last one would silently win
            raise ConfigError(
                f"--noise {spec!r}: {name} noise given twice ({seen[name]!r} and {item!r}); fix: keep one of them"
            )
        seen[name] = item
        if name == "actuation":
            model, _, mult = (arg or "ilqr").partition("*")
            if model not in models:
                raise ConfigError(
                    f"--noise {item!r}: unknown actuation model {model!r}, expected one of {', '.join(models)}; {fix}"
                )
            try:
                k = float(mult or 1.0)
            except ValueError:
                raise ConfigError(f"--noise {item!r}: multiplier {mult!r} is not a number; {fix}") from None
            cfg = dataclasses.replace(cfg, actuation=model, actuation_multiplier=k)
            if not 0 <= k <= 100:
                raise ConfigError(f"--noise {item!r}: multiplier {k:g} is outside [0, 100]; {fix}")
        elif name == "odometry" and arg in ("",) + odo_modes:
            cfg = dataclasses.replace(cfg, odometry=True, odometry_mode=arg or "bounded")
        else:
            raise ConfigError(
                f"--noise: unknown noise {item!r}, expected actuation[:ilqr|proportional|movebase|"
                f"gaussian][*k] or odometry[:bounded|drift]; {fix}"
            )
    return validate(cfg, "sim.noise")


def apply_overrides(cfg: EvalConfig, overrides: list[str]) -> EvalConfig:
    """`cfg` with `--set` overrides (sim.*, task.*, remote.*) merged in."""
    data = parse_overrides(overrides)
    groups = {g: merge(getattr(cfg, g), data.pop(g), g) for g in ("sim", "task", "remote") if g in data}
    if data:
        raise ConfigError(
            f"unknown override group(s) {sorted(data)}; fix: --set takes sim.*, task.* or remote.* keys "
            "here (e.g. --set task.max_steps=300); the other settings have their own options"
        )
    return dataclasses.replace(cfg, **groups)


def check_episode_source(cfg: EvalConfig) -> None:
    """Where the episodes come from fits the task: a dataset (`data`, `scenes`) for objectnav, procedural
    houses (`procedural`) for pointnav."""
    if cfg.task.kind == "pointnav":
        if cfg.data or cfg.scenes:
            raise ConfigError("--task pointnav samples episodes in --procedural houses; fix: drop --data / --scenes")
        if not cfg.procedural:
            raise ConfigError("--task pointnav needs --procedural SEEDS (held-out houses, e.g. 80000-80003)")
        return
    if cfg.procedural:
        raise ConfigError(
            f"--procedural = {cfg.procedural!r}: house seeds are for --task pointnav; fix: drop "
            "--procedural, or pass --task pointnav (Python: task.kind='pointnav')"
        )
    for flag, value in (("--data", cfg.data), ("--scenes", cfg.scenes)):
        if not value:
            raise ConfigError(
                f"{flag} = '': expected an existing folder; fix: pass {flag} (objectnav evaluates "
                "the episodes of a dataset; --task pointnav samples them in --procedural houses)"
            )


# -- from the command line -------------------------------------------------------------------------
def parse_agent_args(items: list[str], checkpoint: str | None) -> dict:
    """`--agent-arg KEY=VALUE` items (values read as YAML) and `--checkpoint` as an agent's keyword
    arguments (`ovon evaluate`, `ovon serve`)."""
    kwargs = {}
    for item in items:
        k, sep, v = item.partition("=")
        if not sep or not all(part.isidentifier() for part in k.strip().split(".")):
            raise ConfigError(
                f"--agent-arg {item!r} is not KEY=VALUE with KEY a Python name (or dotted names, "
                "for agents that take nested settings); fix: e.g. --agent-arg temperature=0.5 or "
                "--agent-arg navigator.stop_distance_m=0.6"
            )
        try:
            kwargs[k.strip()] = yaml.safe_load(v) if v != "" else ""
        except (yaml.YAMLError, RecursionError, ValueError):
            kwargs[k.strip()] = v  # not YAML: the text itself
        if not _finite(kwargs[k.strip()]):
            # the arguments are part of the run's identity (JSON, which has no nan / inf): refused later
            # with a message naming no key
            raise ConfigError(
                f"--agent-arg {item!r}: {v.strip()} is not a finite number (nan and inf cannot be "
                f"recorded in the run folder); fix: pass a finite number, e.g. --agent-arg "
                f"{k.strip()}=0.5"
            )
    if checkpoint is not None:
        if "checkpoint" in kwargs:
            raise ConfigError("--checkpoint and --agent-arg checkpoint=... both given; fix: pass one of them")
        kwargs["checkpoint"] = checkpoint
    return kwargs


def _finite(value: object) -> bool:
    """No nan / inf anywhere in a parsed `--agent-arg` value (YAML reads `.nan`, `.inf`, `[1, .nan]`)."""
    if isinstance(value, float):
        return math.isfinite(value)
    if isinstance(value, list | tuple):
        return all(_finite(v) for v in value)
    if isinstance(value, dict):
        return all(_finite(v) for v in value.values())
    return True


def checkpoint_facts(checkpoint: str, task: str) -> dict:
    """Camera fields a policy checkpoint was trained with ({} when it does not say): a policy sees the
    world through the resolution it learned on unless the user asks otherwise. Refuses, before any work, a
    file that is not a policy and a policy of the other task (`task`: the --task being evaluated)."""
    from ovon.models.policy import policy_task_kind, read_policy_file

    ckpt = read_policy_file(checkpoint, "--checkpoint")
    kind = policy_task_kind(ckpt)
    if kind is not None and kind != task:
        fix = (
            "evaluate it with --task pointnav (point goals in procedural houses), or use it as VLFM's "
            "navigator: --agent vlfm --agent-arg navigator=learned --agent-arg navigator.checkpoint=PATH"
            if kind == "pointnav"
            else "leave --task pointnav out"
        )
        name = {"objectnav": "an ObjectNav", "pointnav": "a PointNav"}
        raise ConfigError(
            f"--checkpoint {checkpoint!r} is {name.get(kind, kind)} policy, this is "
            f"{name.get(task, task)} evaluation; fix: {fix}"
        )
    extra = ckpt.get("extra", {}) or {}
    camera = extra.get("camera") if isinstance(extra, dict) else None
    fields = {f.name for f in dataclasses.fields(CameraConfig)}
    return {k: v for k, v in (camera or {}).items() if k in fields and k != "backend"}


def protocol_config(name: str) -> dict[str, Any]:
    """The EvalConfig fields a named protocol fixes: hm3d-ovon is the authors' rig and task (the defaults of
    SimConfig and TaskConfig: the Stretch, its 360x640 camera, 500 steps, 0.25 m), without noise."""
    from ovon.evaluate.protocol import NAMED

    if name not in NAMED:
        raise ConfigError(
            f"--protocol {name!r} is not a protocol ovon knows (known: {', '.join(sorted(NAMED))}); fix: name one "
            "of them, or --protocol none and set each option yourself (the card then says custom)"
        )
    return {"sim": SimConfig(), "task": TaskConfig()}


def resolve_protocol(asked: str, cfg: EvalConfig) -> str:
    """The named protocol a run starts from ("" for none): `auto` is hm3d-ovon when the episodes name HM3D
    scenes (the released dataset's, and any generated for HM3D), so an HM3D number is the authors' unless an
    option says otherwise; the embedded world's episodes keep ovon's CPU defaults."""
    if asked == "none":
        return ""
    if asked != "auto":
        protocol_config(asked)  # an unknown name is one line here
        return asked
    from ovon.dataset.io import EpisodeDataset

    for split in cfg.splits:
        try:
            ds = EpisodeDataset(cfg.data, split)
            scenes = ds.scenes()
            episodes = ds.load_scene(scenes[0]).episodes if scenes else []
        except (OSError, ValueError):  # a missing or broken split is refused, with its own line, by the run
            continue
        if episodes:
            return "hm3d-ovon" if str(episodes[0].scene_id).startswith("hm3d/") else ""
    return ""


def eval_config(args: Any, notes: list[str] | None = None) -> EvalConfig:
    """`ovon evaluate`'s options (an argparse namespace) as an `EvalConfig`, through the one config path
    (coercion + declared domains), so `--episodes -1`, `--seeds ''` or `--splits ''` are refused with the
    same one-line message as `--set`. What the user should be told (the camera taken from a checkpoint)
    is appended to `notes`."""
    asked = getattr(args, "protocol", None) or "auto"
    if getattr(args, "task", "objectnav") == "pointnav":
        subset = getattr(args, "subset", None)
        for flag, value in (("--subset", subset), ("--protocol", None if asked in ("auto", "none") else asked)):
            if value:
                raise ConfigError(
                    f"{flag} {value!r}: ObjectNav only (--task pointnav samples its episodes in --procedural "
                    f"houses under its checkpoint's task); fix: drop {flag}"
                )
        return _pointnav_eval_config(args)
    cfg = from_dict(
        EvalConfig,
        {
            "agent": args.agent,
            "agent_kwargs": parse_agent_args(args.agent_arg, args.checkpoint),
            "data": args.data,
            "scenes": args.scenes,
            "procedural": args.procedural or "",
            "splits": args.splits,
            "seeds": args.seeds,
            "episodes": args.episodes,
            "workers": args.workers,
            "executor": args.executor,
            "name": args.name,
            "strict": args.strict,
            "subset": getattr(args, "subset", None) or "",
        },
    )
    checkpoint = cfg.agent_kwargs.get("checkpoint") if args.agent in ("policy", "dagrl-od") else None
    camera = checkpoint_facts(str(checkpoint), "objectnav") if checkpoint else {}
    say = notes.append if notes is not None else (lambda line: None)
    protocol = resolve_protocol(asked, cfg)
    if protocol:  # the protocol's settings first: the options below change them, and the card says so
        cfg = dataclasses.replace(cfg, **protocol_config(protocol))
        if asked == "auto":
            say(
                f"protocol {protocol}: the episodes name HM3D scenes, so the authors' settings apply (camera "
                f"{cfg.sim.camera.width}x{cfg.sim.camera.height}, {cfg.task.max_steps} steps); --protocol none keeps "
                "ovon's CPU defaults"
            )
    if args.preset == "paper":
        cfg = dataclasses.replace(cfg, sim=SimConfig())
    elif args.preset == "cpu":
        cfg = dataclasses.replace(cfg, sim=cpu_sim_config())
    elif camera and protocol:
        say(
            f"protocol {protocol}: its {cfg.sim.camera.width}x{cfg.sim.camera.height} camera, not the checkpoint's "
            f"{camera.get('width')}x{camera.get('height')} (--preset cpu or --set sim.camera.* change it)"
        )
    elif camera:
        cfg = with_camera(cfg, camera)
        say(f"camera of the checkpoint: {camera.get('width')}x{camera.get('height')} (--preset cpu|paper overrides)")
    cfg = dataclasses.replace(cfg, sim=dataclasses.replace(cfg.sim, noise=parse_noise(args.noise)))
    return validate(apply_overrides(cfg, args.set))


def _pointnav_eval_config(args: Any) -> EvalConfig:
    """`eval_config` for `--task pointnav`: the checkpoint's task and camera unless --set says otherwise."""
    kwargs = parse_agent_args(args.agent_arg, args.checkpoint)
    data = {
        "agent": args.agent,
        "agent_kwargs": kwargs,
        "data": args.data or "",
        "scenes": args.scenes or "",
        "procedural": args.procedural or "",
        "seeds": args.seeds,
        "workers": args.workers,
        "executor": args.executor,
        "name": args.name,
    }
    if args.episodes is not None:
        data["episodes"] = args.episodes
    cfg = from_dict(EvalConfig, {**pointnav_defaults(), **data})
    check_episode_source(cfg)
    ckpt = kwargs.get("checkpoint")
    camera = checkpoint_facts(str(ckpt), "pointnav") if ckpt else {}
    cfg = dataclasses.replace(cfg, task=checkpoint_task(str(ckpt) if ckpt else None))
    if args.preset == "paper":
        cfg = dataclasses.replace(cfg, sim=SimConfig())
    elif args.preset == "auto" and ckpt:
        if camera:
            cfg = with_camera(cfg, camera)
    elif args.preset == "cpu":
        cpu = cpu_sim_config().camera
        cfg = with_camera(cfg, {"width": cpu.width, "height": cpu.height})
    cfg = dataclasses.replace(cfg, sim=dataclasses.replace(cfg.sim, noise=parse_noise(args.noise)))
    return validate(apply_overrides(cfg, args.set))
