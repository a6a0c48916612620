"""Decoder-only transformer core (LLaMA-style block) with a sliding-window key/value cache.

Why this design (docs/spec.md#end-to-end-policy): 4 blocks of RMSNorm -> causal self-attention with rotary positions ->
RMSNorm -> SiLU-gated MLP, no dropout, context 100 steps.

Position and masking conventions (shared by `forward` and the acting paths, so they agree exactly):
- A token's RoPE position is its step index since its episode start (absolute, it keeps increasing
  past the window). RoPE scores depend only on position differences, so absolute positions are as
  good as window-relative ones and cached keys never need re-rotation.
- Step t attends to steps s with s <= t, s in the same episode and t - s < context (a sliding window
  of `context` steps, itself included), in every layer.
- `step` with the KV cache ("kv" acting) keeps each layer's keys/values of the last `context` steps
  in a ring buffer. It equals `forward` over the whole episode under the mask above. Beyond the
  window that is *not* the same as a fresh forward over only the last `context` steps: a layer-l key
  at step s was computed while s could still see its own window, so the receptive field grows by
  `context` per layer (as in any sliding-window KV cache, e.g. Mistral).
- `RecomputeState` acting ("recompute") stores the last `context` projected inputs and re-runs the
  window every step: it equals a fresh forward over the last `context` steps (with the same absolute
  positions), i.e. what training on chunks of `context` steps sees, at O(context^2) cost per step.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
import torch.nn.functional as F
from torch import nn


def rope_cos_sin(positions: torch.Tensor, head_dim: int, base: float) -> tuple[torch.Tensor, torch.Tensor]:
    """cos/sin (..., head_dim/2) for integer positions, computed in float64 for exactness."""
    half = head_dim // 2
    inv = base ** (-torch.arange(half, dtype=torch.float64, device=positions.device) * 2.0 / head_dim)
    ang = positions.to(torch.float64)[..., None] * inv
    return ang.cos(), ang.sin()


def rope_tables(cos: torch.Tensor, sin: torch.Tensor, dtype: torch.dtype) -> tuple[torch.Tensor, torch.Tensor]:
    """cos/sin (B, T, d/2) -> (B, 1, T, d/2) in `dtype`: what `apply_rope` multiplies by, made once per
    forward (not per layer and per q / k)."""
    return cos[:, None].to(dtype), sin[:, None].to(dtype)


def apply_rope(x: torch.Tensor, cos: torch.Tensor, sin: torch.Tensor) -> torch.Tensor:
    """Rotate-half RoPE. x (..., B, h, T, d); cos/sin (B, 1, T, d/2) in x's dtype (`rope_tables`)."""
    x1, x2 = x.chunk(2, dim=-1)
    return torch.cat([x1 * cos - x2 * sin, x1 * sin + x2 * cos], dim=-1)


class Attention(nn.Module):
    """Multi-head causal self-attention with RoPE (no biases, as LLaMA)."""

    def __init__(self, hidden: int, heads: int) -> None:
        super().__init__()
        if hidden % heads or (hidden // heads) % 2:
            raise ValueError(f"hidden {hidden} must split into {heads} heads of even size")
        self.heads = heads
        self.head_dim = hidden // heads
        self.qkv = nn.Linear(hidden, 3 * hidden, bias=False)
        self.out = nn.Linear(hidden, hidden, bias=False)

    def _qkv(self, x: torch.Tensor, cos: torch.Tensor, sin: torch.Tensor):
        b, t, _ = x.shape
        qkv = self.qkv(x).view(b, t, 3, self.heads, self.head_dim).permute(2, 0, 3, 1, 4)
        q, k = apply_rope(qkv[:2], cos, sin)  # queries and keys rotated in one go (elementwise: the same numbers)
        return q, k, qkv[2]

    def forward(self, x: torch.Tensor, cos: torch.Tensor, sin: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        q, k, v = self._qkv(x, cos, sin)
        if q.device.type == "cpu" and torch.is_autocast_enabled("cpu"):
            # bfloat16 training on a CPU: the bf16 flash-attention backward is ~5x slower than float32's
            # (measured: 28 vs 5 ms per layer on cpu-small's DAgger batch), so attention runs in float32
            with torch.autocast("cpu", enabled=False):
                y = F.scaled_dot_product_attention(q.float(), k.float(), v.float(), attn_mask=mask).to(q.dtype)
        else:
            y = F.scaled_dot_product_attention(q, k, v, attn_mask=mask)
        return self.out(y.transpose(1, 2).reshape(x.shape))

    def step(
        self,
        x: torch.Tensor,
        cos: torch.Tensor,
        sin: torch.Tensor,
        k_cache: torch.Tensor,
        v_cache: torch.Tensor,
        slot: int,
        valid: torch.Tensor,
    ) -> torch.Tensor:
        """x (B,1,H); writes this step's key/value into `slot` of the caches (B,h,W,d) in place."""
        q, k, v = self._qkv(x, cos, sin)
        k_cache[:, :, slot] = k[:, :, 0]
        v_cache[:, :, slot] = v[:, :, 0]
        y = F.scaled_dot_product_attention(q, k_cache, v_cache, attn_mask=valid[:, None, None, :])
        return self.out(y.transpose(1, 2).reshape(x.shape))


class GatedMLP(nn.Module):
    """SiLU-gated MLP: w2(silu(w1 x) * w3 x)."""

    def __init__(self, hidden: int, mlp: int) -> None:
        super().__init__()
        self.w1 = nn.Linear(hidden, mlp, bias=False)
        self.w3 = nn.Linear(hidden, mlp, bias=False)
        self.w2 = nn.Linear(mlp, hidden, bias=False)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.w2(F.silu(self.w1(x)) * self.w3(x))


class Block(nn.Module):
    """Pre-norm LLaMA block."""

    def __init__(self, hidden: int, heads: int, mlp: int, eps: float) -> None:
        super().__init__()
        self.norm1 = nn.RMSNorm(hidden, eps=eps)
        self.attn = Attention(hidden, heads)
        self.norm2 = nn.RMSNorm(hidden, eps=eps)
        self.mlp = GatedMLP(hidden, mlp)

    def forward(self, x, cos, sin, mask):
        x = x + self.attn(self.norm1(x), cos, sin, mask)
        return x + self.mlp(self.norm2(x))

    def step(self, x, cos, sin, k_cache, v_cache, slot, valid):
        x = x + self.attn.step(self.norm1(x), cos, sin, k_cache, v_cache, slot, valid)
        return x + self.mlp(self.norm2(x))


@dataclass
class KVState:
    """Sliding-window KV cache for B environments (updated in place by `TransformerCore.step`).

    k, v: (layers, B, heads, context, head_dim) rotated keys / values in a ring buffer;
    valid: (B, context) which slots hold steps of the current episode; pos: (B,) the next step's
    position (steps since episode start); slot: the ring index the next step writes.
    """

    k: torch.Tensor
    v: torch.Tensor
    valid: torch.Tensor
    pos: torch.Tensor
    slot: int = 0


@dataclass
class RecomputeState:
    """Window of the last `context` projected inputs, oldest first (B, context, H), for "recompute" acting."""

    x: torch.Tensor
    pos: torch.Tensor  # (B, context) positions of the stored steps
    valid: torch.Tensor  # (B, context)
    next_pos: torch.Tensor  # (B,)


def positions_from_starts(episode_starts: torch.Tensor) -> torch.Tensor:
    """(B,T) bool -> (B,T) long steps since the last episode start (or since the chunk start)."""
    b, t = episode_starts.shape
    idx = torch.arange(t, device=episode_starts.device).expand(b, t)
    last = torch.where(episode_starts, idx, torch.zeros_like(idx)).cummax(dim=1).values
    return idx - last


def chunk_mask(episode_starts: torch.Tensor, context: int) -> torch.Tensor:
    """(B,T) bool -> (B,1,T,T) bool attention mask: causal, same episode, within `context` steps."""
    b, t = episode_starts.shape
    seg = episode_starts.long().cumsum(1)
    idx = torch.arange(t, device=episode_starts.device)
    diff = idx[:, None] - idx[None, :]
    causal = (diff >= 0) & (diff < context)
    same = seg[:, :, None] == seg[:, None, :]
    return (causal[None] & same)[:, None]


class TransformerCore(nn.Module):
    """Stack of LLaMA blocks over projected per-step inputs (B, T, hidden) -> (B, T, hidden)."""

    def __init__(
        self,
        hidden: int = 512,
        layers: int = 4,
        heads: int = 8,
        mlp: int = 1024,
        context: int = 100,
        rope_base: float = 10000.0,
        eps: float = 1e-6,
    ) -> None:
        super().__init__()
        self.hidden = hidden
        self.out_dim = hidden
        self.heads = heads
        self.head_dim = hidden // heads
        self.context = context
        self.rope_base = rope_base
        self.blocks = nn.ModuleList(Block(hidden, heads, mlp, eps) for _ in range(layers))
        self.norm = nn.RMSNorm(hidden, eps=eps)

    def _run(self, x: torch.Tensor, positions: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        cos, sin = rope_tables(*rope_cos_sin(positions, self.head_dim, self.rope_base), x.dtype)
        for blk in self.blocks:
            x = blk(x, cos, sin, mask)
        return self.norm(x)

    def forward(
        self,
        x: torch.Tensor,
        episode_starts: torch.Tensor | None = None,
        positions: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """x (B,T,H); episode_starts (B,T) bool (True = first step of an episode); positions (B,T)
        long (default: steps since the last start inside the chunk)."""
        b, t, _ = x.shape
        if episode_starts is None:
            episode_starts = torch.zeros(b, t, dtype=torch.bool, device=x.device)
        episode_starts = episode_starts.bool()
        if positions is None:
            positions = positions_from_starts(episode_starts)
        return self._run(x, positions, chunk_mask(episode_starts, self.context))

    # ----- online acting -----
    def init_state(
        self, batch_size: int, device: torch.device | str | None = None, mode: str = "kv"
    ) -> KVState | RecomputeState:
        p = next(self.parameters())
        device = device or p.device
        w = self.context
        if mode == "recompute":
            return RecomputeState(
                x=torch.zeros(batch_size, w, self.hidden, device=device, dtype=p.dtype),
                pos=torch.zeros(batch_size, w, dtype=torch.long, device=device),
                valid=torch.zeros(batch_size, w, dtype=torch.bool, device=device),
                next_pos=torch.zeros(batch_size, dtype=torch.long, device=device),
            )
        if mode != "kv":
            raise ValueError(f"unknown act mode {mode!r}; valid: kv, recompute")
        shape = (len(self.blocks), batch_size, self.heads, w, self.head_dim)
        return KVState(
            k=torch.zeros(shape, device=device, dtype=p.dtype),
            v=torch.zeros(shape, device=device, dtype=p.dtype),
            valid=torch.zeros(batch_size, w, dtype=torch.bool, device=device),
            pos=torch.zeros(batch_size, dtype=torch.long, device=device),
        )

    def step(
        self, x: torch.Tensor, state: KVState | RecomputeState, done_mask: torch.Tensor | None = None
    ) -> tuple[torch.Tensor, KVState | RecomputeState]:
        """One step for B envs: x (B,H); done_mask (B,) True = this step starts a new episode
        (that env's window is cleared first). Returns (B,H) and the state (updated in place)."""
        if done_mask is not None:
            done = done_mask.to(device=x.device, dtype=torch.bool)
            state.valid.masked_fill_(done[:, None], False)
            if isinstance(state, KVState):
                state.pos.masked_fill_(done, 0)
            else:
                state.next_pos.masked_fill_(done, 0)
        if isinstance(state, RecomputeState):
            return self._step_recompute(x, state)
        slot = state.slot
        state.valid[:, slot] = True
        cos, sin = rope_tables(*rope_cos_sin(state.pos[:, None], self.head_dim, self.rope_base), x.dtype)
        h = x[:, None]
        for i, blk in enumerate(self.blocks):
            h = blk.step(h, cos, sin, state.k[i], state.v[i], slot, state.valid)
        state.pos += 1
        state.slot = (slot + 1) % self.context
        return self.norm(h[:, 0]), state

    def _step_recompute(self, x: torch.Tensor, state: RecomputeState) -> tuple[torch.Tensor, RecomputeState]:
        state.x = torch.cat([state.x[:, 1:], x[:, None]], 1)
        state.pos = torch.cat([state.pos[:, 1:], state.next_pos[:, None]], 1)
        state.valid = torch.cat([state.valid[:, 1:], torch.ones_like(state.valid[:, :1])], 1)
        state.next_pos = state.next_pos + 1
        w = self.context
        idx = torch.arange(w, device=x.device)
        causal = idx[:, None] >= idx[None, :]
        both = state.valid[:, :, None] & state.valid[:, None, :]
        mask = (causal[None] & both) | torch.eye(w, dtype=torch.bool, device=x.device)[None]
        y = self._run(state.x, state.pos, mask[:, None])
        return y[:, -1], state
