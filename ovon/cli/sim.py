"""`ovon sim view`: render one pose (RGB | depth | semantic side by side); `ovon sim bench`: env steps/s."""

from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ovon.config.base import Domain, Pattern, constrained, in_range, non_empty, non_negative

# A pose is metres around the scene's origin (and a yaw in degrees): far beyond this is a typo.
POSE_LIMIT = 1e5


@dataclass(frozen=True)
class PoseDomain(Domain):
    def accepts(self, value) -> bool:  # noqa: ANN001 - a tuple of 4 floats (the type is checked first)
        return all(abs(x) <= POSE_LIMIT for x in value)

    def describe(self, noun: str) -> str:
        return f"x,y,z,yaw_deg (four numbers within ±{POSE_LIMIT:g})"


@dataclass(frozen=True)
class ViewArgs:
    """`ovon sim view`'s own options through declared domains (one-line errors naming the option)."""

    pose: tuple[float, float, float, float] | None = constrained(None, PoseDomain(), flag="--pose")
    pitch: float = in_range(0.0, -90.0, 90.0, flag="--pitch")
    seed: int = non_negative(0, flag="--seed")
    out: str = constrained(
        "", Pattern(r"(?s).*[^/\\]\.[pP][nN][gG]", "the path of a .png file, e.g. frame.png"), flag="--out"
    )


@dataclass(frozen=True)
class BenchArgs:
    """`ovon sim bench`'s own options through declared domains, checked before the scene is loaded: each
    message names the option that is wrong (one range check used to blame --workers for a bad
    --envs-per-worker, numpy's "expected non-negative integer" stood for a bad --seed, and --goal ""
    silently meant the default goal)."""

    scene: str = non_empty("procedural:0", flag="--scene")
    goal: str | None = non_empty(None, flag="--goal")  # None: the scene's most frequent floor object
    workers: int = in_range(1, 0, 1024, flag="--workers")  # 0: one env stepped in this process
    envs_per_worker: int = in_range(4, 1, 1024, flag="--envs-per-worker")
    steps: int = in_range(1000, 1, 100_000_000, flag="--steps")
    seed: int = non_negative(0, flag="--seed")


def _camera_args(p) -> None:
    from ovon.config.sim import cpu_sim_config

    cam = cpu_sim_config().camera  # the one CPU default of every command
    p.add_argument("--width", type=int, default=cam.width, help=f"pixels (default {cam.width}, the CPU camera)")
    p.add_argument("--height", type=int, default=cam.height, help=f"pixels (default {cam.height}, the CPU camera)")
    p.add_argument("--hfov", type=float, default=None, help="horizontal FOV in degrees (default: the config's)")
    p.add_argument(
        "--backend",
        choices=["auto", "gl", "embree"],
        default="auto",
        help="renderer (auto: one that works on this machine)",
    )


def register(sub) -> None:
    g = sub.add_parser("sim", help="simulator tools: render a view, measure throughput")
    gs = g.add_subparsers(dest="sim_command", required=True)

    v = gs.add_parser("view", help="render RGB | depth | semantic at a pose into one PNG")
    v.add_argument(
        "scene", help="scene folder/file (HM3DSem layout, or a bare .glb/.gltf/.ply/.obj) or procedural:<seed>"
    )
    # "-3,0,2,90" is a value, not an option: let the pose start with a minus sign
    v._negative_number_matcher = re.compile(r"^-\d[\d.,eE+-]*$")
    v.add_argument("--pose", help="x,y,z,yaw_deg of the agent's feet (default: a random navigable pose)")
    v.add_argument("--up", default=None, metavar="AXIS", help="up axis of a scan / bare mesh (y, z, -z, ...)")
    v.add_argument("--pitch", default=0.0, help="camera pitch in degrees in [-90, 90], > 0 looks up")
    v.add_argument("--seed", default=0, help="seed of the random pose")
    _camera_args(v)
    v.add_argument("--out", required=True, help="output .png path")
    v.set_defaults(func=cmd_view)

    b = gs.add_parser(
        "bench", help="env steps/s (random moves and turns, auto-reset; depth, semantic and RGB unless --no-rgb)"
    )
    b.add_argument("--scene", default="procedural:0", help="scene folder/file or procedural:<seed>")
    b.add_argument("--goal", help="goal category (default: the scene's most frequent floor object)")
    _camera_args(b)
    b.add_argument("--no-rgb", action="store_true", help="skip the RGB channel (what oracle encoders need)")
    b.add_argument(
        "--workers", default=1, help="worker processes of the vector env; 0: one env stepped in this process"
    )
    b.add_argument("--envs-per-worker", default=4, help="envs hosted by each worker process")
    b.add_argument("--steps", default=1000, help="timed env steps over all envs")
    b.add_argument("--seed", default=0, help="seed of the start poses and actions")
    b.set_defaults(func=cmd_bench)


CAMERA_OPTIONS = {"width": "--width", "height": "--height", "hfov_deg": "--hfov", "backend": "--backend"}


def _camera(args):
    """The camera options through `CameraConfig`'s declared domains (`--hfov 180` is refused like
    `--set sim.camera.hfov_deg=180`), the message naming the options."""
    from ovon.config.base import ConfigError, from_dict
    from ovon.config.sim import CameraConfig

    data = {"width": args.width, "height": args.height, "backend": args.backend}
    if args.hfov is not None:
        data["hfov_deg"] = args.hfov
    try:
        return from_dict(CameraConfig, data)
    except ConfigError as e:
        msg = str(e)
        for key, option in CAMERA_OPTIONS.items():
            msg = msg.replace(f"--set {key}=VALUE with VALUE", f"pass {option} with")
            msg = msg.replace(f"{key} = ", f"{option} = ")
        raise ConfigError(msg) from None


def colorize_depth(depth: np.ndarray, max_depth: float) -> np.ndarray:
    """Depth (metres, 0 = no hit) to an RGB image with the turbo colormap; no hit is black."""
    import cv2

    d = np.clip(depth / max(max_depth, 1e-6), 0.0, 1.0)
    img = cv2.applyColorMap((d * 255).astype(np.uint8), cv2.COLORMAP_TURBO)[:, :, ::-1]
    img = img.copy()
    img[depth <= 0] = 0
    return img


def colorize_semantic(semantic: np.ndarray, seed: int = 0) -> np.ndarray:
    """Instance ids to random (but per-id stable) colours; id 0 is black."""
    ids, inverse = np.unique(semantic, return_inverse=True)
    palette = np.zeros((len(ids), 3), dtype=np.uint8)
    for k, i in enumerate(ids):
        if i != 0:
            palette[k] = np.random.default_rng([seed, int(i)]).integers(40, 256, 3)
    return palette[inverse.reshape(semantic.shape)]


def cmd_view(args) -> int:
    from PIL import Image

    from ovon.atomic import atomic_write_with, check_output_path
    from ovon.cli.scenes import check_up_option
    from ovon.config.base import ConfigError, from_args
    from ovon.config.sim import SimConfig
    from ovon.sim.render import make_renderer
    from ovon.sim.world import load_scene_any

    a = from_args(ViewArgs, args)
    # a folder, or a path under an existing file: refused before the scene is loaded and rendered
    check_output_path(a.out, "--out", expected="the path of a .png file", example="frame.png", error=ConfigError)
    cam = _camera(args)
    check_up_option(args.up, args.scene)
    scene = load_scene_any(args.scene, up=args.up)
    if a.pose is not None:
        pos, yaw = np.array(a.pose[:3], dtype=np.float64), math.radians(a.pose[3])
    else:
        from ovon.sim.navgrid import build_navigation

        sim = SimConfig(camera=cam)
        nav = build_navigation(scene, sim.agent, sim.nav)
        rng = np.random.default_rng(a.seed)
        grids = [g for g in nav.floors if g.navigable.any()]
        if not grids:
            raise ValueError(
                f"scene {args.scene!r} has no navigable area for a random pose; pass --pose x,y,z,yaw "
                "(or --up if the scene is rotated)"
            )
        pos = grids[int(rng.integers(len(grids)))].random_point(rng)
        yaw = float(rng.uniform(-math.pi, math.pi))
    renderer = make_renderer(scene, cam)
    try:
        eye = pos + np.array([0.0, cam.camera_height, 0.0])
        frame = renderer.render(eye, yaw, math.radians(a.pitch))
    finally:
        renderer.close()
    panel = np.concatenate(
        [frame.rgb, colorize_depth(frame.depth, cam.max_depth), colorize_semantic(frame.semantic)], axis=1
    )
    out = Path(a.out)
    atomic_write_with(out, lambda f: Image.fromarray(panel).save(f, format="PNG"))  # never a torn PNG
    n_ids = len(np.unique(frame.semantic[frame.semantic > 0]))
    print(
        f"pose x={pos[0]:.3f} y={pos[1]:.3f} z={pos[2]:.3f} yaw={math.degrees(yaw):.1f} deg "
        f"pitch={a.pitch:.1f} deg; {n_ids} instances in view"
    )
    print(f"wrote {out} ({panel.shape[1]}x{panel.shape[0]}: rgb | depth | semantic)")
    return 0


def cmd_bench(args) -> int:
    import dataclasses

    from ovon.config.base import from_args
    from ovon.config.sim import SimConfig
    from ovon.env.bench import measure_throughput, pick_goal
    from ovon.env.stack import EnvRecipe

    os.environ.setdefault("LP_NUM_THREADS", "0")
    a = from_args(BenchArgs, args)
    cam = dataclasses.replace(_camera(args), rgb=not args.no_rgb)
    goal = a.goal if a.goal is not None else pick_goal(a.scene)
    recipe = EnvRecipe(sim=SimConfig(camera=cam), scene=a.scene, goal=goal)
    envs = a.envs_per_worker * max(1, a.workers)
    r = measure_throughput(recipe, workers=a.workers, envs=envs, steps=a.steps, seed=a.seed)
    where = "in this process" if a.workers == 0 else f"{r['envs']} envs on {r['workers']} worker(s)"
    channels = "depth+semantic" if args.no_rgb else "rgb+depth+semantic"
    print(
        f"scene {a.scene}, goal {goal!r}, {args.width}x{args.height} {channels}, backend {args.backend}, "
        f"{where}: {r['steps']} steps in {r['seconds']:.2f} s (setup {r['setup_s']:.1f} s, "
        f"{r['cpu_ms_per_step']:.2f} CPU ms/step)"
    )
    print(f"{r['steps_per_s']:.1f} steps/s")
    return 0
