"""Where an agent's failed episodes end, per failure label: distance to the success region and to the goal.

Usage: python benchmarks/vlfm_stops.py RUN [RUN ...] [--out benchmarks/results/vlfm_stops.json]

RUN is a folder written by `ovon evaluate` (`episodes.jsonl` + `run.json`), optionally named `NAME=FOLDER`
(e.g. `before=runs/vlfm_old after=runs/vlfm`); the first run is the baseline the others are compared with.
Per run: SR / SPL per split, and per failure label the number of episodes and, over them,

- `to_region`: the geodesic distance to the nearest goal viewpoint minus the success distance (how far
  outside the success region the episode ended; the record's `distance_to_goal` is the geodesic part),
- `to_object`: the floor distance to the nearest goal object's box footprint (`distance_to_object`),
- `goal_in_view`: the share of episodes whose last frame shows a goal instance (the task's seen threshold),

as median / mean / 90th percentile, plus a histogram of `to_region` (0-0.25, 0.25-0.5, 0.5-1, 1-2, > 2 m).
Records from before `distance_to_object` / `goal_in_view` existed report those as null.

`--replay [NAME,...]` (modular agents: vlfm, dagrl-od; the named runs, all when bare; the agent code must be
the one that made the run) also replays every failed STOP through a fresh agent built from the run's
settings (its actions are checked against the record) and reports, at the STOP, what it believed against
the truth: `rho`, its planar distance to its goal point (the stop rule: < the stop distance); where that
goal point lies (floor distance to the nearest episode-goal box, and to the nearest box of any instance of
the goal categories, goal or not: the dataset makes no goal of an instance without viewpoints, a detector
still sees it); and the lifting error, the share of its lifted goal points more than 0.1 m from every box
of the goal categories. `cause` sums it up per episode: `near_miss` (the goal point is on an episode goal and
the stop rule fired), `settled` (on an episode goal, stopped within one step of the radius, unable to get
closer), `off_goal_instance` (the goal point is on a goal-category instance that is not an episode goal),
`off_category` (on no instance of the goal categories: a lifting error or a false detection),
`stopped_<mode>` (a goal point it could not reach, then no frontier left or off its map) or
`nothing_detected` (no goal point: no frontier left or off the map).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections import defaultdict
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ovon.atomic import atomic_write_text  # noqa: E402
from ovon.dataset.io import VAL_SPLITS as SPLIT_ORDER  # noqa: E402
from ovon.evaluate.results import read_records  # noqa: E402
from ovon.task.tracker import FAILURE_LABELS  # noqa: E402

BINS = (0.25, 0.5, 1.0, 2.0)  # to_region histogram edges (m)


def stats(values: list[float]) -> dict | None:
    if not values:
        return None
    a = np.asarray(values, dtype=np.float64)
    return {
        "median": float(np.median(a)),
        "mean": float(a.mean()),
        "p90": float(np.percentile(a, 90)),
        "min": float(a.min()),
        "max": float(a.max()),
    }


def histogram(values: list[float]) -> dict[str, int]:
    edges = (-np.inf, *BINS, np.inf)
    names = [f"<={BINS[0]}"] + [f"{a}-{b}" for a, b in zip(BINS[:-1], BINS[1:], strict=True)] + [f">{BINS[-1]}"]
    counts, _ = np.histogram(np.asarray(values, dtype=np.float64), bins=edges)
    return dict(zip(names, (int(c) for c in counts), strict=True))


def analyse(run: Path) -> dict:
    meta_path = run / "run.json"
    if not meta_path.is_file():
        raise SystemExit(f"vlfm_stops: error: {run} has no run.json; pass a folder written by `ovon evaluate`")
    meta = json.loads(meta_path.read_text())
    success_distance = float(meta.get("task", {}).get("success_distance", 0.25))
    records = read_records(run)
    if not records:
        raise SystemExit(f"vlfm_stops: error: {run}/episodes.jsonl holds no records; run `ovon evaluate` first")
    splits: dict[str, dict] = {}
    by_split: dict[str, list[dict]] = defaultdict(list)
    for r in records:
        by_split[r["split"]].append(r)
    for s in sorted(by_split, key=lambda s: (SPLIT_ORDER.index(s) if s in SPLIT_ORDER else 99, s)):
        rs = by_split[s]
        splits[s] = {
            "episodes": len(rs),
            "sr": 100.0 * float(np.mean([r["success"] for r in rs])),
            "spl": 100.0 * float(np.mean([r["spl"] for r in rs])),
        }
    labels: dict[str, dict] = {}
    for label in FAILURE_LABELS:
        rs = [r for r in records if r.get("failure") == label]
        if not rs:
            continue
        region = [float(r["distance_to_goal"]) - success_distance for r in rs]
        obj = [float(r["distance_to_object"]) for r in rs if r.get("distance_to_object") is not None]
        view = [bool(r["goal_in_view"]) for r in rs if "goal_in_view" in r]
        labels[label] = {
            "episodes": len(rs),
            "to_region_m": stats(region),
            "to_region_histogram": histogram(region),
            "to_object_m": stats(obj),
            "goal_in_view": float(np.mean(view)) if view else None,
            "steps_mean": float(np.mean([r["steps"] for r in rs])),
        }
    stops = [
        float(r["distance_to_goal"]) - success_distance
        for r in records
        if not r["success"] and str(r.get("failure")).startswith("stop_")
    ]
    return {
        "run": str(run),
        "agent": meta.get("name") or meta.get("agent"),
        "agent_kwargs": meta.get("agent_kwargs", {}),
        "camera": {k: meta.get("sim", {}).get("camera", {}).get(k) for k in ("width", "height", "hfov_deg")},
        "success_distance": success_distance,
        "episodes": len(records),
        "sr": 100.0 * float(np.mean([r["success"] for r in records])),
        "spl": 100.0 * float(np.mean([r["spl"] for r in records])),
        "splits": splits,
        "failures": labels,
        "failed_stops": len(stops),
        "failed_stops_within_0.5m_of_region": sum(d <= 0.5 for d in stops),
    }


def to_world(start: tuple[float, float, float], x: np.ndarray, z: np.ndarray) -> np.ndarray:
    """Episodic (x, z) (the agent's frame: the start pose at the origin, yaw 0) -> world (x, z), (N, 2)."""
    x0, z0, y0 = start
    c, s = math.cos(y0), math.sin(y0)
    return np.stack([x0 + x * c + z * s, z0 - x * s + z * c], axis=1)


def nearest(objs: list, xz: np.ndarray) -> np.ndarray:
    """Floor distance of each point to the nearest object's oriented box footprint (inf without objects)."""
    from ovon.scenes.model import footprint_distance

    if not objs or len(xz) == 0:
        return np.full(len(xz), np.inf)
    return np.min([footprint_distance(o, xz) for o in objs], axis=0)


def stop_cause(row: dict, stop_distance: float) -> str:
    """Why a replayed agent STOPped where it did (see the module docstring)."""
    if row["rho"] is None:
        return "nothing_detected"
    if row["mode"] not in (None, "navigate"):
        return f"stopped_{row['mode']}"  # a goal point it could not reach on its map, then no frontier left
    if row["goal_point_to_goal_m"] > 0.1:
        return "off_goal_instance" if row["goal_point_to_category_m"] <= 0.1 else "off_category"
    return "near_miss" if row["rho"] < stop_distance else "settled"


def replay_stops(run: Path) -> dict:
    """Beliefs at the STOP of every failed STOP episode of a modular agent's run (see the docstring)."""
    from ovon.agents import make_agent
    from ovon.agents.base import is_privileged
    from ovon.config.base import from_dict
    from ovon.config.sim import SimConfig
    from ovon.config.task import TaskConfig
    from ovon.dataset.episodes import load_specs
    from ovon.env import make_objectnav
    from ovon.evaluate.runner import episode_info, episode_seed

    meta = json.loads((run / "run.json").read_text())
    sim, task = from_dict(SimConfig, meta["sim"]), from_dict(TaskConfig, meta["task"])
    agent = make_agent(meta["agent"], **meta.get("agent_kwargs", {}))
    if not hasattr(agent, "core"):
        raise SystemExit(
            f"vlfm_stops: error: --replay needs a modular agent (vlfm, dagrl-od); {run} ran {meta['agent']}"
        )
    stop_distance = agent.core.cfg.navigator.stop_distance_m
    failed = [r for r in read_records(run) if not r["success"] and str(r.get("failure")).startswith("stop_")]
    specs = {}
    for split in sorted({r["split"] for r in failed}):
        for s in load_specs(meta["data"], meta["scenes"], split, None):
            specs[(split, s.scene_key, s.episode_id)] = s
    out = []
    for rec in failed:
        spec = specs[(rec["split"], rec["scene"], str(rec["episode_id"]))]
        ep_seed = episode_seed(rec["seed"], spec.split, spec.episode_id, spec.scene_key)
        env = make_objectnav(episodes=[spec], sim=sim, task=task, privileged=True)
        obs, info = env.reset(seed=ep_seed, options={"episode": spec})
        agent.reset(episode_info(spec, ep_seed, sim))
        p = info["privileged"]
        start = (float(p.state.position[0]), float(p.state.position[2]), float(p.state.yaw))
        cats = set(spec.goal_categories)
        goal_objs = [o for o in p.world.scene.objects if o.id in p.goal_ids]
        cat_objs = [o for o in p.world.scene.objects if o.category in cats]
        same = True
        for a in rec["actions"]:
            if is_privileged(agent):
                obs = {**obs, "privileged": info["privileged"]}
            same = same and int(agent.act(obs)) == int(a)
            obs, _, term, trunc, info = env.step(a)
            if term or trunc:
                break
        env.close()

        core = agent.core
        goal = core.goal_point()
        row = {
            "split": rec["split"],
            "scene": Path(rec["scene"]).parent.name,
            "episode_id": rec["episode_id"],
            "category": rec["category"],
            "failure": rec["failure"],
            "replay_matches": same,
            "mode": getattr(agent, "mode", None),
            "rho": None,
            "goal_point_to_goal_m": None,
            "goal_point_to_category_m": None,
            "lifted_off_category": None,
        }
        pts = core.memory.points
        if goal is not None and len(pts):
            g = to_world(start, np.array([goal[0]]), np.array([goal[1]]))
            off = nearest(cat_objs, to_world(start, pts[:, 0].astype(np.float64), pts[:, 2].astype(np.float64))) > 0.1
            row.update(
                rho=math.hypot(goal[0] - core.pose.x, goal[1] - core.pose.z),
                goal_point_to_goal_m=float(nearest(goal_objs, g)[0]),
                goal_point_to_category_m=float(nearest(cat_objs, g)[0]),
                lifted_off_category=float(off.mean()),
            )
        row["cause"] = stop_cause(row, stop_distance)
        out.append(row)
    causes: dict[str, int] = defaultdict(int)
    for r in out:
        causes[r["cause"]] += 1
    lifted = [r["lifted_off_category"] for r in out if r["lifted_off_category"] is not None]
    return {
        "stop_distance_m": stop_distance,
        "episodes": len(out),
        "replays_matching_the_record": sum(r["replay_matches"] for r in out),
        "causes": dict(sorted(causes.items())),
        # the stop rule's distance, over the STOPs it made (bee-lining to a goal point on a goal-category box)
        "rho_m": stats([r["rho"] for r in out if r["cause"] in ("near_miss", "settled", "off_goal_instance")]),
        "lifted_off_category_max": max(lifted) if lifted else None,
        "per_episode": out,
    }


def print_replay(rep: dict) -> None:
    print(
        f"\nreplayed {rep['episodes']} failed STOPs ({rep['replays_matching_the_record']} match the record); "
        f"causes: {rep['causes']}"
    )
    rho = rep["rho_m"]
    if rho:
        print(
            f"rho at the bee-lining STOPs (m): median {rho['median']:.2f}, min {rho['min']:.2f}, max {rho['max']:.2f} "
            f"(stop distance {rep['stop_distance_m']}); lifted points off every goal-category box: at most "
            f"{fmt(rep['lifted_off_category_max'], '.0%')} per episode"
        )


def fmt(x: float | None, spec: str = ".2f") -> str:
    return "-" if x is None else format(x, spec)


def print_run(name: str, res: dict, base: dict | None) -> None:
    delta = ""
    if base is not None:
        delta = f" (vs {base['name']}: SR {res['sr'] - base['sr']:+.1f}, SPL {res['spl'] - base['spl']:+.1f})"
    print(f"\n## {name}: {res['run']}  [{res['agent']}; camera {res['camera']['width']}x{res['camera']['height']}]")
    print(f"{res['episodes']} episodes: SR {res['sr']:.1f}, SPL {res['spl']:.1f}{delta}")
    print("| split | episodes | SR | SPL |\n|---|---|---|---|")
    for s, v in res["splits"].items():
        print(f"| {s} | {v['episodes']} | {v['sr']:.1f} | {v['spl']:.1f} |")
    print(
        "\n| failure | episodes | to region median / mean / p90 (m) | to object median / mean / p90 (m) "
        "| goal in view | to region histogram |"
    )
    print("|---|---|---|---|---|---|")
    for label, v in res["failures"].items():
        rg, ob = v["to_region_m"], v["to_object_m"]
        hist = ", ".join(f"{k}: {c}" for k, c in v["to_region_histogram"].items())
        print(
            f"| {label} | {v['episodes']} | {fmt(rg['median'])} / {fmt(rg['mean'])} / {fmt(rg['p90'])} | "
            f"{fmt(ob and ob['median'])} / {fmt(ob and ob['mean'])} / {fmt(ob and ob['p90'])} | "
            f"{fmt(v['goal_in_view'], '.0%')} | {hist} |"
        )


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("runs", nargs="+", help="run folders of `ovon evaluate`, optionally NAME=FOLDER")
    ap.add_argument("--out", default="benchmarks/results/vlfm_stops.json", help="JSON written here")
    ap.add_argument(
        "--replay",
        nargs="?",
        const="*",
        default="",
        metavar="NAMES",
        help="replay the failed STOPs of these runs (comma-separated names; all when bare): the agent's "
        "beliefs at the STOP (the agent code must be the one that made the run)",
    )
    args = ap.parse_args(argv)
    out: dict = {"runs": []}
    base = None
    for i, spec in enumerate(args.runs):
        name, sep, folder = spec.partition("=")
        if not sep:
            name, folder = f"run{i}", spec
        res = {"name": name, **analyse(Path(folder))}
        print_run(name, res, base)
        if args.replay == "*" or name in args.replay.split(","):
            res["replay"] = replay_stops(Path(folder))
            print_replay(res["replay"])
        if base is None:
            base = res
        else:
            res["vs_" + base["name"]] = {"sr": res["sr"] - base["sr"], "spl": res["spl"] - base["spl"]}
        out["runs"].append(res)
    atomic_write_text(Path(args.out), json.dumps(out, indent=2) + "\n")
    print(f"\nwritten: {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
