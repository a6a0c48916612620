"""ovon's own pretrained perception for the embedded world: one network, three roles.

* `world-vl` image encoder (the policies' SigLIP analogue): `WorldVLEncoder`;
* `world-owl` detector (the OWLv2 analogue): `WorldOWLDetector`;
* `world-vl` value scorer (VLFM's BLIP-2 analogue): `WorldVLScorer`.

The shipped weights (`weights/world_vl.safetensors`, trained by `ovon perception pretrain` on the pretrain
houses only) are found with no path given; `checkpoint=PATH` points at your own (a `world_vl.safetensors`
or the run folder holding it). Nothing is downloaded.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np
import torch

from ovon.models.world.net import NetConfig, WorldVLNet, pool_cells

WEIGHTS_NAME = "world_vl.safetensors"
SHIPPED = "shipped"  # how reports name the packaged weights


@dataclass
class WorldVL:
    """A loaded network with its calibration (threshold and pooling chosen on pretraining houses)."""

    net: WorldVLNet
    threshold: float
    pooling: str
    source: str  # "shipped" or the file's path
    meta: dict

    def __post_init__(self) -> None:
        self._last: tuple[np.ndarray, tuple] | None = None

    @torch.inference_mode()
    def features(self, rgb) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """(B, H, W, 3) uint8 -> (cell features, objectness logits, global embedding)."""
        return self.net.features(torch.as_tensor(np.ascontiguousarray(rgb)))

    def frame_features(self, rgb: np.ndarray) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """One frame's features, reused while the frame is the same (VLFM's detector and value scorer
        read the same frame each step: one forward pass serves both)."""
        rgb = np.asarray(rgb)
        if self._last is not None and self._last[0].shape == rgb.shape and np.array_equal(self._last[0], rgb):
            return self._last[1]
        out = self.features(rgb[None])
        self._last = (rgb.copy(), out)
        return out

    def probs(self, top: torch.Tensor, text: torch.Tensor) -> torch.Tensor:
        """Per-cell probabilities (B, K, h, w) of unit texts (K, D)."""
        with torch.inference_mode():
            return torch.sigmoid(self.net.logit_scale.exp() * self.net.cell_cosines(top, text) + self.net.logit_bias)

    def frame_score(self, probs: torch.Tensor) -> torch.Tensor:
        return pool_cells(probs, self.pooling)

    def global_probs(self, glob: torch.Tensor, text: torch.Tensor) -> torch.Tensor:
        with torch.inference_mode():
            return torch.sigmoid(self.net.logits(glob, text))


def shipped_path() -> Path:
    return Path(str(resources.files("ovon.models.world").joinpath("weights", WEIGHTS_NAME)))


def resolve_checkpoint(checkpoint: str | Path | None) -> Path:
    """The weights file: the shipped one for None / "" / "shipped", else the file or the run folder's file.
    A missing file is one line naming it and how to fix it."""
    if checkpoint in (None, "", SHIPPED):
        path = shipped_path()
        if not path.is_file():
            raise FileNotFoundError(
                f"the shipped world-vl weights are missing ({path}); fix: reinstall ovon, or pass "
                "checkpoint=PATH to weights written by `ovon perception pretrain`"
            )
        return path
    path = Path(checkpoint)
    if path.is_dir():
        path = path / WEIGHTS_NAME
    if not path.is_file():
        raise FileNotFoundError(
            f"checkpoint={checkpoint}: no world-vl weights there (expected a {WEIGHTS_NAME} or a run folder of "
            "`ovon perception pretrain` holding one); fix: pass the path of such a file"
        )
    return path


_LOADED: dict[str, WorldVL] = {}


def load_world_vl(checkpoint: str | Path | None = None) -> WorldVL:
    """Load (once per process and file) the network and its calibration."""
    from safetensors import safe_open
    from safetensors.torch import load_file

    path = resolve_checkpoint(checkpoint)
    key = str(path.resolve())
    if key in _LOADED:
        return _LOADED[key]
    try:
        with safe_open(str(path), framework="pt") as fh:
            meta = json.loads((fh.metadata() or {})["ovon"])
        net = WorldVLNet(NetConfig.from_json(meta["net"]))
        net.load_state_dict(load_file(str(path)))
    except Exception as e:  # a damaged or foreign file: one line, not a traceback from safetensors or torch
        raise ValueError(
            f"checkpoint {path}: not a world-vl weights file ({type(e).__name__}: {e}); fix: pass a file written "
            "by `ovon perception pretrain`"
        ) from None
    net = net.eval().for_inference()  # the roles only act: BatchNorm folded, channels-last
    cal = meta["calibration"]
    source = SHIPPED if path == shipped_path() else str(path)
    model = WorldVL(net, float(cal["threshold"]), str(cal["pooling"]), source, meta)
    _LOADED[key] = model
    return model


__all__ = ["SHIPPED", "WEIGHTS_NAME", "WorldVL", "load_world_vl", "resolve_checkpoint", "shipped_path"]
