"""`ovon video`: replay a recorded episode (same seed + recorded actions = same trajectory) and write an
mp4 with RGB, depth and a top-down map (navigable area, path, goal viewpoints and goal objects)."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import imageio.v2 as imageio
import numpy as np

from ovon.config.base import from_dict
from ovon.config.sim import SimConfig
from ovon.config.task import TaskConfig
from ovon.evaluate.results import read_records
from ovon.evaluate.runner import episode_seed


def _depth_to_rgb(depth: np.ndarray, max_depth: float) -> np.ndarray:
    d = np.clip(depth / max_depth, 0, 1)
    return cv2.applyColorMap((255 * (1 - d)).astype(np.uint8), cv2.COLORMAP_VIRIDIS)[..., ::-1]


class TopDown:
    """Static map image of one floor plus world->pixel conversion."""

    def __init__(self, grid, viewpoints: np.ndarray, goal_boxes: list[tuple[np.ndarray, np.ndarray]], size: int):
        nav = grid.navigable
        img = np.full((*nav.shape, 3), 40, np.uint8)
        img[grid.free] = (90, 90, 90)
        img[nav] = (200, 200, 200)
        self.grid = grid
        self.scale = size / max(nav.shape)
        self.base = cv2.resize(img, (int(nav.shape[1] * self.scale), int(nav.shape[0] * self.scale)),
                               interpolation=cv2.INTER_NEAREST)
        for lo, hi in goal_boxes:
            cv2.rectangle(self.base, self.px(lo), self.px(hi), (220, 60, 60), -1)
        for v in viewpoints:
            cv2.circle(self.base, self.px(v), 2, (60, 180, 60), -1)

    def px(self, p) -> tuple[int, int]:
        g = self.grid
        col = (p[0] - g.origin[0]) / g.cell_size
        row = (p[2] - g.origin[1]) / g.cell_size
        return int(col * self.scale), int(row * self.scale)

    def draw(self, path: list[np.ndarray], yaw: float) -> np.ndarray:
        img = self.base.copy()
        pts = np.array([self.px(p) for p in path], np.int32)
        if len(pts) > 1:
            cv2.polylines(img, [pts], False, (40, 90, 230), 2)
        x, y = pts[-1]
        tip = (int(x - 10 * np.sin(yaw)), int(y - 10 * np.cos(yaw)))
        cv2.arrowedLine(img, (int(x), int(y)), tip, (250, 140, 0), 2, tipLength=0.5)
        return img


def _fit(img: np.ndarray, h: int) -> np.ndarray:
    w = int(round(img.shape[1] * h / img.shape[0]))
    return cv2.resize(img, (w, h), interpolation=cv2.INTER_NEAREST)


def render_video(run_dir: str | Path, episode_id: str, out: str | Path, split: str | None = None,
                 seed: int | None = None, fps: int = 8, scene: str | None = None) -> Path:
    from ovon.env import make_objectnav
    from ovon.evaluate.harness import load_specs

    run_dir = Path(run_dir)
    meta_path = run_dir / "run.json"
    if not meta_path.exists():
        raise FileNotFoundError(f"{run_dir} has no run.json: is it a folder written by `ovon evaluate`?")
    meta = json.loads(meta_path.read_text())
    recs = [r for r in read_records(run_dir) if str(r["episode_id"]) == str(episode_id)
            and (split is None or r["split"] == split) and (seed is None or int(r["seed"]) == seed)
            and (scene is None or scene in r["scene"])]
    if not recs:
        raise KeyError(
            f"episode {episode_id!r} is not in {run_dir}/episodes.jsonl (filters split={split}, seed={seed})"
        )
    where = sorted({(r["split"], r["scene"]) for r in recs})
    if len(where) > 1:  # episode ids are unique per scene shard only
        raise ValueError(
            f"episode {episode_id!r} exists in several (split, scene) pairs: {where}; pass --split and/or --scene"
        )
    rec = recs[0]
    specs = [s for s in load_specs(meta["data"], meta["scenes"], rec["split"], None)
             if s.episode_id == str(episode_id) and s.scene == rec["scene"]]
    if not specs:
        raise KeyError(f"episode {episode_id!r} of {rec['scene']} not found in {meta['data']}/{rec['split']}")
    spec = specs[0]
    sim = from_dict(SimConfig, meta["sim"])
    env = make_objectnav(episodes=[spec], sim=sim, task=from_dict(TaskConfig, meta["task"]), privileged=True)
    obs, info = env.reset(seed=episode_seed(rec["seed"], spec.split, spec.episode_id, spec.scene),
                          options={"episode": spec})
    p = info["privileged"]
    goals = [(np.asarray(o.aabb_min), np.asarray(o.aabb_max)) for o in p.world.scene.objects if o.id in p.goal_ids]
    top = TopDown(p.grid, np.array([v.position for v in p.viewpoints]), goals, size=360)
    path = [p.state.position]
    frames = []
    h = 240

    def frame(o, inf, text):
        rgb = _fit(o["rgb"], h)
        depth = _fit(_depth_to_rgb(o["depth"], sim.camera.max_depth), h)
        td = _fit(top.draw(path, inf["privileged"].state.yaw), h)
        img = np.concatenate([rgb, depth, td], axis=1)
        bar = np.full((28, img.shape[1], 3), 255, np.uint8)
        cv2.putText(bar, text, (6, 20), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 0, 0), 1, cv2.LINE_AA)
        return np.concatenate([bar, img], axis=0)

    frames.append(frame(obs, info, f"goal: {spec.goal_category}  step 0  d={p.distance_to_goal:.2f} m"))
    names = ("STOP", "FORWARD", "LEFT", "RIGHT", "UP", "DOWN")
    for t, a in enumerate(rec["actions"], 1):
        obs, _, term, trunc, info = env.step(a)
        path.append(info["privileged"].state.position)
        frames.append(frame(obs, info, f"goal: {spec.goal_category}  step {t} {names[a]}  "
                                       f"d={info['privileged'].distance_to_goal:.2f} m"))
        if term or trunc:
            break
    env.close()
    verdict = "SUCCESS" if rec["success"] else f"FAIL: {rec['failure']}"
    last = frames[-1].copy()
    cv2.putText(last, verdict, (8, 60), cv2.FONT_HERSHEY_SIMPLEX, 0.8, (255, 0, 0), 2, cv2.LINE_AA)
    frames += [last] * fps
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(f".{out.stem}.tmp{out.suffix}")
    # even sizes for yuv420p
    hh, ww = (frames[0].shape[0] // 2) * 2, (frames[0].shape[1] // 2) * 2
    with imageio.get_writer(tmp, fps=fps, codec="libx264", macro_block_size=1) as w:
        for f in frames:
            w.append_data(np.ascontiguousarray(f[:hh, :ww]))
    tmp.replace(out)
    return out
