"""Fine-tuning an imitation policy with PPO (BC->RL, DAgger->RL; `ovon train --algo ppo --init CKPT`): a
re-initialised critic, the sparse reward, and the fine-tune schedule of docs/spec.md#fine-tune-schedule, as
one component that `train_ppo` calls through a few hooks (from scratch they change nothing).

Schedule (updates, all multiplied by `finetune.scale`): critic lr `critic_lr` until `critic_decay_start`,
then linear to `critic_lr_final` at `critic_decay_end`; actor + core + input projection frozen (lr 0) until
`actor_unfreeze` (and, with `critic_warmup_ev`, until the critic explains that much of the returns'
variance), then linear warm-up from 0 to `actor_lr` at `actor_warmup_end`; the prev-action embedding is
frozen throughout. `finetune.anchor` adds a decaying term that keeps the imitation policy: cross-entropy to
the expert's online labels, or KL to the frozen initial policy. `finetune.critic=separate` learns the value
with its own copy of the initial network.
"""

from __future__ import annotations

from typing import Any

import torch

from ovon.models.chunk import Chunk
from ovon.train import distributed as dist
from ovon.train.batches import imitation_loss
from ovon.train.checkpoint import to_device
from ovon.train.config import FinetuneConfig, TrainConfig


def finetune_lrs(ft: FinetuneConfig, update: int) -> tuple[float, float]:
    """(critic lr, actor lr) at `update` (0-based) of the fine-tune schedule."""
    s = ft.scale

    def ramp(u: float, a: float, b: float) -> float:
        if b <= a:  # a step at b (the config allows start == end)
            return 1.0 if u >= b else 0.0
        return min(1.0, max(0.0, (u - a) / (b - a)))

    critic = ft.critic_lr + ramp(update, ft.critic_decay_start * s, ft.critic_decay_end * s) * (
        ft.critic_lr_final - ft.critic_lr
    )
    if update < ft.actor_unfreeze * s:
        actor = 0.0
    else:
        actor = ft.actor_lr * (
            ramp(update, ft.actor_unfreeze * s, ft.actor_warmup_end * s)
            if ft.actor_warmup_end > ft.actor_unfreeze
            else 1.0
        )
    return critic, actor


def anchor_weight(ft: FinetuneConfig, update: int) -> float:
    """Weight of the imitation anchor at `update` (0-based): anchor_coef decaying linearly to 0."""
    if ft.anchor == "none":
        return 0.0
    if ft.anchor_decay_updates <= 0:
        return ft.anchor_coef
    return ft.anchor_coef * max(0.0, 1.0 - update / (ft.anchor_decay_updates * ft.scale))


def kl_to(ref_logits: torch.Tensor, logits: torch.Tensor) -> torch.Tensor:
    """Mean KL(softmax(ref) || softmax(logits)) over the leading dims."""
    ref = torch.log_softmax(ref_logits, -1)
    return (ref.exp() * (ref - torch.log_softmax(logits, -1))).sum(-1).mean()


def index_state(state: Any, rows: torch.Tensor) -> Any:
    """The LSTM (h, c) of some envs (None stays None)."""
    return None if state is None else tuple(s[:, rows] for s in state)


def reference_logits(reference, chunk: Chunk, steps: int, state: Any) -> tuple[torch.Tensor, Any]:
    """The frozen initial policy's logits on the chunk's `steps` steps after its prefix, and its memory after
    them. An LSTM reference needs its own (h, c) carried from chunk to chunk: the policy's acting state is
    what the *fine-tuned* LSTM remembers, and read by the reference it gives logits that drift away from the
    initial policy's (an anchor to something neither policy would do). A transformer keeps no state (None):
    the prefix is its memory."""
    n = chunk.prefix + steps  # the bootstrap observation after the chunk is the next chunk's first step
    logits, _, state = reference.evaluate(chunk.select(hi=n), state)
    return logits, state


def critic_values(critic, chunk: Chunk, steps: int, state: Any) -> tuple[torch.Tensor, Any]:
    """A separate critic's values on the chunk's `steps` steps after its prefix and on the bootstrap
    observation after them, and its memory at the next chunk's start. Like the reference policy, an LSTM
    critic carries its own (h, c) from chunk to chunk; a transformer's memory is the prefix."""
    n = chunk.prefix + steps
    if state is None:  # transformer: one pass over context, chunk and bootstrap step
        return critic.evaluate(chunk.select(hi=n + 1))[1], None
    _, v, after = critic.evaluate(chunk.select(hi=n), state)  # LSTM: the memory after the chunk,
    _, v_boot, _ = critic.evaluate(chunk.select(lo=n, hi=n + 1), after)  # then the bootstrap step from it
    return torch.cat([v, v_boot], 1), after


class Finetune:
    """What fine-tuning adds to PPO, and the state it carries across updates and checkpoints. `active` False
    (PPO from scratch): one Adam at `lr`, the policy's own values, no anchor."""

    def __init__(self, cfg: TrainConfig, active: bool) -> None:
        self.ft, self.active, self.stop_weight = cfg.finetune, active, cfg.stop_loss_weight
        self.anchor = cfg.finetune.anchor if active else "none"
        self.reference = self.critic_net = self.critic_model = None
        self.gate_open = cfg.finetune.critic_warmup_ev <= 0  # the explained-variance gate of the actor (latched)
        self.ref_state = None  # the reference LSTM's memory at the next chunk's start
        self.critic_state = None  # the separate LSTM critic's, likewise
        self.critic_state0 = None  # ... and at this chunk's start
        self.ref_logits: torch.Tensor | None = None  # the reference's logits on this chunk
        self.weight = 0.0  # the anchor's weight in this update

    # -- set-up and resume ----------------------------------------------------------------------------
    def setup(self, policy, lr: float, adam_eps: float) -> torch.optim.Optimizer:
        """The optimiser. Fine-tuning first freezes a copy of the initial policy (anchor kl), re-initialises
        the critic, freezes the prev-action embedding, makes the separate critic, and gives critic and actor
        their own learning rates."""
        ft = self.ft
        if not self.active:
            return torch.optim.Adam(policy.parameters(), lr=lr, eps=adam_eps)
        if self.anchor == "kl":  # the initial policy, frozen, before the critic is re-initialised
            self.reference = policy.clone().eval().requires_grad_(False)
        if ft.reinit_critic:
            policy.reinit_critic()
        groups = policy.parameter_groups()
        if ft.freeze_prev_action:
            for p in groups["prev_action"]:
                p.requires_grad_(False)
        if ft.critic == "separate":  # its own copy of the initial network; the policy's head goes unused
            self.critic_net = policy.clone().requires_grad_(True)
            self.critic_net.reinit_critic()
            self.critic_net.action_head.requires_grad_(False)
            policy.critic_head.requires_grad_(False)
            groups["critic"] = [p for p in self.critic_net.parameters() if p.requires_grad]
        critic_lr, actor_lr = finetune_lrs(ft, 0)
        param_groups = [
            {"params": groups["critic"], "lr": critic_lr, "name": "critic"},
            {"params": groups["actor"], "lr": actor_lr, "name": "actor"},
        ]
        if not ft.freeze_prev_action and groups["prev_action"]:
            param_groups.append({"params": groups["prev_action"], "lr": actor_lr, "name": "prev_action"})
        return torch.optim.Adam(param_groups, eps=adam_eps)

    def wrap(self, info: dist.DistInfo) -> None:
        """DDP for the separate critic (after the policy's own wrapper)."""
        if self.critic_net is not None:
            self.critic_model = dist.wrap(self.critic_net, info)

    def trainable(self, policy) -> list[torch.nn.Parameter]:
        """The parameters whose gradient norm is clipped: the policy's and the separate critic's."""
        return [p for net in (policy, self.critic_net) if net is not None for p in net.parameters() if p.requires_grad]

    def state(self) -> dict:
        """This rank's part of a checkpoint (written on every PPO run, from scratch too)."""
        extra = (
            {}
            if self.critic_net is None
            else {"critic_net": self.critic_net.state_dict(), "critic_state": self.critic_state}
        )
        return {"actor_gate_open": self.gate_open, "ref_state": self.ref_state, **extra}

    def restore(self, saved: dict, device: torch.device) -> None:
        self.gate_open = saved.get("actor_gate_open", self.gate_open)
        self.ref_state = to_device(saved.get("ref_state"), device)
        if self.critic_net is not None:
            self.critic_net.load_state_dict(saved["critic_net"])
            self.critic_state = to_device(saved.get("critic_state"), device)

    # -- hooks of an update ---------------------------------------------------------------------------
    def begin(self, update: int, optimizer: torch.optim.Optimizer) -> None:
        """The schedule at `update` (0-based): learning rates (a closed gate holds the actor) and the anchor's
        weight."""
        if not self.active:
            return
        critic_lr, actor_lr = finetune_lrs(self.ft, update)
        for g in optimizer.param_groups:
            g["lr"] = critic_lr if g["name"] == "critic" else (actor_lr if self.gate_open else 0.0)
        self.weight = anchor_weight(self.ft, update)

    def values(self, chunk: Chunk, steps: int, values: torch.Tensor) -> torch.Tensor:
        """The values GAE uses (no grad): the separate critic's (its memory at the first chunk is the policy's,
        which is fresh), else `values` (the policy's head)."""
        self.critic_state0 = self.critic_state
        if self.critic_net is None:
            return values
        if self.critic_state0 is None and chunk.state0 is not None:
            self.critic_state0 = chunk.state0
        values, self.critic_state = critic_values(self.critic_net, chunk, steps, self.critic_state0)
        return values

    def read_reference(self, chunk: Chunk, steps: int) -> None:
        """anchor=kl: the frozen initial policy's logits on the chunk (no grad). Its memory at the first chunk
        is the policy's: they are equal."""
        if self.reference is not None:
            state = chunk.state0 if self.ref_state is None else self.ref_state
            self.ref_logits, self.ref_state = reference_logits(self.reference, chunk, steps, state)

    def open_gate(self, ev: float, info: dist.DistInfo) -> None:
        """Latch the actor's gate once the critic explains `critic_warmup_ev` of the returns' variance; every
        rank opens it at the same update (their weights stay equal)."""
        if not self.gate_open:
            self.gate_open = dist.all_reduce_mean({"ev": ev}, info)["ev"] >= self.ft.critic_warmup_ev

    def minibatch_values(self, seq: Chunk, rows: torch.Tensor, values: torch.Tensor) -> torch.Tensor:
        """The values the value loss trains on a minibatch (`rows` of the chunk): the separate critic's, else
        `values`."""
        if self.critic_net is None:
            return values
        return self.critic_net.evaluate(seq, index_state(self.critic_state0, rows), via=self.critic_model)[1]

    def anchor_loss(self, logits: torch.Tensor, labels: torch.Tensor, rows: torch.Tensor) -> torch.Tensor | None:
        """The anchor's loss on a minibatch (weighted by `weight` in the total); None at weight 0."""
        if self.weight <= 0:
            return None
        if self.anchor == "expert":
            return imitation_loss(logits, labels[rows], self.stop_weight)
        return kl_to(self.ref_logits[rows], logits)

    def scalars(self) -> dict[str, float]:
        return {"anchor/weight": self.weight, "actor_gate_open": float(self.gate_open)} if self.active else {}
