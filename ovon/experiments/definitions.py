"""Experiment definitions: the paper's artefacts as data (YAML files in `ovon/experiments/defs/`).

Why data: a user re-runs a table, then changes one thing (a budget, a split, an agent argument) in a
file instead of in code, and a cell shared by two tables (the DAgger run of `main` and of `memory`) is
one run folder trained once because both tables name the same cell. Four kinds of records, each a
typed dataclass loaded with `ovon.config.base.from_dict` (an unknown key fails with the valid ones):

- scales (`scales.yaml`): where the data comes from, how training is launched, evaluation defaults;
- recipes (`recipes.yaml`): a training algorithm and, per scale, its `ovon train --preset` + `--set`;
- cells (`cells.yaml`): training cells (recipe, expert, policy core, init) and evaluation cells (agent,
  checkpoint, agent arguments, noise, splits), shared by every experiment;
- experiments (`<name>.yaml`): one per paper artefact: a table of evaluation cells with the paper's
  numbers beside each, figures, and the paper's findings as checkable rules.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from ovon.config.base import ConfigError, from_dict, load_yaml, values_from_file
from ovon.dataset.io import VAL_SPLITS

DEFS_DIR = Path(__file__).parent / "defs"
CATALOGUE_FILES = ("scales.yaml", "recipes.yaml", "cells.yaml")
METRICS = ("sr", "spl")


class DefinitionError(ConfigError):
    """An experiment definition is wrong; the message names the file, the key and the fix."""


# ----- scales ----------------------------------------------------------------------------------------
@dataclass(frozen=True)
class DataSpec:
    """`generate`: procedural scenes + episodes made by `ovon scenes generate` / `ovon dataset generate`
    under the run root; `paths`: an existing HM3D-OVON episode dataset and its scenes (paper scale)."""

    source: Literal["generate", "paths"] = "generate"
    train_scenes: int = 24
    val_scenes: int = 4
    seed: int = 0
    preset: Literal["fast", "paper"] = "fast"  # `ovon dataset generate --preset`
    set: dict = field(default_factory=dict)  # `ovon dataset generate --set` (GenerationConfig keys)
    workers: int = 2
    episodes: str = ""  # paths: episode dataset root (holds train/, val_seen/, ...)
    scenes: str = ""  # paths: scene-datasets root


@dataclass(frozen=True)
class LaunchSpec:
    """How `ovon train` is started: one process (`nproc_per_node: 0`) or `torchrun`."""

    nproc_per_node: int = 0
    torchrun_args: tuple[str, ...] = ("--standalone",)
    # `ovon train --set` for every training cell of the scale, under the recipe's and the cell's own (the
    # scale's perception, e.g. encoder.image: world-vl): one place instead of a copy in every recipe
    set: dict = field(default_factory=dict)


@dataclass(frozen=True)
class EvalDefaults:
    episodes: int | None = 100  # per split; None = every episode of the split
    seeds: tuple[int, ...] = (0, 1)
    workers: int = 2
    executor: Literal["process", "ray"] = "process"
    set: dict = field(default_factory=dict)  # `ovon evaluate --set` for every evaluation (sim.* / task.*)


@dataclass(frozen=True)
class Scale:
    name: str = ""
    description: str = ""
    data: DataSpec = field(default_factory=DataSpec)
    train: LaunchSpec = field(default_factory=LaunchSpec)
    evaluate: EvalDefaults = field(default_factory=EvalDefaults)


# ----- recipes and cells -----------------------------------------------------------------------------
@dataclass(frozen=True)
class RecipeScale:
    preset: str = ""  # `ovon train --preset`
    set: dict = field(default_factory=dict)  # `ovon train --set`: budgets and hyperparameters


@dataclass(frozen=True)
class Recipe:
    algo: Literal["bc", "dagger", "ppo"] = "dagger"
    description: str = ""
    scales: dict = field(default_factory=dict)  # scale name -> RecipeScale


@dataclass(frozen=True)
class TrainCell:
    recipe: str = ""
    description: str = ""
    expert: Literal["", "frontier", "shortest-path"] = ""  # "" = the preset's (frontier)
    policy: Literal["", "transformer", "lstm"] = ""  # "" = the preset's, or the init's when fine-tuning
    init: str = ""  # training cell to start from (BC->RL, DAgger->RL)
    set: dict = field(default_factory=dict)
    scales: dict = field(default_factory=dict)  # scale name -> {set: {...}}


@dataclass(frozen=True)
class EvalCell:
    agent: str = ""
    description: str = ""
    checkpoint: str = ""  # training cell whose policy.pt the agent gets (--checkpoint)
    camera: str = ""  # training cell whose camera the evaluation uses (default: the checkpoint's own)
    agent_args: dict = field(default_factory=dict)  # --agent-arg key=value
    noise: str = ""  # --noise, e.g. actuation,odometry
    splits: tuple[str, ...] = VAL_SPLITS
    set: dict = field(default_factory=dict)  # --set sim.* / task.*
    scales: dict = field(default_factory=dict)  # scale name -> {agent_args: {...}, set: {...}}


@dataclass(frozen=True)
class CellScale:
    """Per-scale additions of a cell (merged over its own values)."""

    set: dict = field(default_factory=dict)
    agent_args: dict = field(default_factory=dict)
    # training cells only: another recipe, or another init ("none" = train from scratch), at this scale
    recipe: str = ""
    init: str = ""


# ----- experiments -----------------------------------------------------------------------------------
@dataclass(frozen=True)
class Column:
    name: str = ""
    split: str = "val_seen"


@dataclass(frozen=True)
class Row:
    """A table row: `eval` for every column, or `evals` per column; `paper` per column as
    [SR, SR std, SPL, SPL std] in % as printed (std null where the paper prints none)."""

    name: str = ""
    eval: str = ""
    evals: dict = field(default_factory=dict)
    paper: dict = field(default_factory=dict)


@dataclass(frozen=True)
class Table:
    caption: str = ""
    columns: tuple[Column, ...] = ()
    rows: tuple[Row, ...] = ()


@dataclass(frozen=True)
class FailureGroup:
    """A bar of the failure figure: the share of all episodes ending with any of `labels`."""

    name: str = ""
    color: str = "#7f7f7f"
    labels: tuple[str, ...] = ()
    paper: tuple[float, ...] = ()  # % per split of the figure, as stated in the paper's text
    paper_range: tuple[float, ...] = ()  # (lo, hi) where the text gives only a range over the splits


@dataclass(frozen=True)
class FailureFigure:
    name: str = ""
    caption: str = ""
    eval: str = ""
    splits: tuple[str, ...] = VAL_SPLITS
    groups: tuple[FailureGroup, ...] = ()


CheckKind = Literal["best", "greater", "flat", "drop", "smaller_drop"]


@dataclass(frozen=True)
class Check:
    """One rule over table entries ("ROW @ COLUMN"), on the mean over seeds of `metric` (%).

    best: `target` > every entry of `others`; greater: a > b for every pair; flat: max - min of `refs`
    <= `tolerance`; drop: a - b >= `tolerance` for every pair; smaller_drop: the mean drop a - b over
    `pairs` is smaller than the mean drop over `against`."""

    kind: CheckKind = "greater"
    metric: Literal["sr", "spl"] = "sr"
    target: str = ""
    others: tuple[str, ...] = ()
    pairs: tuple[tuple[str, str], ...] = ()
    against: tuple[tuple[str, str], ...] = ()
    refs: tuple[str, ...] = ()
    tolerance: float = 0.0
    margin: float = 0.0  # greater: a - b > margin (0: a > b)


@dataclass(frozen=True)
class Finding:
    id: str = ""
    claim: str = ""
    checks: tuple[Check, ...] = ()
    note: str = ""
    # scale -> one sentence: why our verdict there differs from the paper's. Written after a run has shown
    # it (it interprets a result); the report prints it only while the two verdicts differ.
    differs: dict[str, str] = field(default_factory=dict)


@dataclass(frozen=True)
class Experiment:
    name: str = ""
    title: str = ""
    paper_ref: str = ""
    description: str = ""
    table: Table | None = None
    figures: tuple[FailureFigure, ...] = ()
    findings: tuple[Finding, ...] = ()
    train: dict = field(default_factory=dict)  # extra training cells of this experiment (name -> TrainCell)
    evaluate: dict = field(default_factory=dict)  # extra evaluation cells (name -> EvalCell)
    source: str = ""  # the file it was read from


@dataclass(frozen=True)
class Catalogue:
    """Everything the experiments share: scales, recipes, and the cells by name."""

    scales: dict[str, Scale]
    recipes: dict[str, Recipe]
    train: dict[str, TrainCell]
    evaluate: dict[str, EvalCell]


# ----- loading ---------------------------------------------------------------------------------------
def _typed(cls: type, data: Any, where: str) -> Any:
    """`data` as `cls`; `where` is "FILE" or "FILE:KEY". A bad value's fix says where to edit the file
    (`values_from_file`): a definition's keys cannot be given with --set."""
    if not isinstance(data, dict):
        raise DefinitionError(f"{where}: expected a mapping of {cls.__name__} fields, got {data!r}")
    file = where.split(":")[0]
    try:
        with values_from_file(file):
            return from_dict(cls, data, where)
    except DefinitionError:
        raise
    except (ConfigError, TypeError, ValueError) as e:
        msg = " ".join(str(e).split())
        raise DefinitionError(msg if "fix:" in msg else f"{msg}; fix: edit {file}") from None


def _named(cls: type, data: Any, where: str) -> dict[str, Any]:
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise DefinitionError(f"{where}: expected a mapping name -> {cls.__name__}, got {type(data).__name__}")
    return {str(k): _typed(cls, v, f"{where}.{k}") for k, v in data.items()}


def _read(path: Path) -> dict:
    if path.is_dir():  # not "does not exist": it does, as a folder
        raise DefinitionError(
            f"{path} is a folder, not a YAML file; fix: pass the path of a .yaml file, e.g. {path / 'NAME.yaml'}"
        )
    try:
        return load_yaml(path)
    except ConfigError as e:
        raise DefinitionError(str(e)) from None


def _per_scale(cls: type, data: dict, where: str) -> dict:
    return {str(s): _typed(cls, v or {}, f"{where}.scales.{s}") for s, v in data.items()}


def load_catalogue(defs_dir: Path = DEFS_DIR) -> Catalogue:
    """Scales, recipes and cells from `defs_dir` (the package's own definitions by default)."""
    scales_raw = _read(defs_dir / "scales.yaml")
    scales = {n: dataclasses.replace(s, name=n) for n, s in _named(Scale, scales_raw, "scales.yaml").items()}
    recipes = {}
    for name, r in _named(Recipe, _read(defs_dir / "recipes.yaml"), "recipes.yaml").items():
        recipes[name] = dataclasses.replace(r, scales=_per_scale(RecipeScale, r.scales, f"recipes.yaml:{name}"))
    cells_raw = _read(defs_dir / "cells.yaml")
    unknown = set(cells_raw) - {"anchors", "train", "evaluate"}
    if unknown:
        raise DefinitionError(
            f"cells.yaml: unknown top-level key(s) {sorted(unknown)}; valid: anchors, train, evaluate"
        )
    train, evaluate = _cells(cells_raw, "cells.yaml")
    return Catalogue(scales, recipes, train, evaluate)


def _cells(raw: dict, where: str) -> tuple[dict[str, TrainCell], dict[str, EvalCell]]:
    train = {
        n: dataclasses.replace(c, scales=_per_scale(CellScale, c.scales, f"{where}:train.{n}"))
        for n, c in _named(TrainCell, raw.get("train"), f"{where}:train").items()
    }
    evaluate = {
        n: dataclasses.replace(c, scales=_per_scale(CellScale, c.scales, f"{where}:evaluate.{n}"))
        for n, c in _named(EvalCell, raw.get("evaluate"), f"{where}:evaluate").items()
    }
    return train, evaluate


def experiment_names(defs_dir: Path = DEFS_DIR) -> list[str]:
    """The built-in experiments (every definition file that is not part of the catalogue)."""
    return sorted(p.stem for p in defs_dir.glob("*.yaml") if p.name not in CATALOGUE_FILES)


def load_experiment(name_or_path: str, defs_dir: Path = DEFS_DIR) -> Experiment:
    """A built-in experiment by name, or an experiment YAML file by path."""
    path = Path(name_or_path)
    if path.suffix not in (".yaml", ".yml"):
        path = defs_dir / f"{name_or_path}.yaml"
        if name_or_path in [p.removesuffix(".yaml") for p in CATALOGUE_FILES] or not path.is_file():
            raise DefinitionError(
                f"unknown experiment {name_or_path!r}; valid: {', '.join(experiment_names(defs_dir))}"
                " or the path of an experiment .yaml file"
            )
    raw = _read(path)
    where = str(path if path.parent != defs_dir else path.name)
    exp = _typed(Experiment, {k: v for k, v in raw.items() if k not in ("train", "evaluate", "anchors")}, where)
    train, evaluate = _cells(raw, where)
    return dataclasses.replace(exp, name=exp.name or path.stem, train=train, evaluate=evaluate, source=where)


def merged_catalogue(experiments: list[Experiment], base: Catalogue) -> Catalogue:
    """The catalogue plus the cells the experiments define themselves; one name, one definition."""
    train, evaluate = dict(base.train), dict(base.evaluate)
    for exp in experiments:
        for kind, own, into in (("train", exp.train, train), ("evaluate", exp.evaluate, evaluate)):
            for name, cell in own.items():
                if name in into and into[name] != cell:
                    raise DefinitionError(
                        f"{exp.source}: {kind} cell {name!r} is already defined differently "
                        f"(cells.yaml or another experiment); fix: give it another name"
                    )
                into[name] = cell
    return dataclasses.replace(base, train=train, evaluate=evaluate)


def parse_ref(ref: str, where: str) -> tuple[str, str]:
    """ "ROW @ COLUMN" -> (row, column)."""
    row, sep, col = ref.partition("@")
    if not sep or not row.strip() or not col.strip():
        raise DefinitionError(f"{where}: reference {ref!r} is not 'ROW @ COLUMN' (e.g. 'DAgRL @ val_seen')")
    return row.strip(), col.strip()


def paper_numbers(row: Row, column: str, where: str) -> dict[str, float | None] | None:
    """The paper's {sr, sr_std, spl, spl_std} (%) of a table entry, None when the paper has none."""
    value = row.paper.get(column)
    if value is None:
        return None
    if not isinstance(value, list | tuple) or len(value) != 4:
        raise DefinitionError(
            f"{where}: paper.{column} = {value!r} is not [SR, SR std, SPL, SPL std] (std may be null)"
        )
    try:
        sr, sr_std, spl, spl_std = (None if v is None else float(v) for v in value)
    except (TypeError, ValueError):
        raise DefinitionError(f"{where}: paper.{column} = {value!r} holds a value that is not a number") from None
    if sr is None or spl is None:
        raise DefinitionError(f"{where}: paper.{column} = {value!r}: SR and SPL must be numbers")
    return {"sr": sr, "sr_std": sr_std, "spl": spl, "spl_std": spl_std}


def row_eval(row: Row, column: str) -> str:
    """The evaluation cell of a table entry."""
    return str(row.evals.get(column, row.eval))
