"""Resolve experiment definitions at a scale into typed cells (`ovon.experiments.cells`).

Why typed: a cell's config (the GenerationConfig, the TrainConfig built by `ovon.train.config.build_config`,
the EvalConfig) is its identity; its command is rendered from it. Validation also parses each rendered
command with the real `ovon` argument parser, so a definition that resolves here is one the commands
accept. Layout under `<root>/<scale>/`:
`data/` (generated scenes + episodes), `train/<cell>/`, `eval/<cell>/`, `cells/` (the runner's records),
`locks/`, `logs/`, `reports/`.
"""

from __future__ import annotations

import contextlib
import io
import shlex
from pathlib import Path
from types import SimpleNamespace
from typing import Any

from ovon.config.base import ConfigError, merge, parse_overrides
from ovon.dataset.io import VAL_SPLITS
from ovon.experiments.cells import Cell, DataRun, EvalRun, Plan, TrainRun, overrides_text
from ovon.experiments.definitions import (
    Catalogue,
    CellScale,
    DefinitionError,
    EvalCell,
    Experiment,
    Scale,
    TrainCell,
    load_catalogue,
    merged_catalogue,
    paper_numbers,
    parse_ref,
    row_eval,
)
from ovon.experiments.findings import sentence_refs
from ovon.runfolder import flatten  # {"a": {"b": 1}, "c.d": 2} -> {"a.b": 1, "c.d": 2}: the one flattener
from ovon.train.folder import EpisodeSource

CAMERA_FIELDS = ("width", "height", "hfov_deg", "camera_height", "min_depth", "max_depth")
PERCEPTION = {
    "oracle-vl": "oracle perception",
    "world-vl": "learned perception (world-vl)",
    "siglip": "SigLIP",
    "cnn": "CNN trained from pixels",
}


def display(cell: Cell, argv: list[str]) -> str:
    """The command as a user types it (`ovon ...`, or `torchrun ... -m ovon.cli.main ...`)."""
    head = [*cell.launcher, "-m", "ovon.cli.main"] if cell.launcher else ["ovon"]
    return shlex.join([*head, *argv])


# ----- resolution ------------------------------------------------------------------------------------
def resolve(
    experiments: list[Experiment],
    scale: str,
    root: str | Path,
    overrides: list[str] | tuple = (),
    catalogue: Catalogue | None = None,
) -> Plan:
    """The plan of `experiments` at `scale` under `root`; every definition error is raised here, before
    any work, as one line naming the file, key and fix."""
    cat = merged_catalogue(experiments, catalogue or load_catalogue())
    if scale not in cat.scales:
        raise DefinitionError(f"unknown scale {scale!r}; valid: {', '.join(cat.scales)} (scales.yaml)")
    sc = cat.scales[scale]
    if overrides:
        try:
            sc = merge(sc, parse_overrides(list(overrides)))  # keys as typed: the fix reads `--set KEY=VALUE`
        except ConfigError as e:
            raise DefinitionError(f"{e}; --set here takes the scale's keys (data.*, train.*, evaluate.*)") from None
    _check_scale(sc)
    plan = Plan(list(experiments), sc, Path(root), cat)
    _data_cell(plan)
    eval_names = needed_evals(experiments, cat)
    for name in train_order(eval_names, cat, scale):
        _train_cell(plan, name)
    for name in eval_names:
        _eval_cell(plan, name)
    for exp in experiments:
        check_experiment(exp, plan)
    return plan


def _check_scale(sc: Scale) -> None:
    w = f"scales.yaml:{sc.name}"
    d, e, t = sc.data, sc.evaluate, sc.train
    if d.source == "generate":
        for key in ("train_scenes", "val_scenes", "workers"):
            if getattr(d, key) < 1:
                raise DefinitionError(f"{w}.data.{key} = {getattr(d, key)!r}; expected an integer >= 1")
    elif not d.episodes or not d.scenes:
        raise DefinitionError(
            f"{w}.data: source 'paths' needs data.episodes and data.scenes; fix: --set "
            "data.episodes=/path/to/hm3d_ovon_episodes --set data.scenes=/path/to/scene_datasets"
        )
    if len(set(e.seeds)) < 2 or any(s < 0 for s in e.seeds):
        raise DefinitionError(
            f"{w}.evaluate.seeds = {list(e.seeds)}; expected >= 2 distinct seeds >= 0 (the "
            "report gives the std over seeds)"
        )
    if e.episodes is not None and e.episodes < 1:
        raise DefinitionError(f"{w}.evaluate.episodes = {e.episodes!r}; expected an integer >= 1 or null (all)")
    if e.workers < 1 or t.nproc_per_node < 0:
        raise DefinitionError(f"{w}: evaluate.workers must be >= 1 and train.nproc_per_node >= 0")


def needed_evals(experiments: list[Experiment], cat: Catalogue) -> list[str]:
    """Evaluation cells the experiments' tables and figures name, in first-use order."""
    out: dict[str, None] = {}
    for exp in experiments:
        if exp.table is not None:
            for row in exp.table.rows:
                for col in exp.table.columns:
                    out.setdefault(row_eval(row, col.name))
        for fig in exp.figures:
            out.setdefault(fig.eval)
    for name in out:
        if name not in cat.evaluate:
            where = next(e.source for e in experiments)
            raise DefinitionError(
                f"{where}: evaluation cell {name!r} is not defined; valid: "
                f"{', '.join(sorted(cat.evaluate))} (cells.yaml, or an `evaluate:` section)"
            )
    return list(out)


def train_spec(tc: TrainCell, scale: str) -> tuple[str, str]:
    """(recipe, init) of a training cell at `scale`: its own unless the scale names others ("" = no init)."""
    per = _per_scale(tc, scale)
    init = per.init or tc.init
    return per.recipe or tc.recipe, "" if init == "none" else init


def train_order(eval_names: list[str], cat: Catalogue, scale: str) -> list[str]:
    """Training cells the evaluations need (checkpoints, cameras, inits), each after its init."""
    order: list[str] = []

    def visit(name: str, path: tuple[str, ...], who: str) -> None:
        if name in order:
            return
        if name in path:
            raise DefinitionError(
                f"cells.yaml: training cells initialise each other in a cycle: {' -> '.join([*path, name])}"
            )
        if name not in cat.train:
            raise DefinitionError(
                f"{who} names training cell {name!r}, which is not defined; valid: {', '.join(sorted(cat.train))}"
            )
        init = train_spec(cat.train[name], scale)[1]
        if init:
            visit(init, (*path, name), f"train.{name}.init")
        order.append(name)

    for name in eval_names:
        cell = cat.evaluate[name]
        for ref, key in ((cell.checkpoint, "checkpoint"), (cell.camera, "camera")):
            if ref:
                visit(ref, (), f"evaluate.{name}.{key}")
    return order


def _data_cell(plan: Plan) -> None:
    d, base = plan.scale.data, plan.base
    if d.source == "paths":
        plan.episodes_dir, plan.scenes_dir = Path(d.episodes), Path(d.scenes)
        plan.cells["data:data"] = Cell("data", "data", plan.episodes_dir)
        return
    scenes, episodes = base / "data" / "scenes", base / "data" / "episodes"
    plan.episodes_dir, plan.scenes_dir = episodes, scenes
    overrides = flatten(d.set)
    config = generation_config(d.preset, overrides, f"scales.yaml:{plan.scale.name}.data")
    run = DataRun(config, d.preset, overrides, scenes, episodes, d.train_scenes, d.val_scenes, d.seed, d.workers)
    plan.cells["data:data"] = Cell("data", "data", base / "data", run)


def generation_config(preset: str, overrides: dict, where: str) -> Any:
    """The GenerationConfig `ovon dataset generate --preset PRESET --set ...` builds."""
    from ovon.config.dataset import generation_config as build

    try:
        return build(SimpleNamespace(preset=preset, config=None, set=overrides_text(overrides)))
    except (ConfigError, KeyError, ValueError, TypeError) as e:
        raise DefinitionError(f"{where}: {e.args[0] if isinstance(e, KeyError) and e.args else e}") from None


def _per_scale(cell: TrainCell | EvalCell, scale: str) -> CellScale:
    return cell.scales.get(scale) or CellScale()


def _train_cell(plan: Plan, name: str) -> None:
    cat, sc = plan.catalogue, plan.scale
    tc = cat.train[name]
    where = f"cells.yaml:train.{name}"
    recipe_name, init_name = train_spec(tc, sc.name)
    if recipe_name not in cat.recipes:
        raise DefinitionError(f"{where}.recipe = {recipe_name!r}; valid: {', '.join(cat.recipes)} (recipes.yaml)")
    recipe = cat.recipes[recipe_name]
    if sc.name not in recipe.scales:
        raise DefinitionError(
            f"recipes.yaml:{recipe_name} has no settings for scale {sc.name!r}; fix: add "
            f"scales.{sc.name} (preset and set) to it"
        )
    rs = recipe.scales[sc.name]
    init = plan.cells.get(f"train:{init_name}") if init_name else None
    if init is not None and recipe.algo != "ppo":
        raise DefinitionError(f"{where}: init works with a ppo recipe (BC->RL, DAgger->RL), not {recipe.algo!r}")
    folder = plan.base / "train" / name
    overrides = {
        **flatten(sc.train.set),
        **flatten(rs.set),
        **flatten(tc.set),
        **flatten(_per_scale(tc, sc.name).set),
        "text_cache": str(plan.base / "data" / "text_cache.pt"),
    }
    options = SimpleNamespace(
        algo=recipe.algo,
        preset=rs.preset,
        expert=tc.expert or None,
        policy=(tc.policy if init is None else "") or None,
        encoder=None,
        config=None,
        task=None,
        set=overrides_text(overrides),
    )
    source = EpisodeSource(data=str(plan.episodes_dir), scenes=str(plan.scenes_dir))
    launcher: tuple[str, ...] = ()
    if sc.train.nproc_per_node > 0:
        launcher = ("torchrun", *sc.train.torchrun_args, "--nproc-per-node", str(sc.train.nproc_per_node))
    init_path = str(init.folder / "policy.pt") if init is not None else ""
    run = TrainRun(
        build_train_config(options, where),
        source,
        recipe.algo,
        rs.preset,
        tc.expert,
        options.policy or "",
        init_path,
        overrides,
        folder,
        world_size(sc),
    )
    cell = Cell("train", name, folder, run, ("data:data",) + ((init.id,) if init else ()), launcher)
    check_command(cell, where)
    if init is not None:
        if tc.policy and tc.policy != init.train_cfg.policy.core:
            raise DefinitionError(
                f"{where}.policy = {tc.policy!r}, but a fine-tune keeps the core of its init "
                f"{init_name!r} ({init.train_cfg.policy.core}); fix: drop policy or change the init"
            )
        if init.train_cfg.encoder.image != cell.train_cfg.encoder.image:
            raise DefinitionError(
                f"{where}: encoder {cell.train_cfg.encoder.image!r} differs from its init's "
                f"({init.train_cfg.encoder.image!r}); fix: use the same preset/encoder"
            )
    cell.total = train_updates(cell.train_cfg, world_size(sc))
    plan.cells[cell.id] = cell


def world_size(sc: Scale) -> int:
    if sc.train.nproc_per_node <= 0:
        return 1
    args = list(sc.train.torchrun_args)
    nodes = 1
    for i, a in enumerate(args):
        value = (
            a.split("=", 1)[1]
            if a.startswith("--nnodes=")
            else (args[i + 1] if a == "--nnodes" and i + 1 < len(args) else None)
        )
        if value:
            nodes = int(value.split(":")[-1])
    return sc.train.nproc_per_node * nodes


def train_updates(cfg: Any, world: int) -> int | None:
    """Updates a training run makes (None for BC without `max_updates`: it depends on the data)."""
    if cfg.max_updates > 0:
        return cfg.max_updates
    if cfg.algo == "bc":
        return None
    return max(1, cfg.total_steps // (cfg.num_envs * world * cfg.rollout_steps))


def parse_cli(argv: list[str], where: str):
    """`argv` parsed by the real `ovon` parser; its error becomes one DefinitionError line."""
    from ovon.cli.main import build_parser

    err = io.StringIO()
    try:
        with contextlib.redirect_stderr(err):
            return build_parser().parse_args(argv)
    except SystemExit:
        lines = [ln for ln in err.getvalue().splitlines() if ln.strip()]
        raise DefinitionError(
            f"{where}: the command `ovon {shlex.join(argv)}` is refused: {lines[-1] if lines else 'invalid arguments'}"
        ) from None


def check_command(cell: Cell, where: str) -> Any:
    """The cell's (last) command parsed by the real `ovon` parser: the command accepts what the cell is."""
    return parse_cli(cell.commands[-1], where)


def build_train_config(options: Any, where: str) -> Any:
    """The `TrainConfig` that `ovon train` builds from the same options (presets, --set and their validation)."""
    from ovon.train.config import build_config

    try:
        return build_config(options)
    except (ConfigError, KeyError, ValueError, TypeError) as e:
        msg = e.args[0] if isinstance(e, KeyError) and e.args else e
        raise DefinitionError(f"{where}: {msg}") from None


def _eval_cell(plan: Plan, name: str) -> None:
    cat, sc = plan.catalogue, plan.scale
    ec = cat.evaluate[name]
    where = f"cells.yaml:evaluate.{name}"
    if not ec.agent:
        raise DefinitionError(f"{where}.agent is missing; e.g. agent: policy")
    bad = [s for s in ec.splits if s not in VAL_SPLITS]
    if bad or not ec.splits or len(set(ec.splits)) != len(ec.splits):
        raise DefinitionError(
            f"{where}.splits = {list(ec.splits)}; expected distinct names among {', '.join(VAL_SPLITS)}"
        )
    per = _per_scale(ec, sc.name)
    folder = plan.base / "eval" / name
    deps = ["data:data"]
    checkpoint = ""
    if ec.checkpoint:
        ckpt = plan.cells[f"train:{ec.checkpoint}"]
        checkpoint = str(ckpt.folder / "policy.pt")
        deps.append(ckpt.id)
    ev = sc.evaluate
    values = {**flatten(ev.set), **flatten(ec.set), **flatten(per.set)}
    if ec.camera:
        values = {**camera_set(plan.cells[f"train:{ec.camera}"].train_cfg), **values}
    run = EvalRun(
        ec.agent,
        checkpoint,
        {**ec.agent_args, **per.agent_args},
        plan.episodes_dir,
        plan.scenes_dir,
        tuple(ec.splits),
        tuple(ev.seeds),
        ev.episodes,
        ec.noise,
        values,
        ev.workers,
        ev.executor,
        folder,
    )
    cell = Cell("eval", name, folder, run, tuple(deps), eval_cell=ec)
    _check_eval_args(check_command(cell, where), where)
    cell.unavailable = agent_unavailable(ec.agent)
    cell.total = ev.episodes * len(ec.splits) * len(ev.seeds) if ev.episodes is not None else None
    plan.cells[cell.id] = cell


def camera_set(train_cfg: Any) -> dict[str, Any]:
    """`--set sim.camera.*` giving an evaluation the camera a training cell saw (where it differs from the
    evaluation default), so agents compared in one table see the same images."""
    from ovon.evaluate.config import EvalConfig

    default = EvalConfig().sim.camera
    cam = train_cfg.sim.camera
    return {f"sim.camera.{k}": getattr(cam, k) for k in CAMERA_FIELDS if getattr(cam, k) != getattr(default, k)}


def _check_eval_args(args: Any, where: str) -> None:
    from ovon.evaluate.config import EvalConfig, apply_overrides, parse_noise

    try:
        parse_noise(args.noise)
        apply_overrides(EvalConfig(), args.set)
    except (ConfigError, ValueError, TypeError) as e:
        raise DefinitionError(f"{where}: {e}") from None


def agent_unavailable(agent: str) -> str:
    """ "" when `ovon evaluate --agent NAME` can load the agent here, else why not (one line)."""
    from ovon.agents import load_agent_class

    try:
        load_agent_class(agent)
    except (ValueError, ImportError) as e:
        return f"not available in this installation: {str(e).splitlines()[0]}"
    return ""


def check_experiment(exp: Experiment, plan: Plan) -> None:
    """Tables name existing splits of their cells, every entry has the paper's numbers, findings refer to
    table entries, figures to splits their cell evaluates."""
    from ovon.task.tracker import FAILURE_LABELS

    w = exp.source
    cells = plan.catalogue.evaluate
    if exp.table is None and not exp.figures:
        raise DefinitionError(f"{w}: an experiment needs a table or a figure")
    entries: set[tuple[str, str]] = set()
    if exp.table is not None:
        cols = {c.name: c for c in exp.table.columns}
        if len(cols) != len(exp.table.columns) or not cols:
            raise DefinitionError(f"{w}: table.columns must have distinct names")
        if len({r.name for r in exp.table.rows}) != len(exp.table.rows):
            raise DefinitionError(f"{w}: table.rows must have distinct names")
        for row in exp.table.rows:
            extra = (set(row.evals) | set(row.paper)) - set(cols)
            if extra:
                raise DefinitionError(
                    f"{w}: row {row.name!r} names unknown column(s) {sorted(extra)}; columns: {', '.join(cols)}"
                )
            for col in exp.table.columns:
                ev = row_eval(row, col.name)
                if not ev:
                    raise DefinitionError(f"{w}: row {row.name!r} has no evaluation cell for column {col.name!r}")
                if col.split not in cells[ev].splits:
                    raise DefinitionError(
                        f"{w}: row {row.name!r}, column {col.name!r} needs split {col.split!r}, "
                        f"which evaluation cell {ev!r} does not run (splits: "
                        f"{', '.join(cells[ev].splits)})"
                    )
                # a row without any paper numbers (an upper bound of ours) is allowed; a partial one is a typo
                if paper_numbers(row, col.name, f"{w}: row {row.name!r}") is None and row.paper:
                    raise DefinitionError(
                        f"{w}: row {row.name!r} has no paper numbers for column {col.name!r}; "
                        "fix: add paper.<column>: [SR, SR std, SPL, SPL std]"
                    )
                entries.add((row.name, col.name))
    for fig in exp.figures:
        missing = [s for s in fig.splits if s not in cells[fig.eval].splits]
        if missing:
            raise DefinitionError(f"{w}: figure {fig.name!r} needs split(s) {missing} of cell {fig.eval!r}")
        for g in fig.groups:
            bad = [lb for lb in g.labels if lb not in FAILURE_LABELS]
            if bad or not g.labels:
                raise DefinitionError(
                    f"{w}: figure {fig.name!r}, group {g.name!r}: labels {list(g.labels)}; "
                    f"expected some of {', '.join(FAILURE_LABELS)}"
                )
            if g.paper and len(g.paper) != len(fig.splits):
                raise DefinitionError(
                    f"{w}: figure {fig.name!r}, group {g.name!r}: paper has {len(g.paper)} "
                    f"values for {len(fig.splits)} splits"
                )
            if g.paper_range and len(g.paper_range) != 2:
                raise DefinitionError(f"{w}: figure {fig.name!r}, group {g.name!r}: paper_range is [lo, hi]")
    ids = set()
    for f in exp.findings:
        if not f.id or f.id in ids or not f.checks:
            raise DefinitionError(f"{w}: every finding needs a distinct id and at least one check ({f.id!r})")
        ids.add(f.id)
        for sc, why in f.differs.items():
            if sc not in plan.catalogue.scales or not str(why).strip():
                raise DefinitionError(
                    f"{w}: finding {f.id}: differs.{sc} = {why!r}; expected a scale of scales.yaml "
                    f"({', '.join(plan.catalogue.scales)}) -> one non-empty sentence"
                )
            for refs in sentence_refs(str(why), f"{w}: finding {f.id}: differs.{sc}"):
                for ref in refs:
                    if parse_ref(ref, w) not in entries:
                        raise DefinitionError(
                            f"{w}: finding {f.id}: differs.{sc} quotes {{{' - '.join(refs)}}}, but {ref!r} is not "
                            "a table entry; expected {ROW @ COLUMN} or {ROW @ COLUMN - ROW @ COLUMN} with a row "
                            "and a column of this experiment's table"
                        )
        for chk in f.checks:
            for ref in check_refs(chk):
                if parse_ref(ref, f"{w}: finding {f.id}") not in entries:
                    raise DefinitionError(
                        f"{w}: finding {f.id} refers to {ref!r}, which is not a table entry ('ROW @ COLUMN')"
                    )
            _check_shape(chk, f"{w}: finding {f.id}")


def check_refs(chk) -> list[str]:
    return [
        *([chk.target] if chk.target else []),
        *chk.others,
        *chk.refs,
        *(r for p in chk.pairs for r in p),
        *(r for p in chk.against for r in p),
    ]


def _check_shape(chk, where: str) -> None:
    need = {
        "best": ("target", "others"),
        "greater": ("pairs",),
        "flat": ("refs",),
        "drop": ("pairs",),
        "smaller_drop": ("pairs", "against"),
    }[chk.kind]
    missing = [k for k in need if not getattr(chk, k)]
    if missing:
        raise DefinitionError(f"{where}: a {chk.kind!r} check needs {', '.join(need)} (missing {', '.join(missing)})")
    if chk.margin and chk.kind != "greater":
        raise DefinitionError(f"{where}: margin = {chk.margin:g} on a {chk.kind!r} check; fix: margin is for 'greater'")
