"""Uniformly random moves with a small per-step STOP probability: the chance-level baseline."""

from __future__ import annotations

import numpy as np


class RandomAgent:
    privileged = False

    def __init__(self, stop_probability: float = 0.02, seed: int = 0):
        self.stop_probability = float(stop_probability)
        if not 0.0 <= self.stop_probability <= 1.0:  # also refuses NaN
            raise ValueError(
                f"--agent-arg stop_probability={stop_probability!r}: a probability in [0, 1] is "
                "expected; fix: e.g. --agent-arg stop_probability=0.02"
            )
        self.seed = int(seed)
        self.rng = np.random.default_rng(seed)

    def reset(self, episode_info: dict) -> None:
        # Re-seeded per episode so results do not depend on which worker ran which episode.
        key = f"{self.seed}:{episode_info.get('seed', 0)}:{episode_info.get('episode_id', '')}"
        self.rng = np.random.default_rng(abs(hash_str(key)))

    def act(self, observation: dict) -> int:
        if self.rng.random() < self.stop_probability:
            return 0
        return int(self.rng.integers(1, 4))


def hash_str(s: str) -> int:
    """Stable across processes (Python's hash() is salted per process)."""
    import zlib

    return zlib.crc32(s.encode())
