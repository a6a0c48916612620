"""ORACLE DETECTION: the goal detector computed from the semantic frame (privileged), with a noise model.

Why: no pretrained detector can be installed here. The oracle reads the semantic frame and the scene's
instance -> category map through `observation["privileged"]` (an explicit privileged channel), so every
agent that uses it is privileged and every report says "oracle detection".

Per frame (see `DetectorConfig` for the numbers): instances covering at least `min_frame_share` of the
frame are candidates, in increasing id order. A goal instance (the episode's goal set, which includes the
children categories, or any instance whose category is the goal text) is reported with probability
1 - miss_rate. Any other instance with a category is reported as the goal with a probability that grows
with the MiniLM similarity of its category to the goal text, so "sofa" for "couch" is a likely confusion
and "toaster" for "couch" a rare one. Draws come from a generator re-seeded per episode.
"""

from __future__ import annotations

import numpy as np

from ovon.models.config import DetectorConfig
from ovon.models.detectors.base import Detection, box_of


class OracleDetector:
    name = "oracle detection"
    privileged = True

    def __init__(self, cfg: DetectorConfig | None = None, text_encoder=None) -> None:
        self.cfg = cfg or DetectorConfig()
        self._text = text_encoder  # TextEncoder (list[str] -> (N, dim)); MiniLM when None
        self._sims: dict[tuple[str, str], float] = {}
        self._scene_key: object = None
        self._lut = np.zeros(1, dtype=np.int64)  # instance id -> index into self._cats (-1 = none)
        self._cats: list[str] = []
        self.rng = np.random.default_rng(self.cfg.seed)

    def reset(self, seed: int) -> None:
        self.rng = np.random.default_rng([int(self.cfg.seed), int(seed) & 0xFFFFFFFF])

    # -- text similarity ------------------------------------------------------------------------
    @property
    def text(self):
        if self._text is None:
            from ovon.models.encoders import make_text_encoder

            self._text = make_text_encoder()
        return self._text

    def similarity(self, category: str, goal: str) -> float:
        """Cosine similarity of the two texts' embeddings (cached per pair)."""
        key = (category, goal)
        if key not in self._sims:
            e = np.asarray(self.text.encode([category, goal]), dtype=np.float64)
            e /= np.maximum(np.linalg.norm(e, axis=1, keepdims=True), 1e-12)
            self._sims[key] = float(e[0] @ e[1])
        return self._sims[key]

    def false_positive_probability(self, category: str, goal: str) -> float:
        cfg = self.cfg
        if cfg.fp_rate <= 0.0:
            return 0.0
        s = self.similarity(category, goal)
        x = min(1.0, max(0.0, (s - cfg.fp_min_similarity) / (1.0 - cfg.fp_min_similarity)))
        return cfg.fp_rate * x**cfg.fp_power

    # -- scene ----------------------------------------------------------------------------------
    def _set_scene(self, world) -> None:
        key = world.key or id(world)  # an unnamed scene (scene_id "") is told apart by identity
        if key == self._scene_key:
            return
        objs = [o for o in world.scene.objects if o.category]
        self._cats = sorted({o.category for o in objs})
        index = {c: i for i, c in enumerate(self._cats)}
        size = max((o.id for o in objs), default=0) + 1
        self._lut = np.full(size, -1, dtype=np.int64)
        for o in objs:
            self._lut[o.id] = index[o.category]
        self._scene_key = key

    # -- detection ------------------------------------------------------------------------------
    def detect(self, observation: dict, goal_text: str) -> list[Detection]:
        p = observation.get("privileged")
        if p is None:
            raise RuntimeError(
                "the oracle detector reads observation['privileged'] (semantic frame + instance categories); "
                "the agent holding it must declare privileged = True"
            )
        self._set_scene(p.world)
        sem = np.asarray(p.frame.semantic)
        counts = np.bincount(sem.ravel().clip(min=0))
        need = self.cfg.min_frame_share * sem.size
        ids = np.flatnonzero(counts >= max(need, 1))
        ids = ids[ids > 0]
        goal_ids = p.goal_ids
        out: list[Detection] = []
        for iid in ids.tolist():
            cat_i = int(self._lut[iid]) if iid < self._lut.size else -1
            category = self._cats[cat_i] if cat_i >= 0 else None
            if iid in goal_ids or category == goal_text:
                if self.rng.random() < self.cfg.miss_rate:
                    continue
                score = 1.0
            elif category is not None:
                prob = self.false_positive_probability(category, goal_text)
                if prob <= 0.0 or self.rng.random() >= prob:
                    continue
                score = self.similarity(category, goal_text)
            else:
                continue
            mask = sem == iid
            out.append(Detection(box=box_of(mask), score=float(score), label=goal_text, mask=mask))
        return out
