"""`ovon video`: replay a recorded episode (same seed + recorded actions = same trajectory) and write an
mp4 with RGB, depth and a top-down map (navigable area, path, goal viewpoints and goal objects).

Agents with a `debug_frame(size)` method (`ovon.agents.base.DebugView`, e.g. the modular agents) get a
fourth panel: a fresh agent built from the run's settings is fed the replayed observations and its
`debug_frame` is drawn after each decision (its maps, frontiers, value map, goal points, plan), beside the
truth. Its actions are checked against the record; where they differ (an agent that is not deterministic
given the episode seed) the panel stops and says so, and the video follows the record.
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import cv2
import imageio.v2 as imageio
import numpy as np

from ovon.atomic import atomic_write_path, check_output_path
from ovon.config.base import from_dict
from ovon.config.sim import SimConfig
from ovon.config.task import TaskConfig
from ovon.evaluate.results import read_records
from ovon.evaluate.runner import episode_seed
from ovon.runfolder import IDENTITY_FILE


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
        self.base = cv2.resize(
            img, (int(nav.shape[1] * self.scale), int(nav.shape[0] * self.scale)), interpolation=cv2.INTER_NEAREST
        )
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


class AgentView:
    """Replays the episode through a fresh agent and draws its `debug_frame` after each decision."""

    def __init__(self, agent, info: dict, h: int) -> None:
        from ovon.agents.base import is_privileged

        self.agent, self.h = agent, h
        self.privileged = is_privileged(agent)
        self.diverged: int | None = None  # step at which the agent's action differed from the record
        self.last: np.ndarray | None = None
        agent.reset(info)

    def step(self, t: int, obs: dict, inf: dict, recorded: int | None) -> np.ndarray:
        """Panel for the frame of step `t`: the agent acts on `obs` (when it has not diverged and an action
        was recorded there) and draws what it believes."""
        if self.diverged is None and recorded is not None:
            if self.privileged:
                obs = {**obs, "privileged": inf["privileged"]}
            action = int(self.agent.act(obs))
            if action != int(recorded):
                self.diverged = t
            img = self.agent.debug_frame(self.h)
            if img is not None:
                self.last = _fit(np.asarray(img, dtype=np.uint8), self.h)
        panel = self.last.copy() if self.last is not None else np.full((self.h, self.h, 3), 55, np.uint8)
        if self.diverged is not None:
            cv2.putText(
                panel,
                f"agent left the record after step {self.diverged}",
                (6, self.h - 8),
                cv2.FONT_HERSHEY_SIMPLEX,
                0.45,
                (255, 40, 40),
                1,
                cv2.LINE_AA,
            )
        return panel


def _agent_view(meta: dict, spec, ep_seed: int, sim: SimConfig, h: int) -> AgentView | None:
    """An AgentView when the run's agent has `debug_frame`, else None."""
    from ovon.agents import AgentError, load_agent_class, make_agent
    from ovon.evaluate.runner import episode_info

    cls = load_agent_class(meta["agent"])
    if not callable(getattr(cls, "debug_frame", None)):
        return None
    try:
        agent = make_agent(meta["agent"], **meta.get("agent_kwargs", {}))
    except Exception as e:  # noqa: BLE001 - the constructor is user code: one line, with the way out
        raise AgentError(
            f"agent {meta['agent']!r} of this run cannot be rebuilt for its debug panel "
            f"({type(e).__name__}: {' '.join(str(e).split())[:160]}); fix: pass --no-agent-view"
        ) from None
    return AgentView(agent, episode_info(spec, ep_seed, sim), h)


VIDEO_SUFFIXES = (".mp4", ".mkv", ".mov", ".avi")  # containers ffmpeg writes libx264 into


def run_input(run_dir: Path, meta: dict, key: str, given: str | None = None) -> str:
    """Where the run's input `key` ("data" or "scenes") is now. `given` (the caller's) wins. run.json keeps
    the path as `ovon evaluate` was given it: a relative one is relative to the folder that command ran
    in, not to where `ovon video` runs, so it is taken from run_identity.json, which records each input's
    absolute path (`ovon.runfolder.path_identity`). Run folders without one, and projects moved since
    (the recorded path gone), read it from here."""
    if given:
        return str(given)
    stored = str(meta.get(key) or "")
    if not stored or Path(stored).is_absolute():
        return stored
    try:
        identity = json.loads((run_dir / IDENTITY_FILE).read_text(encoding="utf-8"))
        recorded = str(identity["inputs"][key]["path"])
    except (OSError, ValueError, KeyError, TypeError):
        recorded = ""
    if recorded and Path(recorded).exists():
        return recorded
    if recorded and Path(stored).exists():  # the project moved with its run folders: run from its new root
        return stored
    if recorded:
        raise FileNotFoundError(
            f"{run_dir}/run.json: {key} {stored!r} was {recorded} when the evaluation ran "
            f"(relative to the folder it ran in), and that no longer exists; fix: put it back "
            f"at {recorded}, or pass its new path (`ovon video --{key} PATH`, "
            f"render_video({key}=...))"
        )
    if not Path(stored).exists():
        raise FileNotFoundError(
            f"{run_dir}/run.json: {key} {stored!r} is relative to the folder `ovon evaluate` "
            f"ran in and does not exist from {Path.cwd()}; fix: run `ovon video` from that "
            "folder"
        )
    return stored


def render_video(
    run_dir: str | Path,
    episode_id: str,
    out: str | Path,
    split: str | None = None,
    seed: int | None = None,
    fps: int = 8,
    scene: str | None = None,
    agent_view: bool = True,
    data: str | None = None,
    scenes: str | None = None,
) -> Path:
    """`agent_view`: add the agent's `debug_frame` panel when its class has one (see the module docstring).
    `data` / `scenes`: the episode dataset and scenes roots when they moved (default: the run's own,
    see `run_input`). `out` is checked before the episode is replayed (rendering it takes a while)."""
    from ovon.dataset.episodes import load_specs
    from ovon.env import make_objectnav

    out = check_output_path(
        out, "--out", expected="the path of an .mp4 file", example="episode.mp4", suffixes=VIDEO_SUFFIXES
    )
    run_dir = Path(run_dir)
    meta_path = run_dir / "run.json"
    if not meta_path.exists():
        raise FileNotFoundError(f"{run_dir} has no run.json: is it a folder written by `ovon evaluate`?")
    try:
        meta = json.loads(meta_path.read_text(encoding="utf-8"))
        if not isinstance(meta, dict):
            raise ValueError(f"holds a {type(meta).__name__}, not an object")
    except (ValueError, RecursionError) as e:
        raise ValueError(
            f"{meta_path} is unreadable ({type(e).__name__}); fix: re-run the `ovon evaluate` that wrote it"
        ) from None
    meta = {
        **meta,
        "data": run_input(run_dir, meta, "data", data),
        "scenes": run_input(run_dir, meta, "scenes", scenes),
    }
    recs = [
        r
        for r in read_records(run_dir)
        if str(r["episode_id"]) == str(episode_id)
        and (split is None or r["split"] == split)
        and (seed is None or int(r["seed"]) == seed)
        and (scene is None or scene in r["scene"])
    ]
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
    specs = [
        s
        for s in load_specs(meta["data"], meta["scenes"], rec["split"], None)
        if s.episode_id == str(episode_id) and s.scene_key == rec["scene"]
    ]
    if not specs:
        raise KeyError(f"episode {episode_id!r} of {rec['scene']} not found in {meta['data']}/{rec['split']}")
    spec = specs[0]
    sim = from_dict(SimConfig, meta["sim"])
    env = make_objectnav(episodes=[spec], sim=sim, task=from_dict(TaskConfig, meta["task"]), privileged=True)
    ep_seed = episode_seed(rec["seed"], spec.split, spec.episode_id, spec.scene_key)
    obs, info = env.reset(seed=ep_seed, options={"episode": spec})
    p = info["privileged"]
    goals = [(np.asarray(o.aabb_min), np.asarray(o.aabb_max)) for o in p.world.scene.objects if o.id in p.goal_ids]
    top = TopDown(p.grid, np.array([v.position for v in p.viewpoints]), goals, size=360)
    path = [p.state.position]
    frames = []
    h = 240
    actions = [int(a) for a in rec["actions"]]
    view = _agent_view(meta, spec, ep_seed, sim, h) if agent_view else None

    def frame(o, inf, text, t):
        rgb = _fit(o["rgb"], h)
        depth = _fit(_depth_to_rgb(o["depth"], sim.camera.max_depth), h)
        td = _fit(top.draw(path, inf["privileged"].state.yaw), h)
        panels = [rgb, depth, td]
        if view is not None:
            panels.append(view.step(t, o, inf, actions[t] if t < len(actions) else None))
        img = np.concatenate(panels, axis=1)
        bar = np.full((28, img.shape[1], 3), 255, np.uint8)
        cv2.putText(bar, text, (6, 20), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 0, 0), 1, cv2.LINE_AA)
        return np.concatenate([bar, img], axis=0)

    frames.append(frame(obs, info, f"goal: {spec.goal_category}  step 0  d={p.distance_to_goal:.2f} m", 0))
    names = ("STOP", "FORWARD", "LEFT", "RIGHT", "UP", "DOWN")
    for t, a in enumerate(actions, 1):
        obs, _, term, trunc, info = env.step(a)
        path.append(info["privileged"].state.position)
        frames.append(
            frame(
                obs,
                info,
                f"goal: {spec.goal_category}  step {t} {names[a]}  d={info['privileged'].distance_to_goal:.2f} m",
                t,
            )
        )
        if term or trunc:
            break
    env.close()
    if view is not None and view.diverged is not None:
        warnings.warn(
            f"{meta['agent']} replayed through a fresh agent chose another action than the record after "
            f"step {view.diverged} (not deterministic given the episode seed?): its panel stops there",
            stacklevel=2,
        )
    verdict = "SUCCESS" if rec["success"] else f"FAIL: {rec['failure']}"
    last = frames[-1].copy()
    cv2.putText(last, verdict, (8, 60), cv2.FONT_HERSHEY_SIMPLEX, 0.8, (255, 0, 0), 2, cv2.LINE_AA)
    frames += [last] * fps
    # even sizes for yuv420p
    hh, ww = (frames[0].shape[0] // 2) * 2, (frames[0].shape[1] // 2) * 2

    def encode(tmp: Path) -> None:
        with imageio.get_writer(tmp, fps=fps, codec="libx264", macro_block_size=1) as w:
            for f in frames:
                w.append_data(np.ascontiguousarray(f[:hh, :ww]))

    return atomic_write_path(out, encode)  # no half-written video left beside the old one
