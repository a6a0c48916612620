"""Perception speed: ovon's learned perception (world-vl encoder + world-owl detector) against the oracle's.

    python benchmarks/perception_speed.py [--checkpoint PATH] [--quick] [--out /tmp/perception_speed.json]
        [--parts frames,train] [--houses 0,1] [--frames 64] [--batches 1,4,8] [--repeats 5]
        [--algos ppo,dagger] [--updates 6] [--train-repeats 2] [--envs 0] [--workers 2] [--env-steps 800]

Targets (the issue): encoder and detector together at most 3 ms per frame at the CPU camera (72 x 128) on one
core, batched across a vector env's envs; PPO and DAgger env steps/s with `world-vl` at least 40% of the same
with `oracle-vl`. Both are measured with the oracle in the same run, so read the ratios (the machine is shared).

Part 1, per frame (`frames`; this process, `torch.set_num_threads(1)`): `--frames` real frames of the CPU camera
from random walks in procedural houses (`--houses`; the env stack with the privileged channel, so every frame
has its RGB, depth, bump flag, semantic frame and goal). Timed, in rotating order, `--repeats` passes each:

* `world-vl batched B` (B in `--batches`): one forward pass of the network per batch of B frames
  (`WorldVL.features`), then the encoder's embedding (`WorldVLNet.pooled` + the depth grid + the bump flag, the
  `cpu-small` encoder layout) and the detector's (`cell_cosines` for each frame's goal text, the calibrated
  cell pooling, and the connected components of the frames that pass the threshold) from the same features;
  the stack of the frames is in the time. Every embedding and detection is checked against the roles'
  own `WorldVLEncoder.encode` / `WorldOWLDetector.detect` (`agreement` in the JSON);
* `world-vl roles, batch 1`: what an agent acting alone runs per step (DAgRL+OD), `encode_observation(
  WorldVLEncoder)` (`encode_frame`: an unpadded forward pass of one frame) and `WorldOWLDetector.detect` on the
  same frame, which reuses that forward pass through `WorldVL.frame_features`;
* `oracle`: `OracleVLEncoder.encode_one` (what the env's encoding wrapper calls) + `OracleDetector.detect`,
  frame by frame (the oracle has no batched path), from the semantic frames.

Reported: CPU ms per frame of this process (the figure a busy machine does not inflate; wall ms beside it),
medians over the passes, the world-vl stages (forward pass, encoder pooling, detector) and the ratios to the
oracle.

Part 2, env steps/s (`ovon.train.train` with the `cpu-small` preset on ad-hoc episodes of `--houses`, envs on
`--workers` processes, goal texts from a fixed random table as `train_throughput.py --text hash` does: the
per-step cost is the same): for each of `--algos` (PPO; DAgger with the frontier expert, whose labels drive the
envs at beta 1) `--updates` updates with `encoder.image=oracle-vl` and with `world-vl`, alternated,
`--train-repeats` times; the first update (worker start, world loading) is left out. Reported: env steps/s
including learning, rollout-only steps/s, steady CPU ms per env step (this process + workers), and their
world-vl / oracle-vl ratios against the 40% target. Also `env only`: `ovon.env.bench.measure_throughput`
(what `ovon sim bench` runs: random actions, no policy) of the PPO env stack with each encoder. The env stack
renders RGB only for world-vl (the oracle reads depth + semantic), so the world-vl rows pay for RGB too.

`--quick`: fewer passes and updates (about 2-3 minutes on the shared 2-core machine). Writes JSON to `--out`
(default: perception_speed.json in the temp folder, so a casual run leaves the checkout as it was).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import platform
import shutil
import sys
import tempfile
import time
import zlib
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))  # train_throughput.bench_online
from ovon.atomic import atomic_write_text  # noqa: E402

TARGET_MS = 3.0  # encoder + detector, CPU ms per frame on one core
TARGET_RATIO = 0.4  # world-vl env steps/s / oracle-vl env steps/s


def _median(xs) -> float | None:
    xs = [x for x in xs if x is not None]
    return float(np.median(xs)) if xs else None


def hash_table(texts) -> dict[str, np.ndarray]:
    """Fixed random 384-d vectors per text (train_throughput.py's `--text hash`): no language model to load."""
    return {t: np.random.default_rng(zlib.crc32(t.encode())).standard_normal(384).astype(np.float32) for t in texts}


def code_version(tree: Path) -> str:
    """The checkout's commit, "+dirty" when its code has uncommitted changes (train_throughput.py's stamp, read
    with GIT_OPTIONAL_LOCKS=0: looking does not rewrite the index)."""
    import subprocess

    def git(*a: str) -> str:
        env = {**os.environ, "GIT_OPTIONAL_LOCKS": "0"}
        return subprocess.run(["git", "-C", str(tree), *a], capture_output=True, text=True, env=env).stdout.strip()

    head = git("rev-parse", "--short=12", "HEAD") or "unknown"
    spec = ("--", "ovon", "benchmarks", "pyproject.toml", ":!benchmarks/results")
    changed = git("status", "--porcelain", "--untracked-files=no", *spec)
    return head + ("+dirty" if changed else "")


def encoder_config(image: str, checkpoint: str):
    """The `cpu-small` preset's encoder (grid 2 + global, 6 x 4 depth grid, bump flag) with `image`."""
    from ovon.train.config import train_preset

    enc = train_preset("cpu-small").encoder
    return dataclasses.replace(enc, image=image, world_checkpoint=checkpoint if image == "world-vl" else "")


# ------------------------------------------------------------------------------------------------ part 1


def collect_frames(houses: list[int], n: int, seed: int, stride: int = 3) -> list[dict]:
    """`n` frames of the CPU camera (split over `houses`), every `stride`-th step of a random walk (forward,
    left, right; reset at the episode's end), with what both perception stacks read."""
    from ovon.config.sim import cpu_sim_config
    from ovon.env.bench import pick_goal
    from ovon.env.stack import EnvRecipe, build_env
    from ovon.sim.types import Frame

    rng = np.random.default_rng(seed)
    frames: list[dict] = []
    for k, house in enumerate(houses):
        want = n // len(houses) + (1 if k < n % len(houses) else 0)
        scene = f"procedural:{house}"
        env = build_env(EnvRecipe(sim=cpu_sim_config(), scene=scene, goal=pick_goal(scene), privileged=True))
        try:
            env.reset(seed=seed + house)
            step = 0
            while want > 0:
                obs, _, term, trunc, info = env.step(int(rng.integers(1, 4)))
                if term or trunc:
                    obs, info = env.reset()
                step += 1
                if step % stride:
                    continue
                p = info["privileged"]
                frame = Frame(np.array(obs["rgb"]), np.array(obs["depth"]), np.array(p.frame.semantic))
                frames.append(
                    {
                        "house": house,
                        "rgb": frame.rgb,
                        "depth": frame.depth,
                        "collided": int(obs["collided"]),
                        "goal": str(obs["goal"]),
                        "privileged": dataclasses.replace(p, frame=frame),
                    }
                )
                want -= 1
        finally:
            env.close()
    return frames


class WorldBatched:
    """The world-vl encoder and the world-owl detector from one forward pass per batch."""

    def __init__(self, checkpoint: str, text) -> None:
        from ovon.models.config import DetectorConfig
        from ovon.models.encoders import make_image_encoder
        from ovon.models.world.roles import WorldOWLDetector, _unit_text

        self.encoder = make_image_encoder(encoder_config("world-vl", checkpoint), text)
        self.detector = WorldOWLDetector(DetectorConfig(kind="world-owl", checkpoint=checkpoint), text_encoder=text)
        self.model = self.encoder.model
        self.threshold = self.detector.threshold
        self.text = text
        self._unit_text = _unit_text
        self._units: dict[str, object] = {}

    def unit(self, goal: str):
        if goal not in self._units:
            self._units[goal] = self._unit_text(self.text, [goal])[0]
        return self._units[goal]

    def scores(self, frames: list[dict], batch: int = 8) -> np.ndarray:
        """Each frame's pooled score for its goal text (what the threshold is compared with)."""
        out = []
        for s in range(0, len(frames), batch):
            chunk = frames[s : s + batch]
            top, _, _ = self.model.features(np.stack([f["rgb"] for f in chunk]))
            for i, f in enumerate(chunk):
                out.append(
                    float(self.model.frame_score(self.model.probs(top[i : i + 1], self.unit(f["goal"])[None])[0]))
                )
        return np.array(out)

    def set_threshold(self, value: float) -> None:
        self.threshold = self.detector.threshold = float(value)

    def run(self, chunk: list[dict], clock: dict[str, float]):
        """(embeddings (B, dim), detections per frame); adds CPU seconds per stage to `clock`."""
        import torch
        from scipy import ndimage

        from ovon.models.detectors.base import Detection, box_of
        from ovon.models.encoders.depth_grid import depth_grid_features

        enc, model, net = self.encoder, self.model, self.model.net
        c0 = time.process_time()
        rgb = np.stack([f["rgb"] for f in chunk])
        top, obj, _ = model.features(rgb)
        c1 = time.process_time()
        with torch.inference_mode():
            whole, regions = net.pooled(top, obj, enc.grid)
            parts = [whole[:, None]] if enc.include_global else []
            out = [torch.cat([*parts, regions], dim=1).flatten(1)]
            if enc.depth_grid[0] > 0:
                feats = np.stack([depth_grid_features(f["depth"], enc.depth_grid, enc.max_depth) for f in chunk])
                out.append(torch.from_numpy(feats))
            if enc.collision:
                out.append(torch.tensor([[float(f["collided"])] for f in chunk]))
            emb = torch.cat(out, dim=1).float()
        c2 = time.process_time()
        goals = list(dict.fromkeys(f["goal"] for f in chunk))
        texts = torch.stack([self.unit(g) for g in goals])
        probs = model.probs(top, texts)  # (B, K, h, w)
        own = probs[torch.arange(len(chunk)), torch.tensor([goals.index(f["goal"]) for f in chunk])]  # (B, h, w)
        scores = model.frame_score(own)
        dets: list[list] = []
        H, W = rgb.shape[1:3]
        rows = cols = None
        for i, f in enumerate(chunk):
            found = []
            if float(scores[i]) >= self.threshold:
                p = own[i].numpy()
                labels, n = ndimage.label(p >= self.threshold)
                if rows is None:
                    rows = (np.arange(H) * p.shape[0]) // H
                    cols = (np.arange(W) * p.shape[1]) // W
                for k in range(1, n + 1):
                    cells = labels == k
                    mask = cells[rows][:, cols]
                    found.append(Detection(box_of(mask), float(p[cells].max()), f["goal"], mask))
                found.sort(key=lambda d: -d.score)
            dets.append(found)
        c3 = time.process_time()
        clock["forward"] += c1 - c0
        clock["encoder"] += c2 - c1
        clock["detector"] += c3 - c2
        return emb, dets


def roles_batch1(world: WorldBatched, f: dict):
    """What an agent acting alone runs per step: the encoder's batch of one, then the detector on the same
    frame (one shared forward pass)."""
    from ovon.models.encoders import encode_observation

    obs = {"rgb": f["rgb"], "depth": f["depth"], "collided": f["collided"]}
    return encode_observation(world.encoder, obs), world.detector.detect({"rgb": f["rgb"]}, f["goal"])


def agreement(world: WorldBatched, frames: list[dict], batch: int) -> dict:
    """The batched path's embeddings and detections against the roles' (batch of one each)."""
    clock = {"forward": 0.0, "encoder": 0.0, "detector": 0.0}
    emb_err, det_diff, dets_total = 0.0, 0, 0
    for s in range(0, len(frames), batch):
        chunk = frames[s : s + batch]
        emb, dets = world.run(chunk, clock)
        for i, f in enumerate(chunk):
            ref_emb, ref_dets = roles_batch1(world, f)
            emb_err = max(emb_err, float(np.abs(emb[i].numpy() - ref_emb).max()))
            dets_total += len(ref_dets)
            same = len(dets[i]) == len(ref_dets) and all(
                a.box == b.box and abs(a.score - b.score) < 1e-4 for a, b in zip(dets[i], ref_dets)
            )
            det_diff += 0 if same else 1
    return {"batch": batch, "max_abs_embedding_diff": emb_err, "frames_with_other_detections": det_diff,
            "detections": dets_total, "frames": len(frames)}  # fmt: skip


def bench_frames(args) -> dict:
    import torch

    from ovon.models.config import DetectorConfig
    from ovon.models.detectors.oracle import OracleDetector
    from ovon.models.encoders import TableTextEncoder, make_image_encoder
    from ovon.train.episodes import adhoc_specs
    from ovon.train.text import needed_texts

    torch.set_num_threads(1)
    houses = [int(h) for h in args.houses.split(",")]
    t0 = time.perf_counter()
    frames = collect_frames(houses, args.frames, args.seed)
    render_s = time.perf_counter() - t0
    goals = sorted({f["goal"] for f in frames})
    text = TableTextEncoder(hash_table(needed_texts(adhoc_specs(houses)) + goals))
    world = WorldBatched(args.checkpoint, text)
    for g in goals:
        world.unit(g)
    # the oracle: one encoder and one detector per house, their scene set before timing (the env sets it at a
    # scene change, not per step)
    oracle_enc, oracle_det = {}, {}
    for f in frames:
        h = f["house"]
        if h not in oracle_enc:
            oracle_enc[h] = make_image_encoder(encoder_config("oracle-vl", ""), text)
            p = f["privileged"]
            oracle_enc[h].set_scene({o.id: o.category for o in p.world.scene.objects if o.category})
            oracle_det[h] = OracleDetector(DetectorConfig(), text_encoder=text)
            oracle_det[h].detect({"privileged": p}, f["goal"])

    def oracle_pass(clock):
        c0 = time.process_time()
        for f in frames:
            oracle_enc[f["house"]].encode_one(f["privileged"].frame.semantic, f["depth"], f["collided"])
        c1 = time.process_time()
        for f in frames:
            oracle_det[f["house"]].detect({"privileged": f["privileged"]}, f["goal"])
        clock["encoder"] += c1 - c0
        clock["detector"] += time.process_time() - c1

    def roles_pass(clock):
        c0 = time.process_time()
        for f in frames:
            roles_batch1(world, f)
        clock["total"] += time.process_time() - c0

    def batched_pass(b):
        def run(clock):
            for s in range(0, len(frames), b):
                world.run(frames[s : s + b], clock)

        return run

    # the calibrated threshold may leave most frames without a detection; this row sets it at the median frame
    # score, so about half the frames pay for the detections' connected components too
    calibrated = world.threshold
    lowered = float(np.median(world.scores(frames)))
    bmax = max(args.batch_sizes)

    def half_detected(clock):
        world.set_threshold(lowered)
        try:
            batched_pass(bmax)(clock)
        finally:
            world.set_threshold(calibrated)

    configs = {f"world-vl batched {b}": batched_pass(b) for b in args.batch_sizes}
    configs[f"world-vl batched {bmax}, half detected"] = half_detected
    configs["world-vl roles, batch 1"] = roles_pass
    configs["oracle"] = oracle_pass
    names = list(configs)
    for name in names:  # warm-up (first convolutions, caches)
        configs[name]({"forward": 0.0, "encoder": 0.0, "detector": 0.0, "total": 0.0})
    runs: dict[str, list[dict]] = {n: [] for n in names}
    for rep in range(args.repeats):
        for name in names[rep % len(names) :] + names[: rep % len(names)]:
            clock = {"forward": 0.0, "encoder": 0.0, "detector": 0.0, "total": 0.0}
            w0, c0 = time.perf_counter(), time.process_time()
            configs[name](clock)
            wall, cpu = time.perf_counter() - w0, time.process_time() - c0
            n = len(frames)
            row = {"cpu_ms_per_frame": 1000 * cpu / n, "wall_ms_per_frame": 1000 * wall / n}
            row.update({f"{k}_cpu_ms_per_frame": 1000 * v / n for k, v in clock.items() if v > 0 and k != "total"})
            runs[name].append(row)
    results = {}
    oracle_ms = _median(r["cpu_ms_per_frame"] for r in runs["oracle"])
    for name in names:
        keys = sorted({k for r in runs[name] for k in r})
        med = {k: _median(r.get(k) for r in runs[name]) for k in keys}
        med["x_oracle_cpu"] = med["cpu_ms_per_frame"] / oracle_ms if oracle_ms else None
        if name.startswith("world-vl"):
            med["meets_target"] = med["cpu_ms_per_frame"] <= TARGET_MS
        results[name] = {"median": med, "runs": runs[name]}
    check = {"calibrated": agreement(world, frames, bmax)}
    world.set_threshold(lowered)
    try:
        check["half_detected"] = agreement(world, frames, bmax)
    finally:
        world.set_threshold(calibrated)
    return {
        "houses": houses,
        "frames": len(frames),
        "camera": list(frames[0]["rgb"].shape[:2][::-1]),
        "goals": goals,
        "render_s": render_s,
        "checkpoint": world.model.source,
        "threshold": calibrated,
        "half_detected_threshold": lowered,
        "pooling": world.model.pooling,
        "torch_threads": torch.get_num_threads(),
        "repeats": args.repeats,
        "target_ms_per_frame": TARGET_MS,
        "configs": results,
        "agreement": check,
    }


def print_frames(res: dict) -> None:
    print(
        f"\nPer frame, {res['frames']} frames {res['camera'][0]}x{res['camera'][1]} of houses {res['houses']}, "
        f"1 torch thread, medians of {res['repeats']} passes (CPU ms; wall beside it); target <= {TARGET_MS} ms"
    )
    print(f"{'':34} {'CPU ms':>7} {'wall ms':>8} {'forward':>8} {'encoder':>8} {'detector':>8} {'x oracle':>9}  target")
    for name, r in res["configs"].items():
        m = r["median"]

        def f(k, m=m):
            return f"{m[k]:.3f}" if m.get(k) is not None else "-"

        verdict = ("pass" if m["meets_target"] else "FAIL") if "meets_target" in m else ""
        print(
            f"{name:34} {f('cpu_ms_per_frame'):>7} {f('wall_ms_per_frame'):>8} {f('forward_cpu_ms_per_frame'):>8} "
            f"{f('encoder_cpu_ms_per_frame'):>8} {f('detector_cpu_ms_per_frame'):>8} {m['x_oracle_cpu']:>9.2f}  "
            f"{verdict}"
        )
    for key, thr in (("calibrated", res["threshold"]), ("half_detected", res["half_detected_threshold"])):
        a = res["agreement"][key]
        print(
            f"batched ({a['batch']}) vs the roles, threshold {thr:.4g} ({key}, {res['pooling']}): max |embedding "
            f"diff| {a['max_abs_embedding_diff']:.2e}, {a['frames_with_other_detections']}/{a['frames']} frames "
            f"with other detections ({a['detections']} detections by the roles)"
        )


# ------------------------------------------------------------------------------------------------ part 2


def bench_env_only(args, text_table: dict, image: str) -> dict:
    from ovon.config.sim import cpu_sim_config
    from ovon.env.bench import measure_throughput, pick_goal
    from ovon.env.stack import EnvRecipe

    scene = f"procedural:{args.houses.split(',')[0]}"
    recipe = EnvRecipe(
        sim=cpu_sim_config(),
        scene=scene,
        goal=pick_goal(scene),
        encoder=encoder_config(image, args.checkpoint),
        text_table=text_table,
    )
    envs = args.envs or 4 * args.workers
    warmup = 5 if args.quick else 20  # vector env calls before the timed ones
    return measure_throughput(
        recipe, workers=args.workers, envs=envs, steps=args.env_steps, warmup=warmup, seed=args.seed
    )


def bench_train(args) -> dict:
    from train_throughput import bench_online  # benchmarks/: the figures of the training-throughput table

    from ovon.config.base import parse_seed_list
    from ovon.train.config import train_preset
    from ovon.train.episodes import adhoc_specs
    from ovon.train.text import needed_texts, write_text_table

    root = Path(tempfile.mkdtemp(prefix="ovon-perception-bench-"))
    images = ("oracle-vl", "world-vl")
    algos = [a for a in args.algos.split(",") if a]
    try:
        specs = adhoc_specs(parse_seed_list(args.houses))
        table = hash_table(needed_texts(specs))
        base = train_preset(
            "cpu-small",
            max_updates=args.updates,
            env_workers=args.workers,
            progress=False,
            checkpoint_every=10**9,
            text_cache=str(root / "text.pt"),
        )
        if args.envs:
            base = dataclasses.replace(base, num_envs=args.envs)
        write_text_table(root / "text.pt", table, base.encoder)
        runs: dict[str, dict[str, list[dict]]] = {k: {i: [] for i in images} for k in ["env-only", *algos]}
        for rep in range(args.train_repeats):
            order = images if rep % 2 == 0 else images[::-1]
            for image in order:
                r = bench_env_only(args, table, image)
                runs["env-only"][image].append(r)
                print(f"  env only, {image}: {r['steps_per_s']:.0f} steps/s", flush=True)
            for algo in algos:
                for image in order:
                    cfg = dataclasses.replace(base, encoder=encoder_config(image, args.checkpoint))
                    t = time.perf_counter()
                    r = bench_online(algo, cfg, specs, root / f"{algo}-{image}-{rep}")
                    r.pop("learning", None)
                    runs[algo][image].append(r)
                    print(
                        f"  {algo}, {image}: {r['env_steps_per_s']:.0f} env steps/s, rollout "
                        f"{r['rollout_steps_per_s']:.0f} ({time.perf_counter() - t:.0f} s)",
                        flush=True,
                    )
    finally:
        shutil.rmtree(root, ignore_errors=True)
    summary = {}
    for key, by_image in runs.items():
        fields = ("steps_per_s", "cpu_ms_per_step") if key == "env-only" else (
            "env_steps_per_s", "rollout_steps_per_s", "steady_cpu_ms_per_step", "learn_s")  # fmt: skip
        med = {i: {k: _median(r.get(k) for r in rs) for k in fields} for i, rs in by_image.items()}
        o, w = med["oracle-vl"], med["world-vl"]
        rate = fields[0]
        ratio = w[rate] / o[rate] if o[rate] and w[rate] else None
        entry = {"median": med, "ratio": ratio, "meets_target": ratio is not None and ratio >= TARGET_RATIO}
        if key != "env-only":
            entry["rollout_ratio"] = (
                w["rollout_steps_per_s"] / o["rollout_steps_per_s"]
                if o["rollout_steps_per_s"] and w["rollout_steps_per_s"]
                else None
            )
            cpu_o, cpu_w = o["steady_cpu_ms_per_step"], w["steady_cpu_ms_per_step"]
            entry["cpu_ratio"] = cpu_o / cpu_w if cpu_o and cpu_w else None
        else:
            entry["cpu_ratio"] = o["cpu_ms_per_step"] / w["cpu_ms_per_step"]
        summary[key] = entry
    return {
        "preset": "cpu-small",
        "num_envs": base.num_envs,
        "env_workers": args.workers,
        "rollout_steps": base.rollout_steps,
        "updates": args.updates,
        "repeats": args.train_repeats,
        "env_only_steps": args.env_steps,
        "houses": args.houses,
        "target_ratio": TARGET_RATIO,
        "summary": summary,
        "runs": runs,
    }


def print_train(res: dict) -> None:
    print(
        f"\nEnv steps/s, cpu-small, {res['num_envs']} envs on {res['env_workers']} workers, medians of "
        f"{res['repeats']} runs ({res['updates']} updates, the first left out); target world-vl >= "
        f"{TARGET_RATIO:.0%} of oracle-vl"
    )
    print(f"{'':10} {'oracle-vl':>10} {'world-vl':>10} {'ratio':>7} {'rollout ratio':>14} {'CPU ratio':>10}  target")
    for key, e in res["summary"].items():
        rate = "steps_per_s" if key == "env-only" else "env_steps_per_s"
        o, w = e["median"]["oracle-vl"][rate], e["median"]["world-vl"][rate]

        def f(x, spec=".2f"):
            return "-" if x is None else format(x, spec)

        print(
            f"{key:10} {f(o, '.0f'):>10} {f(w, '.0f'):>10} {f(e['ratio']):>7} {f(e.get('rollout_ratio')):>14} "
            f"{f(e['cpu_ratio']):>10}  {'pass' if e['meets_target'] else 'FAIL'}"
        )


# ------------------------------------------------------------------------------------------------ main


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--checkpoint", default="", help="world-vl weights (file or run folder); '' = the shipped ones")
    ap.add_argument("--quick", action="store_true", help="fewer passes and updates (a few minutes)")
    ap.add_argument("--out", default=str(Path(tempfile.gettempdir()) / "perception_speed.json"))
    ap.add_argument("--parts", default="frames,train", help="frames (per-frame cost), train (env steps/s)")
    ap.add_argument("--houses", default="0,1", help="procedural house seeds")
    ap.add_argument("--frames", type=int, default=64)
    ap.add_argument("--batches", default="1,4,8", help="world-vl batch sizes")
    ap.add_argument("--repeats", type=int, default=None, help="passes over the frames (default 7, quick 3)")
    ap.add_argument("--algos", default="ppo,dagger")
    ap.add_argument("--updates", type=int, default=None, help="updates per training run (default 6, quick 3)")
    ap.add_argument("--train-repeats", type=int, default=None, help="runs per encoder (default 2, quick 1)")
    ap.add_argument("--envs", type=int, default=0, help="num_envs (0 = the preset's)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--env-steps", type=int, default=None, help="env-only timed steps (default 1600, quick 400)")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    quick = args.quick
    args.repeats = args.repeats or (3 if quick else 7)
    args.updates = args.updates or (3 if quick else 6)
    args.train_repeats = args.train_repeats or (1 if quick else 2)
    args.env_steps = args.env_steps or (400 if quick else 1600)
    args.batch_sizes = [int(b) for b in args.batches.split(",") if b]
    parts = {p for p in args.parts.split(",") if p}
    if bad := parts - {"frames", "train"}:
        raise SystemExit(f"--parts: unknown part(s) {sorted(bad)}; valid: frames, train")
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    from ovon.models.world import load_world_vl

    try:
        source = load_world_vl(args.checkpoint).source  # a missing or foreign file: one line, before any work
    except (FileNotFoundError, ValueError) as e:
        raise SystemExit(f"perception_speed.py: {e}") from None
    result: dict = {
        "command": " ".join([Path(sys.argv[0]).name, *sys.argv[1:]]),
        "code": code_version(Path(__file__).resolve().parents[1]),
        "checkpoint": source,
        "quick": quick,
        "machine": {"cpus": os.cpu_count(), "platform": platform.platform()},
        "load_average_before": os.getloadavg(),
    }
    t0 = time.perf_counter()
    if "frames" in parts:
        result["frames"] = bench_frames(args)
        print_frames(result["frames"])
    if "train" in parts:
        print("\nenv steps/s:", flush=True)
        result["train"] = bench_train(args)
        print_train(result["train"])
    result["load_average_after"] = os.getloadavg()
    result["seconds"] = time.perf_counter() - t0
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(out, json.dumps(result, indent=1) + "\n")
    print(f"\nwrote {out} ({result['seconds']:.0f} s)")


if __name__ == "__main__":
    main()
