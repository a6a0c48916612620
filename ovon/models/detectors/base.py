"""The detector protocol: `detect(observation, goal_text) -> list[Detection]`.

Why a protocol: the paper's detector (OWLv2) needs weights no machine here can download, so detection is a
pluggable choice picked by config (`ovon.models.detectors.make_detector`); the modular agents only rely on
pixel boxes, optional masks and scores.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np


@dataclass
class Detection:
    """One detection of the goal text in one frame."""

    box: tuple[int, int, int, int]  # pixel box (x0, y0, x1, y1), x1/y1 exclusive
    score: float  # detector confidence in [0, 1]
    label: str  # the text it was asked for
    mask: np.ndarray | None = None  # (H, W) bool instance mask when the detector has one

    def pixels(self, shape: tuple[int, int], box_shrink: float = 0.0) -> np.ndarray:
        """(H, W) bool of the pixels that belong to the object: the mask, else the box shrunk by
        `box_shrink` (fraction of its width/height removed, half on each side: the box's border is mostly
        background)."""
        if self.mask is not None:
            return np.asarray(self.mask, dtype=bool)
        x0, y0, x1, y1 = self.box
        dx = int(round((x1 - x0) * box_shrink / 2.0))
        dy = int(round((y1 - y0) * box_shrink / 2.0))
        out = np.zeros(shape, dtype=bool)
        out[max(0, y0 + dy) : max(0, y1 - dy), max(0, x0 + dx) : max(0, x1 - dx)] = True
        return out


@runtime_checkable
class Detector(Protocol):
    """`privileged` detectors read `observation["privileged"]` (oracle detection); the agent that holds
    one becomes privileged, and every report names it."""

    name: str
    privileged: bool

    def reset(self, seed: int) -> None:
        """Start an episode (re-seeds any noise, so results do not depend on scheduling)."""
        ...

    def detect(self, observation: dict, goal_text: str) -> list[Detection]: ...


def box_of(mask: np.ndarray) -> tuple[int, int, int, int]:
    """Tight pixel box (x0, y0, x1, y1) of a non-empty mask."""
    rows = np.flatnonzero(mask.any(axis=1))
    cols = np.flatnonzero(mask.any(axis=0))
    return int(cols[0]), int(rows[0]), int(cols[-1]) + 1, int(rows[-1]) + 1
