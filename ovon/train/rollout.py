"""Vectorised training environments in worker processes, with perception and expert labels computed
where the env lives.

Why in the worker: frozen encoders (oracle-vl, SigLIP) then run once per step in parallel, and only a
small embedding crosses the pipe; the expert (frontier or shortest-path) labels the visited state next
to the env that holds the ground truth (`privileged=True`). A trainable CNN cannot run there, so with
`encoder.image == "cnn"` the worker sends the frames instead.

Each env slot samples its episodes from its own list with its own seeded generator (a few episodes
per scene before switching, since loading a world is slow). Its full state - sampler, current episode
seed and the actions taken so far - is small, and `set_state` replays the episode to the same point,
so a resumed run continues exactly.
"""

from __future__ import annotations

import math
import multiprocessing as mp
import traceback
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import torch

from ovon.config.sim import SimConfig
from ovon.config.task import TaskConfig
from ovon.models.config import EncoderConfig
from ovon.task.episode import EpisodeSpec


@dataclass
class SlotConfig:
    """What one env slot needs (picklable: sent to a spawned worker)."""

    specs: list[EpisodeSpec]
    sim: SimConfig
    task: TaskConfig
    encoder: EncoderConfig
    text_table: dict[str, np.ndarray]
    expert: str | None  # "frontier" | "shortest-path" | None (no labels)
    seed: int
    scene_repeat: int = 4
    expert_cfg: Any = None  # FrontierExpertConfig / ShortestPathExpertConfig; None = the expert's defaults
    expert_viewpoint_radius: float = 0.0  # > 0: the expert aims at viewpoints this close to a goal box


@dataclass
class StepOut:
    image: Any  # (Di,) float32 embedding, or {"rgb": (H,W,3) uint8, "depth": (H,W) float32} for a CNN
    goal: np.ndarray  # (Dg,) float32 goal-text embedding
    label: int  # expert action for this observation's state (-1 without an expert)
    reward: float  # reward of the step that led here (0 after reset)
    done: bool  # the step that led here ended an episode (this observation starts a new one)
    first: bool  # this observation is the first of an episode
    metrics: dict | None = None  # metrics of the episode that just ended


def inner_viewpoints(p: Any, radius: float) -> list:
    """The goal viewpoints within `radius` m (horizontally) of a goal object's box, or all when none is.

    Why: success only needs any viewpoint (up to 1 m from the object), so an expert aiming at the nearest
    one stops at the outer edge of that band, where the object looks about as big as two steps earlier;
    a student that stops a step or two early then fails. Aiming at the inner viewpoints gives STOP labels
    where the goal fills the view, and an early STOP still lands inside the band. Evaluation is unchanged."""
    if radius <= 0:
        return list(p.viewpoints)
    boxes = [(o.aabb_min, o.aabb_max) for o in p.world.scene.objects if o.id in p.goal_ids]
    if not boxes:
        return list(p.viewpoints)

    def box_distance(v) -> float:
        x, z = float(v.position[0]), float(v.position[2])
        return min(math.hypot(max(lo[0] - x, 0.0, x - hi[0]), max(lo[2] - z, 0.0, z - hi[2])) for lo, hi in boxes)

    inner = [v for v in p.viewpoints if box_distance(v) <= radius]
    return inner or list(p.viewpoints)


def make_expert(name: str, cfg: Any = None):
    """The labelling expert named `name`, with its config `cfg` (None = defaults)."""
    if name == "frontier":
        from ovon.experts.config import FrontierExpertConfig
        from ovon.experts.frontier_expert import FrontierExpert

        return FrontierExpert(cfg or FrontierExpertConfig())
    if name == "shortest-path":
        from ovon.experts.config import ShortestPathExpertConfig
        from ovon.experts.shortest_path import ShortestPathExpert

        return ShortestPathExpert(cfg or ShortestPathExpertConfig())
    raise ValueError(f"unknown expert {name!r}; valid: frontier, shortest-path")


class EnvSlot:
    """One `ObjectNavEnv` (privileged) + its image encoder + its expert labeller + its episode sampler."""

    def __init__(self, cfg: SlotConfig) -> None:
        from ovon.sim.env import ObjectNavEnv
        from ovon.train.common import TableTextEncoder

        if not cfg.specs:
            raise ValueError("an env slot needs at least one episode")
        self.cfg = cfg
        self.env = ObjectNavEnv(episodes=cfg.specs[:1], sim=cfg.sim, task=cfg.task, privileged=True)
        self.text = TableTextEncoder(cfg.text_table, cfg.encoder)
        self.encoder = None
        if cfg.encoder.image != "cnn":
            from ovon.models.encoders import make_image_encoder

            self.encoder = make_image_encoder(cfg.encoder, self.text)
        self.expert = make_expert(cfg.expert, cfg.expert_cfg) if cfg.expert else None
        self.by_scene: dict[str, list[int]] = {}
        for i, s in enumerate(cfg.specs):
            self.by_scene.setdefault(s.scene, []).append(i)
        self.scenes = sorted(self.by_scene)
        self.rng = np.random.default_rng(cfg.seed)
        self.scene: str | None = None
        self.remaining = 0
        self.spec_index = -1
        self.ep_seed = 0
        self.actions: list[int] = []
        self.skipped = 0  # episodes whose reset failed (no reachable goal on the start floor)
        self._goal = np.zeros(0, np.float32)

    # -- sampling / state ------------------------------------------------------------------
    def _sample(self) -> tuple[int, int]:
        if self.remaining <= 0 or self.scene is None:
            self.scene = self.scenes[int(self.rng.integers(len(self.scenes)))]
            self.remaining = max(1, self.cfg.scene_repeat)
        self.remaining -= 1
        idx = self.by_scene[self.scene]
        return idx[int(self.rng.integers(len(idx)))], int(self.rng.integers(2**31 - 1))

    def get_state(self) -> dict:
        return {"rng": self.rng.bit_generator.state, "scene": self.scene, "remaining": self.remaining,
                "spec_index": self.spec_index, "ep_seed": self.ep_seed, "actions": list(self.actions),
                "skipped": self.skipped}

    def set_state(self, state: dict) -> StepOut:
        """Restore the sampler and replay the current episode's actions (deterministic env + expert)."""
        self.rng.bit_generator.state = state["rng"]
        self.scene, self.remaining, self.skipped = state["scene"], state["remaining"], state["skipped"]
        out = self._start(state["spec_index"], state["ep_seed"])
        for a in state["actions"]:
            out = self.step(a)
        return out

    # -- stepping --------------------------------------------------------------------------
    def _start(self, spec_index: int, ep_seed: int) -> StepOut:
        spec = self.cfg.specs[spec_index]
        obs, _ = self.env.reset(seed=ep_seed, options={"episode": spec})
        self.spec_index, self.ep_seed, self.actions = spec_index, ep_seed, []
        p = self.env.unwrapped.privileged()
        if self.encoder is not None and hasattr(self.encoder, "set_scene"):
            self.encoder.set_scene({o.id: o.category for o in p.world.scene.objects if o.category})
            if hasattr(self.encoder, "reseed"):
                self.encoder.reseed(ep_seed)  # oracle noise stream per episode: replayable
        self._goal = self.text.encode([obs["goal"]])[0].numpy()
        label = -1
        if self.expert is not None:
            vps = inner_viewpoints(p, self.cfg.expert_viewpoint_radius)
            self.expert.reset(p.grid, [(v.position, v.yaw) for v in vps], p.state)
            label = int(self.expert.act(p.state))
        return StepOut(self._image(obs), self._goal, label, 0.0, False, True)

    def reset(self) -> StepOut:
        """Start the next sampled episode (episodes whose set-up fails are skipped and counted)."""
        for _ in range(100):
            index, seed = self._sample()
            try:
                return self._start(index, seed)
            except ValueError:
                self.skipped += 1
        raise RuntimeError("100 episodes in a row could not be set up; check the episode list")

    def _image(self, obs: dict) -> Any:
        if self.encoder is None:
            return {"rgb": obs["rgb"], "depth": obs["depth"]}
        return self.encoder.encode({"rgb": obs["rgb"][None], "depth": obs["depth"][None],
                                    "semantic": obs["semantic"][None],
                                    "collided": np.array([obs.get("collided", 0)])})[0].numpy()

    def step(self, action: int, auto_reset: bool = True) -> StepOut:
        """Step; at an episode end the returned observation is the next episode's first (auto-reset),
        or the final one with `auto_reset=False` (recording)."""
        action = int(action)
        obs, reward, terminated, truncated, info = self.env.step(action)
        self.actions.append(action)
        if terminated or truncated:
            metrics = dict(info["metrics"])
            spec = self.cfg.specs[self.spec_index]
            metrics.update(scene=spec.scene, goal=spec.goal_category, episode_id=spec.episode_id)
            if not auto_reset:
                return StepOut(self._image(obs), self._goal, -1, float(reward), True, False, metrics)
            out = self.reset()
            out.reward, out.done, out.metrics = float(reward), True, metrics
            return out
        label = -1
        if self.expert is not None:
            label = int(self.expert.act(self.env.unwrapped.privileged().state, last_action=action))
        return StepOut(self._image(obs), self._goal, label, float(reward), False, False)

    def close(self) -> None:
        self.env.close()


# ----- worker processes ---------------------------------------------------------------------------
def _worker_main(conn, slot_cfgs: list[SlotConfig]) -> None:
    from ovon.parallel import init_worker

    init_worker()
    slots: list[EnvSlot] = []
    try:
        slots = [EnvSlot(c) for c in slot_cfgs]
        conn.send(("ok", None))
        while True:
            cmd, arg = conn.recv()
            if cmd == "reset":
                conn.send(("ok", [s.reset() for s in slots]))
            elif cmd == "step":
                conn.send(("ok", [s.step(a) for s, a in zip(slots, arg)]))
            elif cmd == "get_state":
                conn.send(("ok", [s.get_state() for s in slots]))
            elif cmd == "set_state":
                conn.send(("ok", [s.set_state(st) for s, st in zip(slots, arg)]))
            elif cmd == "close":
                conn.send(("ok", None))
                break
            else:
                conn.send(("error", f"unknown command {cmd!r}"))
    except (KeyboardInterrupt, EOFError):
        pass
    except Exception:  # report to the parent instead of dying silently
        try:
            conn.send(("error", traceback.format_exc()))
        except (BrokenPipeError, EOFError):
            pass
    finally:
        for s in slots:
            s.close()
        conn.close()


@dataclass
class Batch:
    """One observation per env (tensors on CPU)."""

    image: Any  # (N, Di) float32 or {"rgb": (N,H,W,3) uint8, "depth": (N,H,W)}
    goal: torch.Tensor  # (N, Dg)
    label: torch.Tensor  # (N,) long, -1 without an expert
    reward: torch.Tensor  # (N,) float32
    done: torch.Tensor  # (N,) bool
    first: torch.Tensor  # (N,) bool
    metrics: list[dict] = field(default_factory=list)

    @staticmethod
    def collate(outs: list[StepOut]) -> Batch:
        if isinstance(outs[0].image, dict):
            image = {k: torch.from_numpy(np.stack([o.image[k] for o in outs])) for k in outs[0].image}
        else:
            image = torch.from_numpy(np.stack([o.image for o in outs]).astype(np.float32))
        return Batch(
            image=image,
            goal=torch.from_numpy(np.stack([o.goal for o in outs]).astype(np.float32)),
            label=torch.tensor([o.label for o in outs], dtype=torch.long),
            reward=torch.tensor([o.reward for o in outs], dtype=torch.float32),
            done=torch.tensor([o.done for o in outs], dtype=torch.bool),
            first=torch.tensor([o.first for o in outs], dtype=torch.bool),
            metrics=[o.metrics for o in outs if o.metrics is not None],
        )


def split_specs(specs: list[EpisodeSpec], n: int) -> list[list[EpisodeSpec]]:
    """Scenes round-robin over `n` slots (each slot keeps few scenes: fewer world reloads); with fewer
    scenes than slots, slots share scenes and split their episodes."""
    by_scene: dict[str, list[EpisodeSpec]] = {}
    for s in specs:
        by_scene.setdefault(s.scene, []).append(s)
    scenes = sorted(by_scene)
    if len(scenes) >= n:
        return [[s for sc in scenes[i::n] for s in by_scene[sc]] for i in range(n)]
    out = []
    for i in range(n):
        sc = by_scene[scenes[i % len(scenes)]]
        share = sc[(i // len(scenes)) :: max(1, -(-n // len(scenes)))]
        out.append(share or sc)
    return out


class VecEnv:
    """`num_envs` env slots, in this process (`workers=0`) or spread over `workers` spawned processes."""

    def __init__(
        self,
        specs: list[EpisodeSpec],
        num_envs: int,
        sim: SimConfig,
        task: TaskConfig,
        encoder: EncoderConfig,
        text_table: dict[str, Any],
        expert: str | None,
        seed: int,
        workers: int = -1,
        scene_repeat: int = 4,
        expert_cfg: Any = None,
        expert_viewpoint_radius: float = 0.0,
    ) -> None:
        table = {k: np.asarray(v, dtype=np.float32) for k, v in text_table.items()}
        self.num_envs = num_envs
        cfgs = [
            SlotConfig(part, sim, task, encoder, table, expert, seed * 10007 + i, scene_repeat, expert_cfg,
                       expert_viewpoint_radius)
            for i, part in enumerate(split_specs(specs, num_envs))
        ]
        workers = num_envs if workers < 0 else min(workers, num_envs)
        self.local: list[EnvSlot] = []
        self.procs: list[Any] = []
        self.conns: list[Any] = []
        self.groups: list[list[int]] = []
        if workers == 0:
            self.local = [EnvSlot(c) for c in cfgs]
            return
        ctx = mp.get_context("spawn")
        for w in range(workers):
            idx = list(range(w, num_envs, workers))
            parent, child = ctx.Pipe()
            p = ctx.Process(target=_worker_main, args=(child, [cfgs[i] for i in idx]), daemon=True)
            p.start()
            child.close()
            self.procs.append(p)
            self.conns.append(parent)
            self.groups.append(idx)
        for c in self.conns:
            self._recv(c)

    @staticmethod
    def _recv(conn) -> Any:
        status, payload = conn.recv()
        if status != "ok":
            raise RuntimeError(f"env worker failed:\n{payload}")
        return payload

    def _call(self, cmd: str, args: list | None = None) -> list:
        """Run `cmd` on every slot (per-slot `args`), results in slot order."""
        if self.local:
            fn = {"reset": lambda s, a: s.reset(), "step": lambda s, a: s.step(a),
                  "get_state": lambda s, a: s.get_state(), "set_state": lambda s, a: s.set_state(a)}[cmd]
            return [fn(s, None if args is None else args[i]) for i, s in enumerate(self.local)]
        for conn, idx in zip(self.conns, self.groups):
            conn.send((cmd, None if args is None else [args[i] for i in idx]))
        out: list = [None] * self.num_envs
        for conn, idx in zip(self.conns, self.groups):
            for i, r in zip(idx, self._recv(conn)):
                out[i] = r
        return out

    def reset(self) -> Batch:
        return Batch.collate(self._call("reset"))

    def step(self, actions: torch.Tensor | np.ndarray) -> Batch:
        acts = [int(a) for a in np.asarray(actions).reshape(-1)]
        return Batch.collate(self._call("step", acts))

    def get_state(self) -> list[dict]:
        return self._call("get_state")

    def set_state(self, states: list[dict]) -> Batch:
        if len(states) != self.num_envs:
            raise ValueError(f"saved env state has {len(states)} envs, this run has {self.num_envs}")
        return Batch.collate(self._call("set_state", states))

    def close(self) -> None:
        for s in self.local:
            s.close()
        self.local = []
        for c in self.conns:
            try:
                c.send(("close", None))
                c.recv()
            except (BrokenPipeError, EOFError, OSError):
                pass
            c.close()
        for p in self.procs:
            p.join(timeout=10)
            if p.is_alive():
                p.terminate()
        self.conns, self.procs = [], []

    def __enter__(self) -> VecEnv:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def make_vec_env(cfg, specs: list[EpisodeSpec], task: TaskConfig, text_table: dict, label: bool, rank: int) -> VecEnv:
    """The trainer's envs from a `TrainConfig` (seeded by config seed and rank)."""
    return VecEnv(specs, cfg.num_envs, cfg.sim, task, cfg.encoder, text_table,
                  cfg.expert if label else None, seed=cfg.seed * 1000 + rank,
                  workers=cfg.env_workers, scene_repeat=cfg.scene_repeat, expert_cfg=expert_config(cfg),
                  expert_viewpoint_radius=cfg.expert_viewpoint_radius_m)


def expert_config(cfg) -> Any:
    """The `TrainConfig`'s config for its labelling expert."""
    return cfg.frontier_expert if cfg.expert == "frontier" else cfg.shortest_path_expert
