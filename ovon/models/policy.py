"""Actor-critic policy over per-step embeddings (docs/spec.md#end-to-end-policy), shared by BC, DAgger and PPO.

    o_t = [image_emb, goal_emb, prev_action_emb (, goal similarity)]  ->  Linear(hidden)  ->  core  ->  heads

With `cfg.goal_similarity` the input also holds, per text-aligned part of the image embedding, its dot
product, cosine and norm against the unit goal embedding (3 numbers per part).

`prev_action_emb` is `nn.Embedding(num_actions + 1, prev_action_dim)` indexed by previous action + 1,
0 at an episode start (callers pass -1 there; it is forced to 0 at every start anyway).
The core is a `TransformerCore` (sliding-window KV cache when acting) or an `LSTMCore`.
Why one wrapper: trainers, evaluators and checkpoints see a single interface whatever the core.
"""

from __future__ import annotations

import copy
import warnings
from pathlib import Path
from typing import Any

import torch
from torch import nn
from torch.distributions import Categorical

from ovon.config.base import from_dict, to_dict
from ovon.models.chunk import Chunk, Images
from ovon.models.config import EncoderConfig, PolicyConfig, text_aligned_parts
from ovon.models.lstm import LSTMCore, matched_lstm_hidden, transformer_core_params
from ovon.models.transformer import TransformerCore

CHECKPOINT_FORMAT = "ovon-policy-v1"


# Storage dtypes of frozen-encoder embeddings that `make_obs` widens to float32 (the buffer keeps float16).
NARROW_FLOATS = (torch.float16, torch.bfloat16)


class ActorCritic(nn.Module):
    """Policy + value function; `evaluate` reads a learner's `Chunk` (`forward` the embedded sequence),
    `act_step`/`act` act online, `embed` turns an env's images and goals into the input of either.

    If `encoder_cfg.image == "cnn"` the trainable CNN lives inside the policy (`image_encoder`), so
    it is optimised, saved and loaded with it; frozen encoders stay outside (embeddings are inputs).
    """

    def __init__(
        self, cfg: PolicyConfig, image_dim: int, text_dim: int, encoder_cfg: EncoderConfig | None = None
    ) -> None:
        super().__init__()
        self.cfg = cfg
        self.image_dim = image_dim
        self.text_dim = text_dim
        self.encoder_cfg = encoder_cfg
        self.obs_dim = image_dim + text_dim
        self.image_encoder: nn.Module | None = None
        if encoder_cfg is not None and encoder_cfg.image == "cnn":
            from ovon.models.encoders.cnn import CNNEncoder

            if encoder_cfg.cnn_dim != image_dim:
                raise ValueError(f"image_dim {image_dim} != cnn_dim {encoder_cfg.cnn_dim}")
            self.image_encoder = CNNEncoder(
                encoder_cfg.cnn_dim, encoder_cfg.cnn_channels, encoder_cfg.cnn_depth, encoder_cfg.cnn_max_depth
            )
        self.sim_parts = 0
        if cfg.goal_similarity:
            if encoder_cfg is None:
                raise ValueError("policy.goal_similarity needs the encoder config (which parts are text-aligned)")
            self.sim_parts = text_aligned_parts(encoder_cfg)
            if self.sim_parts == 0 or self.sim_parts * text_dim > image_dim:
                raise ValueError(
                    f"policy.goal_similarity: image encoder {encoder_cfg.image!r} has no goal-text-space "
                    "parts; set policy.goal_similarity=false"
                )
        # prev_action_dim 0 = no previous-action input: with little data the policy otherwise learns to
        # repeat its last action (the "copycat" shortcut) and keeps pressing MOVE_FORWARD into walls.
        self.prev_action_emb = nn.Embedding(cfg.num_actions + 1, cfg.prev_action_dim) if cfg.prev_action_dim else None
        self.input_proj = nn.Linear(self.obs_dim + cfg.prev_action_dim + 3 * self.sim_parts, cfg.hidden)
        self.core = self._make_core(cfg)
        self.action_head = nn.Linear(self.core.out_dim, cfg.num_actions)
        self.critic_head = nn.Linear(self.core.out_dim, 1)
        nn.init.normal_(self.action_head.weight, std=0.01)  # near-uniform initial policy (RL)
        nn.init.zeros_(self.action_head.bias)
        with torch.no_grad():
            self.action_head.bias[0] = cfg.stop_bias  # STOP is action 0

    @staticmethod
    def _make_core(cfg: PolicyConfig) -> nn.Module:
        if cfg.core == "transformer":
            return TransformerCore(cfg.hidden, cfg.layers, cfg.heads, cfg.mlp, cfg.context, cfg.rope_base, cfg.norm_eps)
        if cfg.core == "lstm":
            width = cfg.lstm_hidden or matched_lstm_hidden(
                cfg.hidden, cfg.layers, transformer_core_params(cfg.hidden, cfg.layers, cfg.mlp)
            )
            return LSTMCore(cfg.hidden, width, cfg.layers)
        raise ValueError(f"unknown policy core {cfg.core!r}; valid: transformer, lstm")

    # ----- inputs -----
    @staticmethod
    def make_obs(image_emb: torch.Tensor, goal_emb: torch.Tensor) -> torch.Tensor:
        """Concatenate image (..., Di) and goal (..., Dg) embeddings; the goal broadcasts over time
        (e.g. image (B,T,Di) with goal (B,Dg)), in the image's dtype; float16 / bfloat16 buffer embeddings
        are widened to float32 inside the one copy the concatenation makes (a `.float()` first cost a pass)."""
        while goal_emb.ndim < image_emb.ndim:
            goal_emb = goal_emb.unsqueeze(-2)
        goal_emb = goal_emb.expand(*image_emb.shape[:-1], goal_emb.shape[-1])
        dtype = torch.float32 if image_emb.dtype in NARROW_FLOATS else image_emb.dtype
        out = torch.empty(
            *image_emb.shape[:-1], image_emb.shape[-1] + goal_emb.shape[-1], dtype=dtype, device=image_emb.device
        )
        out[..., : image_emb.shape[-1]] = image_emb
        out[..., image_emb.shape[-1] :] = goal_emb
        return out

    def encode_images(self, batch: Any) -> torch.Tensor:
        """Run the policy-owned trainable image encoder (only when `encoder_cfg.image == "cnn"`)."""
        if self.image_encoder is None:
            raise RuntimeError("this policy owns no image encoder; pass precomputed embeddings")
        return self.image_encoder.encode(batch)

    def image_features(self, images: Images) -> torch.Tensor:
        """Image embeddings for a batch with any leading dims: a tensor passes through (float16 buffer
        embeddings too: `make_obs` widens them as it concatenates); raw frames go through the policy's
        trainable CNN (with gradients when called under grad)."""
        if isinstance(images, torch.Tensor):
            return images if images.dtype in NARROW_FLOATS else images.float()
        rgb = images["rgb"]
        lead = rgb.shape[:-3]
        flat = {k: v.reshape(-1, *v.shape[len(lead) :]) for k, v in images.items()}
        return self.encode_images(flat).reshape(*lead, -1)

    def embed(self, images: Images, goals: torch.Tensor) -> torch.Tensor:
        """The core's observation input for images (embeddings or frames) and goal embeddings, any leading dims:
        the one place acting, learning and evaluation turn what an env gives into what the policy reads."""
        return self.make_obs(self.image_features(images), goals)

    def _project(self, obs_emb: torch.Tensor, prev_actions: torch.Tensor, starts: torch.Tensor | None):
        if obs_emb.shape[-1] != self.obs_dim:
            raise ValueError(f"obs_emb last dim {obs_emb.shape[-1]} != image_dim + text_dim = {self.obs_dim}")
        x = [obs_emb]
        if self.prev_action_emb is not None:
            idx = (prev_actions.long() + 1).clamp(0, self.cfg.num_actions)
            if starts is not None:
                idx = torch.where(starts.bool(), torch.zeros_like(idx), idx)
            x.append(self.prev_action_emb(idx).to(obs_emb.dtype))
        if self.sim_parts:
            x.append(self.goal_similarity(obs_emb))
        return self.input_proj(torch.cat(x, -1))

    def goal_similarity(self, obs_emb: torch.Tensor) -> torch.Tensor:
        """(..., image_dim + text_dim) -> (..., 3 * parts): dot, cosine and norm of each text-aligned part
        against the unit goal embedding."""
        parts = obs_emb[..., : self.sim_parts * self.text_dim].reshape(*obs_emb.shape[:-1], self.sim_parts, -1)
        goal = obs_emb[..., self.image_dim :]
        goal = goal / goal.norm(dim=-1, keepdim=True).clamp_min(1e-12)
        dot = (parts * goal.unsqueeze(-2)).sum(-1)
        norm = parts.norm(dim=-1)
        return torch.cat([dot, dot / norm.clamp_min(1e-6), norm], -1)

    # ----- training -----
    def forward_seq(
        self,
        obs_emb: torch.Tensor,
        prev_actions: torch.Tensor,
        episode_starts: torch.Tensor | None = None,
        state: Any = None,
        positions: torch.Tensor | None = None,
    ) -> tuple[torch.Tensor, torch.Tensor, Any]:
        """Like `forward`, also returning the core's final state (LSTM (h, c); None for the transformer).

        `state` is the LSTM's state before the chunk (recurrent PPO); `positions` (B,T) the
        transformer's RoPE positions (default: steps since the last start within the chunk).
        """
        x = self._project(obs_emb, prev_actions, episode_starts)
        if isinstance(self.core, TransformerCore):
            feats, new_state = self.core(x, episode_starts, positions), None
        else:
            feats, new_state = self.core(x, episode_starts, state)
        return self.action_head(feats), self.critic_head(feats).squeeze(-1), new_state

    def evaluate(
        self, chunk: Chunk, state: Any = None, via: nn.Module | None = None
    ) -> tuple[torch.Tensor, torch.Tensor, Any]:
        """Logits (N, L', A) and values (N, L') of the chunk's steps after its context prefix (L' = L - prefix),
        and the core's state after the chunk (LSTM (h, c); None for a transformer, or when run `via`).

        `state`: the LSTM's before the chunk. `via`: the module the sequence goes through for a loss, this policy
        or its DDP wrapper (whose forward is what syncs gradients across ranks; it returns no state)."""
        obs = self.embed(chunk.images, chunk.goals)
        if via is None:
            logits, values, state = self.forward_seq(obs, chunk.prevs, chunk.starts, state)
        else:
            (logits, values), state = via(obs, chunk.prevs, chunk.starts, state), None
        return logits[:, chunk.prefix :], values[:, chunk.prefix :], state

    def forward(
        self,
        obs_emb: torch.Tensor,
        prev_actions: torch.Tensor,
        episode_starts: torch.Tensor | None = None,
        state: Any = None,
        positions: torch.Tensor | None = None,
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """obs_emb (B,T,image_dim+text_dim), prev_actions (B,T) long (-1 at start), episode_starts
        (B,T) bool -> logits (B,T,num_actions), values (B,T). A chunk may hold episode boundaries."""
        logits, values, _ = self.forward_seq(obs_emb, prev_actions, episode_starts, state, positions)
        return logits, values

    # ----- acting -----
    def init_state(self, batch_size: int, device: torch.device | str | None = None) -> Any:
        """Fresh acting state for `batch_size` envs (KV cache / input window / LSTM (h, c))."""
        return self.core.init_state(batch_size, device, self.cfg.act_mode)

    def act_step(
        self,
        obs_emb: torch.Tensor,
        prev_action: torch.Tensor,
        state: Any,
        done_mask: torch.Tensor | None = None,
    ) -> tuple[torch.Tensor, torch.Tensor, Any]:
        """One step for B envs: obs_emb (B,D), prev_action (B,) (-1 at start), done_mask (B,) True
        where this step is the first of a new episode -> logits (B,A), value (B,), new state.
        The transformer's state is updated in place (and returned)."""
        x = self._project(obs_emb, prev_action, done_mask)
        feats, state = self.core.step(x, state, done_mask)
        return self.action_head(feats), self.critic_head(feats).squeeze(-1), state

    @torch.no_grad()
    def act(
        self,
        obs_emb: torch.Tensor,
        prev_action: torch.Tensor,
        state: Any,
        done_mask: torch.Tensor | None = None,
        deterministic: bool = False,
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, Any]:
        """Sample (or argmax) actions: -> (actions (B,), log_probs (B,), values (B,), state)."""
        logits, value, state = self.act_step(obs_emb, prev_action, state, done_mask)
        dist = self.distribution(logits)
        action = logits.argmax(-1) if deterministic else dist.sample()
        return action, dist.log_prob(action), value, state

    @staticmethod
    def distribution(logits: torch.Tensor) -> Categorical:
        return Categorical(logits=logits.float())

    # ----- fine-tuning / checkpoints -----
    def reinit_critic(self) -> None:
        """Fresh critic head for BC->RL / DAgger->RL (the IL policy never trained it)."""
        self.critic_head.reset_parameters()

    def parameter_groups(self) -> dict[str, list[nn.Parameter]]:
        """Named groups for the fine-tune schedule: critic, actor (head + core + projection + owned
        encoder), prev_action (frozen during fine-tuning upstream)."""
        actor = [*self.action_head.parameters(), *self.core.parameters(), *self.input_proj.parameters()]
        if self.image_encoder is not None:
            actor += list(self.image_encoder.parameters())
        return {
            "critic": list(self.critic_head.parameters()),
            "actor": actor,
            "prev_action": [] if self.prev_action_emb is None else list(self.prev_action_emb.parameters()),
        }

    def num_params(self, part: str | None = None) -> int:
        mod = self if part is None else getattr(self, part)
        return sum(p.numel() for p in mod.parameters())

    def save(self, path: str | Path, extra: dict[str, Any] | None = None) -> None:
        """Checkpoint with everything needed to rebuild the module (config + dims + weights)."""
        from ovon.atomic import atomic_write_with

        payload = {
            "format": CHECKPOINT_FORMAT,
            "policy_config": to_dict(self.cfg),
            "encoder_config": None if self.encoder_cfg is None else to_dict(self.encoder_cfg),
            "image_dim": self.image_dim,
            "text_dim": self.text_dim,
            "state_dict": self.state_dict(),
            "extra": extra or {},
        }
        atomic_write_with(path, lambda f: torch.save(payload, f))

    @classmethod
    def load(cls, path: str | Path, map_location: str | torch.device = "cpu", flag: str = "policy") -> ActorCritic:
        """Rebuild a policy saved by `save` (any core); `path` may be its run folder. A file that is not
        one is refused in one line naming `flag` (`read_policy_file`)."""
        ckpt = read_policy_file(path, flag, "cpu")  # extras (the text table) stay on the CPU, where they are read
        cfg = from_dict(PolicyConfig, ckpt["policy_config"])
        enc = ckpt.get("encoder_config")
        enc_cfg = None if enc is None else from_dict(EncoderConfig, enc)
        policy = build_policy(cfg, ckpt["image_dim"], ckpt["text_dim"], enc_cfg)
        policy.load_state_dict(ckpt["state_dict"])
        policy.checkpoint_extra = ckpt.get("extra", {})
        return policy.to(map_location)  # load_state_dict copies into the module's own (CPU) parameters

    def clone(self) -> ActorCritic:
        """A deep copy (frozen reference, acting copy, separate critic). Why not `copy.deepcopy` alone: the
        copy's cuDNN LSTM weights are no longer one contiguous chunk, and every call would re-pack them."""
        twin = copy.deepcopy(self)
        for m in twin.modules():
            if isinstance(m, nn.LSTM):
                m.flatten_parameters()
        return twin


class TransformerPolicy(ActorCritic):
    """ActorCritic with the decoder-only transformer core (the paper's policy)."""

    def __init__(self, cfg: PolicyConfig, image_dim: int, text_dim: int, encoder_cfg: EncoderConfig | None = None):
        if cfg.core != "transformer":
            raise ValueError("TransformerPolicy needs cfg.core == 'transformer'")
        super().__init__(cfg, image_dim, text_dim, encoder_cfg)


class LSTMPolicy(ActorCritic):
    """ActorCritic with the LSTM core (the RNN baseline, width matched in parameters)."""

    def __init__(self, cfg: PolicyConfig, image_dim: int, text_dim: int, encoder_cfg: EncoderConfig | None = None):
        if cfg.core != "lstm":
            raise ValueError("LSTMPolicy needs cfg.core == 'lstm'")
        super().__init__(cfg, image_dim, text_dim, encoder_cfg)


def build_policy(
    policy_cfg: PolicyConfig, image_dim: int, text_dim: int, encoder_cfg: EncoderConfig | None = None
) -> ActorCritic:
    """`TransformerPolicy` or `LSTMPolicy` according to `policy_cfg.core`."""
    cls = TransformerPolicy if policy_cfg.core == "transformer" else LSTMPolicy
    return cls(policy_cfg, image_dim, text_dim, encoder_cfg)


def load_weights_file(path: str | Path, map_location: Any = "cpu") -> Any:
    """`torch.load(weights_only=True)` without torch's own warnings: a foreign file that starts like a pickle
    makes torch warn before it raises, and a caller's one-line refusal must be the only line."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return torch.load(path, map_location=map_location, weights_only=True)


def read_policy_file(path: str | Path, flag: str = "policy", map_location: str | torch.device = "cpu") -> dict:
    """The dict of a policy.pt written by `ActorCritic.save` (a run folder means its policy.pt), read with
    weights_only. Anything else - a missing, empty, truncated or foreign file, a training run's
    checkpoint.pt - is one line naming `flag`, the path and the fix, never torch's own multi-line text."""
    given = Path(path)
    p = given / "policy.pt" if given.is_dir() else given
    fix = "fix: pass the policy.pt written by `ovon train` (or its run folder)"
    where = f"{flag} {str(path)!r}"
    if not p.is_file():
        raise FileNotFoundError(f"{where}: {p} does not exist; {fix}")
    if p.stat().st_size == 0:
        raise ValueError(f"{where}: {p} is empty; {fix}")
    resume_state = f"{where}: {p} is a training run's resume state, not a policy; fix: pass {p.parent / 'policy.pt'}"
    try:
        ckpt = load_weights_file(p, map_location)
    except Exception as e:  # noqa: BLE001 - torch raises many types (unpickling, zip, EOF) for a bad file
        if p.name == "checkpoint.pt":
            raise ValueError(resume_state) from None
        raise ValueError(
            f"{where}: {p} is not a checkpoint torch can read ({type(e).__name__}: truncated, or not "
            f"written by torch.save); {fix}"
        ) from None
    if isinstance(ckpt, dict) and {"optimizer", "ranks"} <= ckpt.keys():
        raise ValueError(resume_state)
    if not isinstance(ckpt, dict) or ckpt.get("format") != CHECKPOINT_FORMAT:
        what = f"format {ckpt.get('format')!r}" if isinstance(ckpt, dict) else f"a {type(ckpt).__name__}"
        raise ValueError(f"{where}: {p} is not an ovon policy ({CHECKPOINT_FORMAT}; it holds {what}); {fix}")
    return ckpt


def policy_task_kind(ckpt: dict) -> str | None:
    """The task ("objectnav" | "pointnav") a policy dict of `read_policy_file` was trained for; None when
    it does not say (written before policies recorded their task)."""
    task = (ckpt.get("extra") or {}).get("task") if isinstance(ckpt.get("extra"), dict) else None
    kind = task.get("kind") if isinstance(task, dict) else None
    return kind if isinstance(kind, str) else None


def load_policy(path: str | Path, map_location: str | torch.device = "cpu") -> ActorCritic:
    return ActorCritic.load(path, map_location)
