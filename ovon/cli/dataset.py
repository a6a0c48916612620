"""`ovon dataset generate | splits | stats | validate`.

Each command's options are a dataclass with declared domains (`ovon.config.base`), built by `from_args`:
bad options are refused in one line before any scene is loaded."""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

from ovon.atomic import check_output_path
from ovon.config.base import (
    ExistingPath,
    OneOf,
    Pattern,
    constrained,
    domain_of,
    existing_dir,
    existing_file,
    from_args,
    in_range,
    non_empty,
    positive,
)
from ovon.dataset.io import HELD_OUT_SPLITS, SPLIT_NAME_PATTERN, VAL_SPLITS
from ovon.dataset.io import SPLITS as _SPLITS
from ovon.dataset.splits import SplitConfig

SPLIT_NAME = Pattern(SPLIT_NAME_PATTERN, "split folder names (letters, digits, _ . -)")


@dataclass(frozen=True)
class GenerateArgs:
    scenes: str = existing_dir(flag="--scenes")
    split: tuple[str, ...] = non_empty(_SPLITS, each=OneOf(_SPLITS), distinct=True, flag="--split")
    categories: str = existing_file("", optional=True, flag="--categories")
    config: str = existing_file("", optional=True, flag="--config")
    workers: int = in_range(1, 1, 1024, flag="--workers")
    executor: Literal["process", "ray"] = constrained("process", flag="--executor")


@dataclass(frozen=True)
class SplitsArgs:
    """The options of `ovon dataset splits`; the numbers share `SplitConfig`'s domains."""

    scenes: str = existing_dir("", optional=True, flag="--scenes")
    seed: int = constrained(0, domain_of(SplitConfig, "seed"), flag="--seed")
    threshold: float = constrained(0.68, domain_of(SplitConfig, "similarity_threshold"), flag="--threshold")
    holdout: float = constrained(0.25, domain_of(SplitConfig, "holdout_fraction"), flag="--holdout")
    out: str = non_empty("categories.json", flag="--out")


@dataclass(frozen=True)
class ValidateArgs:
    data: str = existing_dir(flag="DATA")
    scenes: str = existing_dir(flag="--scenes")
    split: tuple[str, ...] | None = non_empty(None, each=SPLIT_NAME, distinct=True, flag="--split")
    max_episodes_per_scene: int | None = positive(None, flag="--max-episodes-per-scene")


@dataclass(frozen=True)
class VerifyArgs:
    data: str = existing_dir(flag="DATA")
    scenes: str = existing_dir("", optional=True, flag="--scenes")


@dataclass(frozen=True)
class SubsetArgs:
    data: str = existing_dir(flag="DATA")
    size: int = in_range(360, 1, 10_000_000, flag="--size")
    name: str = constrained("", Pattern(r"([A-Za-z0-9][A-Za-z0-9_.-]*)?", "letters, digits, _ . -"), flag="--name")
    split: tuple[str, ...] = non_empty(VAL_SPLITS, each=SPLIT_NAME, distinct=True, flag="--split")
    out: str = non_empty("subset.json", flag="--out")


@dataclass(frozen=True)
class StatsArgs:
    data: str = constrained("", ExistingPath("dir"), flag="DATA")


def register(sub) -> None:
    p = sub.add_parser("dataset", help="HM3D-OVON episode datasets: generate, split, inspect, validate")
    dsub = p.add_subparsers(dest="dataset_command", required=True)

    g = dsub.add_parser("generate", help="generate episodes for a scene dataset folder (train/ and val/)")
    g.add_argument("--scenes", required=True, help="scene dataset folder holding train/ and val/")
    g.add_argument("--out", required=True, help="dataset folder to write (train/, val_seen/, ...)")
    g.add_argument(
        "--preset",
        choices=["paper", "fast"],
        default="fast",
        help="starting GenerationConfig values (paper: the paper's sizes)",
    )
    g.add_argument("--split", action="append", help="only these splits (repeatable); default all four")
    g.add_argument("--categories", help="an existing categories.json to reuse (from `ovon dataset splits`)")
    g.add_argument("--config", help="YAML with GenerationConfig fields")
    g.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="override, e.g. episodes_per_val_split=300 or viewpoints.render_size=128",
    )
    g.add_argument("--workers", default=min(2, os.cpu_count() or 1), help="worker processes")
    g.add_argument(
        "--executor", choices=["process", "ray"], default="process", help="run the workers as local processes or on ray"
    )
    g.add_argument("--no-progress", action="store_true", help="no progress bar")
    g.set_defaults(func=cmd_generate)

    s = dsub.add_parser("splits", help="category split by SentenceBERT similarity -> categories.json")
    s.add_argument("--scenes", help="scene dataset folder: split the categories annotated in it")
    s.add_argument("--vocabulary", action="store_true", help="split the whole embedded vocabulary instead")
    s.add_argument("--seed", default=0, help="seed of the held-out draw")
    s.add_argument(
        "--threshold", default=0.68, help="SentenceBERT cosine similarity above which a category counts as seen-like"
    )
    s.add_argument("--holdout", default=0.25, help="fraction of the categories held out as unseen")
    s.add_argument("--out", required=True, help="path of categories.json")
    s.set_defaults(func=cmd_splits)

    st = dsub.add_parser("stats", help="per-split numbers (Table 1/2 style)")
    st.add_argument("data", help="episode dataset root (holds train/, val_seen/, ...)")
    st.add_argument("--json", action="store_true", help="print JSON instead of tables")
    st.set_defaults(func=cmd_stats)

    v = dsub.add_parser("validate", help="schema + every start reachable within limits")
    v.add_argument("data", help="episode dataset root (holds train/, val_seen/, ...)")
    v.add_argument("--scenes", required=True, help="scene-datasets root the episodes refer to")
    v.add_argument("--split", action="append", help="only this split (repeatable); default: every split")
    v.add_argument("--max-episodes-per-scene", help="check at most this many episodes per scene (default: all)")
    v.set_defaults(func=cmd_validate)

    ve = dsub.add_parser("verify", help="inventory of a download: junk files, empty split files, name mix-ups, gaps")
    ve.add_argument("data", help="episode dataset root of the download")
    ve.add_argument("--scenes", help="scene-datasets root: also report scenes referenced but missing")
    ve.set_defaults(func=cmd_verify)

    su = dsub.add_parser("subset", help="a canonical episode subset chosen by content (the same for everyone)")
    su.add_argument("data", help="episode dataset root to draw the subset from")
    su.add_argument("--size", required=True, help="episodes per split")
    su.add_argument("--name", help="the subset's name (default: size<N>)")
    su.add_argument("--split", action="append", help="split to include (repeatable; default: the val splits)")
    su.add_argument("--out", required=True, help="JSON file for `ovon evaluate --subset FILE`")
    su.set_defaults(func=cmd_subset)


def cmd_generate(args) -> int:
    from ovon.config.dataset import generation_config
    from ovon.dataset.generate import generate

    a = from_args(GenerateArgs, args, split=tuple(args.split) if args.split else None)
    check_output_path(args.out, "--out", folder=True)  # "" would write the dataset into the current folder
    cfg = generation_config(args)
    # the category split that `generate` will read (given, or left in --out by an earlier run), checked first
    cat_path = Path(a.categories) if a.categories else Path(args.out) / "categories.json"
    if cat_path.is_file():
        check_generation_categories(cat_path, a.scenes, a.split)
    rep = generate(
        a.scenes,
        args.out,
        cfg,
        splits=a.split,
        workers=a.workers,
        executor=a.executor,
        progress=not args.no_progress,
        category_split_path=a.categories or None,
    )
    n = sum(rep.episodes.values())
    per_scene = rep.seconds / max(1, rep.scenes)
    print(f"new episodes per split: {json.dumps(rep.episodes)}")
    if rep.not_goal_reasons:
        print(f"objects that are not goals: {dict(rep.not_goal_reasons)}")
    if rep.rejections:
        print(f"start rejections: {dict(rep.rejections)}")
    print(
        f"{rep.scenes} scenes in {rep.seconds:.1f} s ({per_scene:.1f} s/scene"
        + (f", {1000 * rep.seconds / n:.1f} s per 1000 episodes" if n else "")
        + f"); dataset: {args.out}"
    )
    return 0


def check_generation_categories(path: Path, scenes: str, splits: tuple[str, ...]) -> None:
    """Refuse, before any scene is processed, a categories.json that cannot give the requested splits:
    its lists broken (`check_category_split`: overlapping, unknown or empty lists), or a split whose
    categories no scene of the kind it is generated on (train scenes for train, val scenes otherwise) has
    annotated. Why: generation used to run and then either write empty splits or blame the scenes ("repair
    those scenes") for a file made for other scenes. Cheap: semantic.txt files only, no mesh."""
    from ovon.dataset.generate import discover_scenes, scene_categories
    from ovon.dataset.records import DatasetError
    from ovon.dataset.splits import load_category_split

    cs = load_category_split(path, splits=splits)
    refs = discover_scenes(scenes)
    present: dict[str, set[str]] = {"train": set(), "val": set()}
    for ref in refs:
        present[ref.kind] |= scene_categories(ref)
    for split in splits:
        kind = "train" if split == "train" else "val"
        if not any(r.kind == kind for r in refs):
            continue  # `generate` names the missing scene folder
        cats = cs.categories(split)
        if not set(cats) & present[kind]:
            key = split if split in HELD_OUT_SPLITS else "train"
            shown = ", ".join(repr(c) for c in cats[:5]) + (f" and {len(cats) - 5} more" if len(cats) > 5 else "")
            raise DatasetError(
                f"{path}: none of its {len(cats)} {key} categories ({shown}) is annotated in a {kind} "
                f"scene of {scenes}, so the {split} split would get no episode; expected a "
                f"categories.json made for these scenes; fix: pass --categories with a file whose "
                f"{key} names categories of the {kind} scenes (`ovon dataset splits --scenes {scenes}`, "
                f"another --seed if needed), or leave --split {split} out"
            )


def cmd_splits(args) -> int:
    from ovon.config.base import ConfigError
    from ovon.dataset.splits import SplitConfig, empty_held_out_problem, split_categories

    a = from_args(SplitsArgs, args)
    if args.vocabulary == bool(a.scenes):
        raise ConfigError(
            "ovon dataset splits: give exactly one of --scenes DIR or --vocabulary; fix: e.g. "
            "ovon dataset splits --vocabulary --out categories.json"
        )
    check_output_path(
        a.out, "--out", expected="the path of categories.json", example="categories.json", error=ConfigError
    )
    if args.vocabulary:
        from ovon.scenes.vocabulary import load_vocabulary

        cats = load_vocabulary().names
    else:
        from ovon.dataset.generate import discover_scenes, scene_categories

        cats = sorted(set().union(*(scene_categories(r) for r in discover_scenes(a.scenes))))
    cs = split_categories(cats, SplitConfig(seed=a.seed, holdout_fraction=a.holdout, similarity_threshold=a.threshold))
    problem = empty_held_out_problem(cs, len(cats), a.holdout)
    if problem:  # a file with an empty held-out list gives a dataset that `dataset validate` rejects
        raise ConfigError(problem)
    cs.save(a.out)
    for name in HELD_OUT_SPLITS:
        rng = cs.similarity_range(name)
        print(
            f"{name}: {len(cs.categories(name))} categories"
            + (f", similarity [{rng[0]:.2f}, {rng[1]:.2f}]" if rng else "")
        )
    print(f"train: {len(cs.categories('train'))} categories; written {Path(a.out)}")
    return 0


def cmd_stats(args) -> int:
    from ovon.dataset.stats import dataset_stats, format_stats

    stats = dataset_stats(from_args(StatsArgs, args).data)
    print(json.dumps(stats, indent=2) if args.json else format_stats(stats))
    return 0


def cmd_validate(args) -> int:
    from ovon.dataset.validate import validate_dataset

    a = from_args(ValidateArgs, args, split=tuple(args.split) if args.split else None)
    rep = validate_dataset(
        a.data, a.scenes, list(a.split) if a.split else None, max_episodes_per_scene=a.max_episodes_per_scene
    )
    for e in rep.errors[:50]:
        print(f"  {e}")
    status = "OK" if rep.ok else f"{sum(rep.counts.values())} problem(s): {dict(rep.counts)}"
    print(f"validated {rep.episodes} episodes in {rep.shards} shards: {status}")
    return 0 if rep.ok else 1


def cmd_verify(args) -> int:
    from ovon.dataset.verify import verify_dataset

    a = from_args(VerifyArgs, args)
    rep = verify_dataset(a.data, a.scenes or None)
    print(rep.table(), end="")
    return 0 if rep.ok else 1


def cmd_subset(args) -> int:
    from ovon.dataset.subset import make_subset, write_subset

    a = from_args(SubsetArgs, args, split=tuple(args.split) if args.split else None)
    subset = make_subset(a.data, a.size, a.name, a.split)
    path = write_subset(subset, a.out)
    counts = ", ".join(f"{s} {len(v)}" for s, v in sorted(subset.splits.items()))
    print(f"subset {subset.name!r}: {counts} episodes (ids sha256 {subset.ids_sha256[:12]}); wrote {path}")
    return 0
