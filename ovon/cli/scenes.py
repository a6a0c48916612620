"""`ovon scenes ...`: generate procedural houses in the HM3D layout, inspect a scene, draw it from above,
list the vocabulary."""

from __future__ import annotations

import argparse
import json
import math
import os
import time
from dataclasses import MISSING, dataclass
from pathlib import Path

import numpy as np

from ovon.atomic import check_output_path
from ovon.config.base import ConfigError, from_args, in_range
from ovon.scenes.procedural.seeds import (  # noqa: F401  (house_seed and the constants are re-exported)
    MAX_DATASET_SEED,
    MAX_HOUSE_SEED,
    SEED_STRIDE,
    SPLIT_BASE,
    SPLIT_CAPACITY,
    house_seed,
)


@dataclass(frozen=True)
class GenerateArgs:
    """`ovon scenes generate`'s options through declared domains, checked before the split folder is made
    (`--count 100000000` used to fail in the loop, leaving an empty folder; `--count 0` wrote nothing and
    succeeded; `--workers 0` was silently 1). --count's upper bound depends on --split (`check_count`)."""

    count: int = in_range(MISSING, 1, None, flag="--count")  # required; at most SPLIT_CAPACITY[split]
    split: str = "train"
    seed: int = in_range(0, 0, MAX_DATASET_SEED, flag="--seed")
    workers: int | None = in_range(None, 1, 1024, flag="--workers")  # None: min(2, cpus)


def check_count(count: int, split: str) -> None:
    """A split holds at most SPLIT_CAPACITY[split] houses per dataset seed (the next indices would be
    the other split's or the next seed's houses): one line naming --count, before any work."""
    cap = SPLIT_CAPACITY[split]
    if count > cap:
        raise ConfigError(
            f"--count = {count}: --split {split} holds at most {cap} houses per --seed (more would "
            f"reuse the houses of another split or seed); expected an integer in [1, {cap}]; fix: pass "
            f"--count {cap} or less (and another --seed for more houses)"
        )


def _done_seeds(split_dir: Path) -> dict[int, str]:
    """Seeds already written under `split_dir` (the sidecar is written last, so its presence means done)."""
    done: dict[int, str] = {}
    if not split_dir.is_dir():
        return done
    for side in split_dir.glob("*/*.ovon.json"):
        try:
            meta = json.loads(side.read_text()).get("meta") or {}
        except (OSError, ValueError):
            continue
        stem = side.name[: -len(".ovon.json")]
        complete = all((side.parent / f"{stem}{s}").is_file() for s in (".glb", ".semantic.glb", ".semantic.txt"))
        if complete and "house_seed" in meta:
            done[int(meta["house_seed"])] = side.parent.name
    return done


def _generate_one(job: tuple[int, int, str, str]) -> tuple[int, int, str, int, float]:
    """Worker: generate one house and write it. Returns (index, seed, scene_id, n_objects, seconds)."""
    index, seed, split, split_dir = job
    from ovon.scenes.hm3dsem import write_scene
    from ovon.scenes.procedural import generate_house

    t0 = time.perf_counter()
    scene = generate_house(seed)
    if not scene.source:
        scene.source = f"procedural:{seed}"
    folder = Path(split_dir) / scene.scene_id
    side = folder / f"{scene.scene_id.split('-', 1)[-1]}.ovon.json"
    if side.is_file():
        other = (json.loads(side.read_text()).get("meta") or {}).get("house_seed")
        if other is not None and int(other) != seed:
            raise ValueError(
                f"scene id {scene.scene_id} of house seed {seed} collides with the one of seed {other} in {folder}"
            )
    meta = {"house_seed": seed, "split": split, "index": index}
    write_scene(scene, folder, meta=meta)
    return index, seed, scene.scene_id, len(scene.objects), time.perf_counter() - t0


def cmd_generate(args: argparse.Namespace) -> int:
    from rich.console import Console

    from ovon.parallel import progress_bar, run_jobs

    console = Console()
    a = from_args(GenerateArgs, args)
    check_count(a.count, a.split)
    check_output_path(args.out, "--out", folder=True)  # "" would scatter houses into the current folder
    split_dir = Path(args.out) / a.split
    split_dir.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    done = _done_seeds(split_dir)
    jobs = []
    for i in range(a.count):
        s = house_seed(a.seed, a.split, i)
        if s not in done:
            jobs.append((i, s, a.split, str(split_dir)))
    skipped = a.count - len(jobs)
    workers = a.workers if a.workers is not None else min(2, os.cpu_count() or 1)
    workers = min(workers, len(jobs) or 1)
    console.print(
        f"generating {len(jobs)} {a.split} houses into {split_dir} "
        f"({skipped} already there, {workers} worker{'s' if workers > 1 else ''})"
    )
    results = []
    with progress_bar(f"scenes/{a.split}", total=len(jobs)) as bar:
        for res in run_jobs(_generate_one, jobs, workers=workers):
            results.append(res)
            bar.advance(1)
    elapsed = time.perf_counter() - t0
    if results:
        per = np.mean([r[4] for r in results])
        n_obj = np.mean([r[3] for r in results])
        console.print(f"mean per house: {per:.2f} s, {n_obj:.0f} objects")
    console.print(f"done: {len(results)} written, {skipped} skipped, in {elapsed:.1f} s")
    return 0


def cmd_inspect(args: argparse.Namespace) -> int:
    from ovon.scenes.hm3dsem import load_scene
    from ovon.scenes.inspect import print_summary, summarize

    check_up_option(args.up)
    if str(args.path).lower().endswith(".navmesh"):
        return _inspect_navmesh(args)
    scene = load_scene(args.path, up=args.up)
    summary = summarize(scene)
    if args.nav:
        from ovon.config.dataset import StartConfig
        from ovon.sim.navsummary import navigation_summary

        summary["navigation"] = navigation_summary(scene, StartConfig().min_island_radius)
    if args.json:
        print(json.dumps(summary, indent=1))
    else:
        print_summary(summary)
    return 0


def _inspect_navmesh(args: argparse.Namespace) -> int:
    """`ovon scenes inspect X.navmesh`: habitat's navigable area and islands, and with --nav ovon's grids."""
    from rich.console import Console
    from rich.table import Table

    from ovon.sim.navmesh import navmesh_summary

    if args.up is not None:
        raise ValueError(f"{args.path}: a navmesh is in habitat's frame (y up) already; drop --up")
    s = navmesh_summary(args.path, grids=args.nav)
    if args.json:
        print(json.dumps(s, indent=1))
        return 0
    console = Console()
    over = Table(title=f"Navmesh {Path(args.path).name}", show_header=False)
    over.add_column("key", style="bold")
    over.add_column("value")
    over.add_row(
        "format",
        f"habitat navmesh version {s['version']}, {s['tiles']} tile(s), {s['polygons']} polygons "
        f"({s['walkable_polygons']} walkable)",
    )
    settings = s["settings"]
    over.add_row(
        "baked for",
        f"agent radius {s['agent_radius']:.3f} m"
        + (
            f", height {settings['agent_height']:.2f} m, max climb {settings['agent_max_climb']:.2f} m, max slope "
            f"{settings['agent_max_slope']:.0f} deg, cell {settings['cell_size']:.3f} m"
            if settings
            else " (version 1: no NavMeshSettings stored)"
        ),
    )
    over.add_row("bounds", f"{s['bounds_min']} .. {s['bounds_max']}")
    over.add_row("navigable area", f"{s['navigable_area_m2']:.3f} m² (3D area of the walkable detail triangles)")
    over.add_row("islands", str(s["num_islands"]))
    for g in s.get("grid", []):
        over.add_row(
            f"ovon grid floor {g['floor']}",
            f"{g['navigable_m2']:.2f} m² at y={g['height']:.2f} in "
            f"{g['islands']} islands ({g['cell_size']:.3f} m cells)",
        )
    console.print(over)
    isl = Table(title=f"Islands (largest first{', first 50' if s['num_islands'] > 50 else ''})")
    for col in ("island", "area m²", "radius m"):
        isl.add_column(col, justify="right")
    for i in s["islands"]:
        isl.add_row(str(i["island"]), f"{i['area_m2']:.3f}", f"{i['radius_m']:.3f}")
    console.print(isl)
    return 0


def cmd_render_topdown(args: argparse.Namespace) -> int:
    from ovon.scenes.hm3dsem import load_scene
    from ovon.scenes.topdown import render_topdown

    # checked before the scene is loaded and drawn
    check_output_path(args.out, "--out", expected="the path of a .png file", example="topdown.png")
    check_up_option(args.up)
    out = render_topdown(load_scene(args.path, up=args.up), args.out, floor=args.floor)
    print(f"wrote {out}")
    return 0


def cmd_list(args: argparse.Namespace) -> int:
    from ovon.scenes.hm3dsem import list_scenes

    for p in list_scenes(args.dataset_dir, args.split):
        print(p)
    return 0


def cmd_vocabulary(args: argparse.Namespace) -> int:
    from rich.console import Console
    from rich.table import Table

    from ovon.scenes.vocabulary import hm3dsem_counts, label_coverage, load_vocabulary

    vocab = load_vocabulary()
    console = Console()
    if args.coverage:
        cov = label_coverage(vocab.label_map, hm3dsem_counts())
        if args.json:
            print(json.dumps(cov, indent=1))
            return 0
        t = Table(
            title=f"HM3DSem v0.2 labels through ovon's cleaning ({cov['instances']:,} instances, "
            f"{cov['labels']:,} raw labels)"
        )
        for col in ("outcome", "instances", "share", "labels", "largest labels"):
            t.add_column(col, justify="left" if col in ("outcome", "largest labels") else "right")
        for k, n in cov["instances_by_outcome"].items():
            top = ", ".join(f"{r} ({c})" for r, c in cov["top_labels"][k][:6])
            t.add_row(k, f"{n:,}", f"{100 * cov['share_by_outcome'][k]:.1f}%", str(cov["labels_by_outcome"][k]), top)
        console.print(t)
        console.print(
            f"mapped instances fall in {cov['categories']} of the {len(vocab)} vocabulary categories; "
            "only mapped labels become goal categories"
        )
        return 0
    table = Table(title="Vocabulary")
    for col in ("name", "family", "placement", "HM3DSem n", "raw labels"):
        table.add_column(col)
    for name in vocab.names:
        c = vocab[name]
        table.add_row(
            c.name, c.family, c.placement, str(c.hm3dsem_instances), ", ".join(r for r in c.raw_labels if r != c.name)
        )
    console.print(table)
    console.print(f"{len(vocab)} categories, {len({c.family for c in vocab.categories.values()})} shape families")
    return 0


def check_up_option(up: str | None, scene: str | None = None) -> None:
    """Refuse a bad `--up` before the scene is loaded, one line naming it (`scenes inspect`,
    `render-topdown`, `sim view`). Why here: the scene loaders read --up only for scans and bare meshes,
    so `--up q` was ignored for a procedural house while a glb refused it, and `--up 0,0,0` was refused as
    "expected three numbers" although it is three. A procedural house (`scene` = procedural:<seed>) is
    built y-up: any --up for it is refused (as for a scene written by ovon), never silently ignored."""
    if up is None:
        return
    from ovon.scenes.hm3dsem.upaxis import AXES, parse_up

    axes = ", ".join(AXES)
    expected = f"one of {axes} or three numbers x,y,z (a non-zero vector)"
    t = up.strip().lower()
    if not t:
        raise ConfigError(
            f"--up {up!r} is empty; expected {expected}; fix: e.g. --up z, or leave --up out (the "
            "habitat config's up axis, else y)"
        )
    parts = t.split(",")
    if t not in AXES and len(parts) == 3:
        try:
            v = [float(x) for x in parts]
        except ValueError:
            v = []
        if v and not all(math.isfinite(x) for x in v):
            raise ConfigError(f"--up {up!r}: expected three finite numbers x,y,z; fix: e.g. --up 0,0,1")
        if v and math.hypot(*v) < 1e-9:
            raise ConfigError(
                f"--up {up!r} is the zero vector, which points nowhere; expected three numbers x,y,z "
                "not all zero (the scene's up direction); fix: e.g. --up 0,0,1 for a z-up scan"
            )
    try:
        parse_up(up)
    except ValueError:
        raise ConfigError(f"--up {up!r}: expected {expected}; fix: e.g. --up z for a z-up scan") from None
    if scene is not None and str(scene).startswith("procedural:"):
        raise ConfigError(
            f"--up {up}: procedural houses ({scene}) are built y-up already, --up would be ignored; fix: drop --up"
        )


def add_up_argument(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--up",
        default=None,
        metavar="AXIS",
        help="up axis of a scan / bare mesh: y, z, -z, x, ... or x,y,z (default: the habitat "
        "stage/scene-dataset config, else y)",
    )


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("scenes", help="generate, inspect and draw scenes")
    sub = p.add_subparsers(dest="scenes_command", required=True)

    g = sub.add_parser("generate", help="write procedural houses in the HM3D layout DIR/<split>/<NNNNN-id>/")
    g.add_argument("--split", choices=sorted(SPLIT_BASE), default="train", help="which split to write")
    g.add_argument(
        "--count",
        required=True,
        help=f"number of houses in the split (1 to {SPLIT_CAPACITY['train']} train, {SPLIT_CAPACITY['val']} val)",
    )
    g.add_argument("--seed", default=0, help=f"dataset seed (0 to {MAX_DATASET_SEED}); house seeds derive from it")
    g.add_argument("--out", required=True, help="dataset folder (DATASET_DIR)")
    g.add_argument("--workers", default=None, help="worker processes (default: min(2, cpus))")
    g.set_defaults(func=cmd_generate)

    i = sub.add_parser(
        "inspect",
        help="print a summary of one scene (folder or any of its files) or of a habitat "
        "navmesh (X.navmesh: navigable area and islands as habitat computes them)",
    )
    i.add_argument("path", help="scene folder, one of its files, or an X.navmesh")
    i.add_argument("--json", action="store_true", help="print the summary as JSON")
    i.add_argument(
        "--nav",
        action="store_true",
        help="also build navigability: area, islands per floor (from the "
        "navmesh beside the mesh when there is one, see sim.nav.source)",
    )
    add_up_argument(i)
    i.set_defaults(func=cmd_inspect)

    r = sub.add_parser("render-topdown", help="draw one scene from above (one panel per floor)")
    r.add_argument("path", help="scene folder or one of its files")
    r.add_argument("--out", required=True, help="PNG file to write")
    r.add_argument("--floor", type=int, default=None, help="only this floor index")
    add_up_argument(r)
    r.set_defaults(func=cmd_render_topdown)

    ls = sub.add_parser("list", help="list the scene folders of a dataset tree")
    ls.add_argument("dataset_dir", help="scene dataset folder (holds train/, val/)")
    ls.add_argument("--split", default=None, help="only this split (default: every split)")
    ls.set_defaults(func=cmd_list)

    v = sub.add_parser("vocabulary", help="print the categories (name, family, placement, HM3DSem count)")
    v.add_argument(
        "--coverage",
        action="store_true",
        help="share of HM3DSem v0.2 instances mapped / structural / free text / unmapped",
    )
    v.add_argument("--json", action="store_true", help="with --coverage: print it as JSON")
    v.set_defaults(func=cmd_vocabulary)
