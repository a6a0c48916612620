"""LSTM core: the RNN baseline of docs/spec.md#end-to-end-policy (same inputs and heads as the transformer).

Why `matched_lstm_hidden`: the paper compares against "a 4-layer LSTM of similar parameter count",
so the width is solved from the transformer core's count instead of being guessed. With the paper
preset (hidden 512, 4 layers, MLP 1024) the transformer core has 10,490,368 parameters and the
matched LSTM (input 512, 4 layers) has width 576 and 10,487,808 parameters (-0.02%).
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

import torch
from torch import nn


def transformer_core_params(hidden: int, layers: int, mlp: int) -> int:
    """Parameters of `TransformerCore` (qkv + out + gated MLP + 2 RMSNorms per block + final norm)."""
    return layers * (4 * hidden * hidden + 3 * hidden * mlp + 2 * hidden) + hidden


def lstm_params(input_dim: int, hidden: int, layers: int) -> int:
    """Parameters of `torch.nn.LSTM` (two bias vectors per layer, as PyTorch has)."""
    first = 4 * hidden * (input_dim + hidden + 2)
    rest = 4 * hidden * (2 * hidden + 2)
    return first + (layers - 1) * rest


def matched_lstm_hidden(input_dim: int, layers: int, target_params: int) -> int:
    """Smallest-error LSTM width whose parameter count matches `target_params`."""
    best, best_err = 1, None
    for h in range(1, 8192):
        err = abs(lstm_params(input_dim, h, layers) - target_params)
        if best_err is None or err < best_err:
            best, best_err = h, err
        elif lstm_params(input_dim, h, layers) > target_params:
            break
    return best


LSTMState = tuple[torch.Tensor, torch.Tensor]


@contextmanager
def _onednn_off(device: torch.device) -> Iterator[None]:
    """Single-step CPU LSTM is ~5x faster without oneDNN (docs/spec.md#platform-notes: ~1 ms vs ~10 ms)."""
    if device.type != "cpu" or not torch.backends.mkldnn.enabled:
        yield
        return
    torch.backends.mkldnn.enabled = False
    try:
        yield
    finally:
        torch.backends.mkldnn.enabled = True


class LSTMCore(nn.Module):
    """Multi-layer LSTM over projected per-step inputs, reset at episode starts."""

    def __init__(self, input_dim: int, hidden: int, layers: int) -> None:
        super().__init__()
        self.out_dim = hidden
        self.layers = layers
        self.lstm = nn.LSTM(input_dim, hidden, num_layers=layers, batch_first=True)

    def init_state(self, batch_size: int, device: torch.device | str | None = None, mode: str = "") -> LSTMState:
        p = next(self.parameters())
        shape = (self.layers, batch_size, self.out_dim)
        dev = device or p.device
        return torch.zeros(shape, device=dev, dtype=p.dtype), torch.zeros(shape, device=dev, dtype=p.dtype)

    def forward(
        self,
        x: torch.Tensor,
        episode_starts: torch.Tensor | None = None,
        state: LSTMState | None = None,
    ) -> tuple[torch.Tensor, LSTMState]:
        """x (B,T,I) -> (B,T,H) and the final (h, c). The state is zeroed for an env at each of its
        episode starts (runs the LSTM segment by segment between start times)."""
        if x.device.type == "cpu" and torch.is_autocast_enabled("cpu"):
            # `learn_dtype=bfloat16` on a CPU: torch's bfloat16 LSTM gave results that depended on a thread
            # running beside it (`dagger.overlap`'s acting), so a run did not repeat; float32 repeats exactly
            with torch.autocast("cpu", enabled=False):
                return self.forward(x.float(), episode_starts, state)
        b, t, _ = x.shape
        h, c = state if state is not None else self.init_state(b, x.device)
        if episode_starts is None:
            y, (h, c) = self.lstm(x, (h, c))
            return y, (h, c)
        starts = episode_starts.bool()
        # one device->host copy for all cut points (per-step checks would sync a GPU once per step)
        cuts = [0] + [i + 1 for i in starts[:, 1:].any(0).nonzero().flatten().tolist()] + [t]
        outs = []
        for a, e in zip(cuts[:-1], cuts[1:]):
            keep = (~starts[:, a]).to(h.dtype)[None, :, None]
            h, c = h * keep, c * keep
            y, (h, c) = self.lstm(x[:, a:e], (h, c))
            outs.append(y)
        return torch.cat(outs, 1), (h, c)

    def step(
        self, x: torch.Tensor, state: LSTMState, done_mask: torch.Tensor | None = None
    ) -> tuple[torch.Tensor, LSTMState]:
        """x (B,I); done_mask (B,) True = this step starts a new episode (state zeroed first)."""
        starts = None if done_mask is None else done_mask.bool()[:, None]
        with _onednn_off(x.device):
            y, new_state = self.forward(x[:, None], starts, state)
        return y[:, 0], new_state
