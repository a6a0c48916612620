"""The acting loop shared by DAgger and PPO: a policy acts in the training envs for T steps and every
observation, label, action and reward is recorded (a `Rollout`: a `Chunk` plus what was done and got);
plus the pure return/advantage arithmetic.

The collector owns what acting carries across updates (the envs' current batch, the policy's acting
memory, the previous actions) and hands it to the checkpoint (`state`) and back (`restore`), so an
algorithm only says how an action is chosen from the logits.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import torch

from ovon.models.chunk import Chunk, cat_time, map_images, pad_time, slice_time, stack_images
from ovon.train.checkpoint import to_device
from ovon.train.envs import Batch

# choose(logits (N, A), batch) -> (actions (N,), log-probabilities of those actions (N,) or None)
Chooser = Callable[[torch.Tensor, Batch], tuple[torch.Tensor, torch.Tensor | None]]


@dataclass
class Rollout:
    """`steps` steps of every env as (N, T, ...) tensors on the CPU. `chunk`: what the policy read, after the
    collector's context prefix; with a bootstrap observation T + 1 steps (the last one: value only, no action);
    its labels are the expert's per step (-1 without an expert), its `state0` the acting memory before it
    (LSTM (h, c); None for the transformer)."""

    chunk: Chunk
    actions: torch.Tensor  # (N, T)
    behaviour_logp: torch.Tensor | None  # (N, T) log-prob of each action when it was taken
    rewards: torch.Tensor  # (N, T): reward of step t
    dones: torch.Tensor  # (N, T): step t ended its episode
    finished: list[dict] = field(default_factory=list)  # metrics of the episodes that ended


def acting_context(policy_cfg) -> int:
    """How many steps before a step a KV-cached transformer's acting reads: layers x (context - 1), since
    each layer's keys were computed when their step was acted, from that step's own window. An update that
    prepends this many steps to a chunk computes the logits acting computed. ("recompute" acting re-runs
    only the last `context` steps each step, which no single forward over a sequence equals beyond one layer;
    `behaviour_kl` shows the difference.) 0 for the LSTM, whose memory is its state (`Chunk.state0`)."""
    return policy_cfg.layers * (policy_cfg.context - 1) if policy_cfg.core == "transformer" else 0


class RolloutCollector:
    """Acts in `envs`, starting from `batch` (the envs' current observation)."""

    def __init__(self, envs, batch: Batch, policy, device: torch.device | str, prefix: int = 0) -> None:
        """`prefix` > 0: each rollout also carries the `prefix` steps before it, so that an update
        that re-reads the chunk through a sliding-window transformer sees the context acting saw."""
        self.envs, self.batch, self.device = envs, batch, device
        self.num_envs = envs.num_envs
        self.act_state = policy.init_state(self.num_envs, device)
        self.prev_action = torch.full((self.num_envs,), -1, dtype=torch.long, device=device)
        self.prefix = prefix
        self.tail: dict | None = None  # the last `prefix` steps acted (images, goals, prevs, starts)

    # -- resume ---------------------------------------------------------------------------------
    def state(self) -> dict:
        """What a checkpoint needs to continue acting exactly."""
        return {
            "env": self.envs.get_state(),
            "act_state": self.act_state,
            "prev_action": self.prev_action.cpu(),
            "tail": self.tail,
        }

    def restore(self, saved: dict) -> None:
        self.act_state = to_device(saved["act_state"], self.device)
        self.prev_action = saved["prev_action"].to(self.device)
        self.tail = saved.get("tail")
        self.batch = self.envs.set_state(saved["env"])

    # -- acting ---------------------------------------------------------------------------------
    def collect(self, actor, steps: int, choose: Chooser, bootstrap: bool = False) -> Rollout:
        """`steps` actions per env with `actor` (in eval mode, no gradients); `bootstrap` records the
        observation after the last step too (PPO's value bootstrap)."""
        dev = self.device
        state0 = _clone_state(self.act_state)
        images, goals, prevs, starts, labels = [], [], [], [], []
        actions, logps, rewards, dones, finished = [], [], [], [], []
        actor.eval()
        for t in range(steps + 1):
            b = self.batch
            if t == steps and not bootstrap:
                break
            images.append(b.image)
            goals.append(b.goal)
            prevs.append(self.prev_action.cpu())
            starts.append(b.first)
            labels.append(b.label)
            if t == steps:
                break
            with torch.inference_mode():  # no autograd bookkeeping at all (cheaper than no_grad per op)
                obs = actor.embed(map_images(b.image, lambda x: x.to(dev)), b.goal.to(dev))
                logits, _, self.act_state = actor.act_step(obs, self.prev_action, self.act_state, b.first.to(dev))
                action, logp = choose(logits, b)
            actions.append(action.cpu())
            if logp is not None:
                logps.append(logp.cpu())
            self.batch = self.envs.step(action.cpu())
            rewards.append(self.batch.reward)
            dones.append(self.batch.done)
            self.prev_action = torch.where(self.batch.first.to(dev), torch.full_like(action, -1), action)
            finished += self.batch.metrics
        obs = {
            "images": stack_images(images, 1),
            "goals": torch.stack(goals, 1),
            "prevs": torch.stack(prevs, 1),
            "starts": torch.stack(starts, 1),
        }
        if self.prefix > 0:
            obs = self._with_prefix(obs, steps)
        return Rollout(
            Chunk(**obs, labels=torch.stack(labels, 1), state0=state0, prefix=self.prefix),
            actions=torch.stack(actions, 1),
            behaviour_logp=torch.stack(logps, 1) if logps else None,
            rewards=torch.stack(rewards, 1),
            dones=torch.stack(dones, 1),
            finished=finished,
        )

    def _with_prefix(self, obs: dict, steps: int) -> dict:
        """Prepend the stored tail (before the first rollout: padding marked as episode starts, which
        nothing attends to because every env's first step is itself a start) and keep the new tail."""
        P = self.prefix
        tail = self.tail
        if tail is None:
            tail = {k: pad_time(v, P, k == "starts") for k, v in obs.items()}
        full = {k: cat_time(tail[k], v) for k, v in obs.items()}
        acted = {k: slice_time(full[k], P, P + steps) for k in full}  # the chunk without its bootstrap
        self.tail = {k: slice_time(cat_time(tail[k], acted[k]), -P, None) for k in full}
        return full


def _clone_state(state):
    """Detached copy of an LSTM (h, c) acting state (the transformer needs none: chunks carry starts)."""
    if isinstance(state, tuple):
        return tuple(s.detach().clone() for s in state)
    return None


# -- returns -----------------------------------------------------------------------------------------
def gae(
    rewards: torch.Tensor, values: torch.Tensor, dones: torch.Tensor, gamma: float, lam: float
) -> tuple[torch.Tensor, torch.Tensor]:
    """Generalised advantage estimation over (N, T) rewards / dones and (N, T + 1) values (the last
    column bootstraps). A done step does not look past its episode's end. Returns (advantages, returns)."""
    done = dones.float()
    adv = torch.zeros_like(rewards)
    running = torch.zeros(rewards.shape[0], dtype=rewards.dtype, device=rewards.device)
    for t in reversed(range(rewards.shape[1])):
        nonterminal = 1.0 - done[:, t]
        delta = rewards[:, t] + gamma * values[:, t + 1] * nonterminal - values[:, t]
        running = delta + gamma * lam * nonterminal * running
        adv[:, t] = running
    return adv, adv + values[:, : rewards.shape[1]]


def explained_variance(values: torch.Tensor, returns: torch.Tensor) -> float:
    """1 - Var(returns - values) / Var(returns): 1 is a perfect critic, 0 no better than the mean,
    negative worse (0 when the returns do not vary: nothing to explain)."""
    var = returns.var()
    if not torch.isfinite(var) or var.item() == 0.0:
        return 0.0
    return float(1.0 - (returns - values).var() / var)
