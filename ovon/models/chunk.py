"""The chunk: N step sequences as a policy reads them, the one batch type of every learner (a rollout's
observations, an entry of DAgger's buffer, a BC batch; `ActorCritic.evaluate` reads it), and the image-batch
plumbing it is made of.

Why one type: PPO, DAgger and BC all feed the policy images, goals, previous actions and episode starts per
step; written three ways (a dataclass, positional tuples, dicts), each learner had its own slicing and joining.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import torch

# An image batch: precomputed embeddings (..., D) float, or raw frames {"rgb": (..., H, W, 3) uint8,
# "depth": (..., H, W) float} for a trainable CNN that lives inside the policy.
Images = torch.Tensor | dict[str, torch.Tensor]


@dataclass
class Chunk:
    """(N, L, ...) steps of N sequences. The first `prefix` steps are context: read (a transformer's window, the
    steps before an LSTM's memory is needed), their outputs dropped by `evaluate`, never trained on. `labels`
    cover the steps after the prefix. `context`: earlier steps kept as views of the chunks before this one
    (DAgger's buffer, no copy), joined in front by `with_context`."""

    images: Images
    goals: torch.Tensor  # (N, L, Dg)
    prevs: torch.Tensor  # (N, L) previous action of each step (-1 at an episode start)
    starts: torch.Tensor  # (N, L) bool: the step is the first of its episode
    labels: torch.Tensor | None = None  # (N, L - prefix): the expert's action per step (-1: none, padding)
    state0: Any = None  # the LSTM's (h, c) before the chunk (None: fresh, or a transformer)
    prefix: int = 0
    context: list[Chunk] = field(default_factory=list)

    @property
    def length(self) -> int:
        """Steps per sequence (L), prefix included."""
        return int(self.goals.shape[1])

    def observations(self) -> Chunk:
        """What the policy reads (images, goals, prevs, starts): the same tensors, nothing else."""
        return Chunk(self.images, self.goals, self.prevs, self.starts)

    def select(self, rows: torch.Tensor | slice = slice(None), lo: int = 0, hi: int | None = None) -> Chunk:
        """The observations of `rows` (an index tensor or a slice) at steps lo:hi (views for slices); the prefix
        steps among them stay context."""
        key = (rows, slice(lo, hi))
        return Chunk(
            map_images(self.images, lambda x: x[key]),
            self.goals[key],
            self.prevs[key],
            self.starts[key],
            prefix=max(0, self.prefix - lo),
        )

    def to(self, device: torch.device | str) -> Chunk:
        """Observations and labels on `device`; `state0` stays where it is (acting memory already lives on the
        policy's device, a buffered one on the CPU until its batch is joined)."""
        return Chunk(
            map_images(self.images, lambda x: x.to(device)),
            self.goals.to(device),
            self.prevs.to(device),
            self.starts.to(device),
            None if self.labels is None else self.labels.to(device),
            self.state0,
            self.prefix,
            self.context,
        )

    def with_context(self, prefix: int) -> Chunk:
        """This chunk after exactly `prefix` steps of its `context` (N, prefix + L, ...), labels kept. A context
        shorter than `prefix` (the first rollouts of a run) is padded in front with steps marked as episode
        starts, which nothing attends to: those chunks begin with every env's first step."""
        parts = [*self.context, self.observations()] if prefix > 0 else [self.observations()]
        seq = functools.reduce(_join_time, parts)
        missing = prefix - sum(p.length for p in parts[:-1])
        if missing > 0:
            seq = _join_time(seq.padding(missing), seq)
        return Chunk(seq.images, seq.goals, seq.prevs, seq.starts, self.labels, self.state0, prefix)

    def padding(self, n: int) -> Chunk:
        """n steps shaped like this chunk's first one, every one an episode start."""
        return Chunk(
            pad_time(self.images, n, False),
            pad_time(self.goals, n, False),
            pad_time(self.prevs, n, False),
            pad_time(self.starts, n, True),
        )

    def _fields(self) -> tuple:
        return self.images, self.goals, self.prevs, self.starts

    @staticmethod
    def cat(chunks: list[Chunk]) -> Chunk:
        """Chunks of equal length and prefix joined over sequences (rows); `state0` is left to the caller (a
        missing one means a fresh state, which only the policy can make)."""
        labels = [c.labels for c in chunks]
        return Chunk(
            cat_images([c.images for c in chunks]),
            torch.cat([c.goals for c in chunks]),
            torch.cat([c.prevs for c in chunks]),
            torch.cat([c.starts for c in chunks]),
            None if any(x is None for x in labels) else torch.cat(labels),
            prefix=chunks[0].prefix,
        )


def last_steps(parts: list[Chunk], n: int) -> list[Chunk]:
    """The last `n` steps (or all there are) of consecutive chunks' observations, as views (a chunk wholly
    inside them is kept as it is)."""
    out: list[Chunk] = []
    need = n
    for part in reversed(parts):
        if need <= 0:
            break
        k = part.length
        out.insert(0, part if k <= need else part.select(lo=k - need))
        need -= min(k, need)
    return out


def _join_time(a: Chunk, b: Chunk) -> Chunk:
    return Chunk(*(cat_time(x, y) for x, y in zip(a._fields(), b._fields())))


# -- image batches and (N, T, ...) step tensors ---------------------------------------------------------
def map_images(images: Images, fn: Callable[[torch.Tensor], torch.Tensor]) -> Images:
    return fn(images) if isinstance(images, torch.Tensor) else {k: fn(v) for k, v in images.items()}


def stack_images(items: list[Images], dim: int = 0) -> Images:
    if isinstance(items[0], torch.Tensor):
        return torch.stack(items, dim)
    return {k: torch.stack([x[k] for x in items], dim) for k in items[0]}


def cat_images(items: list[Images]) -> Images:
    """Concatenate along the first (env) dimension."""
    if isinstance(items[0], torch.Tensor):
        return torch.cat(items)
    return {k: torch.cat([x[k] for x in items]) for k in items[0]}


def cat_time(a, b):
    """Two (N, T, ...) step tensors (or dicts of them: CNN images) joined in time."""
    return {k: torch.cat([a[k], b[k]], 1) for k in a} if isinstance(a, dict) else torch.cat([a, b], 1)


def slice_time(x, lo, hi):
    """Steps lo:hi of (N, T, ...) step tensors (or dicts of them); a view."""
    return {k: v[:, lo:hi] for k, v in x.items()} if isinstance(x, dict) else x[:, lo:hi]


def pad_time(x, n: int, start: bool):
    """n steps of padding shaped like x's first step (starts: all True)."""
    if isinstance(x, dict):
        return {k: pad_time(v, n, start) for k, v in x.items()}
    first = x[:, :1]
    pad = torch.ones_like(first) if start else torch.zeros_like(first)
    return pad.expand(-1, n, *first.shape[2:]).clone()
