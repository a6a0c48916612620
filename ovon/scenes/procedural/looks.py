"""Per-category looks: within a shape family, different things look different; true synonyms look alike.

Why: a family gives one silhouette to many names (the chair family holds office chairs, dining chairs and
strollers), so with colour and size alone a learned detector cannot tell siblings apart; in HM3D an
office chair does not look like a dining chair. Each *look key* (a name, or its synonym group from
`data/looks.yaml`) gets a two-tone look: an accent colour and a surface pattern laid out on the
category's two longest axes, plus whether the parts (legs, doors, shades: faces with a part shade) take
the accent. Siblings of a family get distinct (pattern, accent) pairs, spread by a family-seeded
permutation, so the assignment is deterministic and does not depend on the instance or the house.

Patterns recolour faces after splitting them along the pattern's planes (geometry is unchanged: the
pieces cover the original triangles exactly), so navigability and the semantic frame stay as they were.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from functools import lru_cache
from importlib import resources

import numpy as np
import yaml

from ..vocabulary import Category, Vocabulary

# A fixed accent palette: saturated colours far apart from each other (RGB 0-255).
PALETTE: tuple[tuple[int, int, int], ...] = (
    (200, 40, 40), (40, 80, 200), (40, 160, 70), (235, 200, 40), (245, 245, 245), (25, 25, 25),
    (240, 130, 30), (130, 50, 170), (30, 170, 170), (235, 120, 170), (120, 80, 40), (150, 200, 60),
)  # fmt: skip
# Patterns on the (a, b) plane of the two longest axes, coordinates u, v in [0, 1]:
PATTERNS: tuple[str, ...] = (
    "plain",  # the parts only
    "bands",  # three bands across b
    "stripes",  # three stripes across a
    "halves",  # accent on the far half of a
    "end",  # accent on the last fifth of b (a top, a cap, a headboard)
    "checker",  # 3 x 3 checker
    "frame",  # a border along all four edges
    "centre",  # a centre panel
    "diagonal",  # two diagonal bands
)
MIN_ACCENT_CONTRAST = 90.0  # RGB distance below which an accent is too close to the base colour to read


@dataclass(frozen=True)
class Look:
    key: str  # the synonym group's first name (or the category itself)
    pattern: str
    accent: tuple[int, int, int]
    accent_parts: bool
    axes: tuple[int, int]  # local axes (0 = x, 1 = y, 2 = z) of the pattern's u and v

    def describe(self) -> str:
        parts = ", accent parts" if self.accent_parts else ""
        return f"{self.pattern} in rgb{self.accent}{parts}"


@lru_cache(maxsize=1)
def synonym_groups() -> tuple[tuple[str, ...], ...]:
    text = resources.files("ovon.scenes").joinpath("data/looks.yaml").read_text(encoding="utf-8")
    return tuple(tuple(g) for g in yaml.safe_load(text)["synonyms"])


@lru_cache(maxsize=1)
def _group_heads() -> dict[str, str]:
    return {name: group[0] for group in synonym_groups() for name in group}


def look_key(name: str) -> str:
    """The name whose look `name` shares (its synonym group's first name; itself when it has none). A dict
    lookup: labelling frames calls this once per visible instance."""
    return _group_heads().get(name, name)


def _axes(cat: Category) -> tuple[int, int]:
    mean = [(a + b) / 2 for a, b in zip(cat.size_min, cat.size_max)]
    first, second = sorted(range(3), key=lambda i: (-mean[i], i))[:2]
    return first, second


def _rank(family: str, text: str) -> int:
    return int.from_bytes(hashlib.sha256(f"{family}|{text}".encode()).digest()[:8], "big")


_TABLES: dict[int, tuple[Vocabulary, dict[str, Look]]] = {}  # id -> (the vocabulary kept alive, its looks)


def _family_looks(vocab: Vocabulary) -> dict[str, Look]:
    hit = _TABLES.get(id(vocab))
    if hit is not None and hit[0] is vocab:
        return hit[1]
    table = _build_looks(vocab)
    _TABLES[id(vocab)] = (vocab, table)
    return table


def _build_looks(vocab: Vocabulary) -> dict[str, Look]:
    by_family: dict[str, list[str]] = {}
    for name in sorted(vocab.categories):
        by_family.setdefault(vocab.categories[name].family, []).append(name)
    looks: dict[str, Look] = {}
    for family, names in sorted(by_family.items()):
        keys = sorted({look_key(n) for n in names}, key=lambda k: _rank(family, k))
        combos = sorted(
            ((p, a, parts) for p in PATTERNS for a in range(len(PALETTE)) for parts in (True, False)),
            key=lambda c: _rank(family, f"{c[0]}|{c[1]}|{c[2]}"),
        )
        order = {c: i for i, c in enumerate(combos)}
        used_pattern: dict[str, int] = {}
        taken: set[tuple[str, int, bool]] = set()
        for key in keys:
            cat = vocab.categories[key] if key in vocab.categories else vocab.categories[names[0]]
            base = np.asarray(cat.colors, dtype=np.float64)

            far = {
                i
                for i, p in enumerate(PALETTE)
                if np.linalg.norm(base - np.asarray(p), axis=1).min() >= MIN_ACCENT_CONTRAST
            }
            # prefer the least used pattern so siblings differ in layout, not only in accent colour
            choice = min(
                (c for c in combos if c not in taken and c[1] in far),
                key=lambda c: (used_pattern.get(c[0], 0), order[c]),
                default=next(c for c in combos if c not in taken),
            )
            taken.add(choice)
            used_pattern[choice[0]] = used_pattern.get(choice[0], 0) + 1
            looks[key] = Look(key, choice[0], PALETTE[choice[1]], choice[2], _axes(cat))
    return {name: looks[look_key(name)] for name in vocab.categories}


def look_of(cat: Category, vocab: Vocabulary) -> Look:
    return _family_looks(vocab)[cat.name]


def _pattern_planes(pattern: str, size: np.ndarray, axes: tuple[int, int]) -> list[tuple[np.ndarray, float]]:
    """Planes (normal, offset) in the local frame along which faces are cut before recolouring."""
    a, b = axes
    lo = np.array([-size[0] / 2, 0.0, -size[2] / 2])

    def at(axis: int, frac: float) -> tuple[np.ndarray, float]:
        n = np.zeros(3)
        n[axis] = 1.0
        return n, float(lo[axis] + frac * size[axis])

    cuts = {
        "plain": [],
        "bands": [at(b, f) for f in (1 / 6, 2 / 6, 3 / 6, 4 / 6, 5 / 6)],
        "stripes": [at(a, f) for f in (1 / 6, 2 / 6, 3 / 6, 4 / 6, 5 / 6)],
        "halves": [at(a, 0.5)],
        "end": [at(b, 0.8)],
        "checker": [at(a, 1 / 3), at(a, 2 / 3), at(b, 1 / 3), at(b, 2 / 3)],
        "frame": [at(a, 0.15), at(a, 0.85), at(b, 0.15), at(b, 0.85)],
        "centre": [at(a, 0.3), at(a, 0.7), at(b, 0.3), at(b, 0.7)],
    }
    if pattern == "diagonal":
        n = np.zeros(3)
        n[a], n[b] = 1.0 / size[a], 1.0 / size[b]  # u + v = const in normalised coordinates
        base = lo[a] / size[a] + lo[b] / size[b]
        return [(n, base + f) for f in (0.4, 0.8, 1.2, 1.6)]
    return cuts[pattern]


def _accent_mask(pattern: str, uv: np.ndarray) -> np.ndarray:
    u, v = uv[:, 0], uv[:, 1]
    if pattern == "plain":
        return np.zeros(len(u), dtype=bool)
    if pattern == "bands":
        return (np.floor(v * 6).astype(int) % 2) == 1
    if pattern == "stripes":
        return (np.floor(u * 6).astype(int) % 2) == 1
    if pattern == "halves":
        return u > 0.5
    if pattern == "end":
        return v > 0.8
    if pattern == "checker":
        return ((np.floor(u * 3) + np.floor(v * 3)).astype(int) % 2) == 1
    if pattern == "frame":
        return (u < 0.15) | (u > 0.85) | (v < 0.15) | (v > 0.85)
    if pattern == "centre":
        return (np.abs(u - 0.5) < 0.2) & (np.abs(v - 0.5) < 0.2)
    if pattern == "diagonal":
        s = u + v
        return ((s > 0.4) & (s < 0.8)) | ((s > 1.2) & (s < 1.6))
    raise ValueError(f"unknown pattern {pattern!r}; known: {list(PATTERNS)}")


def split_faces(
    vertices: np.ndarray, faces: np.ndarray, keep: np.ndarray, normal: np.ndarray, offset: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Cut every triangle that crosses the plane normal . x = offset into three (winding kept);
    `keep` (M,) per-face values follow their pieces. Slivers of no area are dropped."""
    d = vertices @ normal - offset
    eps = 1e-9
    side = d[faces] >= -eps  # (M, 3)
    n_pos = side.sum(axis=1)
    cross = ((n_pos == 1) | (n_pos == 2)) & (np.abs(d[faces]).max(axis=1) > eps)
    if not cross.any():
        return vertices, faces, keep
    fc = faces[cross]
    sc = side[cross]
    # the lone vertex is the one whose side differs from the other two; roll it to the front
    lone = np.where(sc.sum(axis=1) == 1, np.argmax(sc, axis=1), np.argmin(sc, axis=1))
    order = (lone[:, None] + np.arange(3)[None, :]) % 3
    tri = np.take_along_axis(fc, order, axis=1)
    A, B, C = (vertices[tri[:, i]] for i in range(3))
    dA, dB, dC = (d[tri[:, i]] for i in range(3))
    P = A + (dA / (dA - dB))[:, None] * (B - A)
    Q = A + (dA / (dA - dC))[:, None] * (C - A)
    n0 = len(vertices)
    k = len(fc)
    iP = n0 + np.arange(k)
    iQ = n0 + k + np.arange(k)
    new_faces = np.concatenate(
        [np.stack([tri[:, 0], iP, iQ], 1), np.stack([iP, tri[:, 1], tri[:, 2]], 1), np.stack([iP, tri[:, 2], iQ], 1)]
    )
    V = np.concatenate([vertices, P, Q])
    F = np.concatenate([faces[~cross], new_faces]).astype(np.int32)
    K = np.concatenate([keep[~cross], np.tile(keep[cross], 3)])
    area = np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1)
    ok = area > 1e-12
    return V, F[ok], K[ok]


def apply_look(
    vertices: np.ndarray, faces: np.ndarray, shade: np.ndarray, size: tuple[float, float, float],
    base: np.ndarray, look: Look,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:  # fmt: skip
    """(vertices, faces, per-face RGB) of a local-frame part mesh dressed in `look` (base colour x shade
    where the pattern is off, the accent x shade where it is on)."""
    sz = np.maximum(np.asarray(size, dtype=np.float64), 1e-6)
    V, F, S = vertices, faces, shade
    for normal, offset in _pattern_planes(look.pattern, sz, look.axes):
        V, F, S = split_faces(V, F, S, normal, offset)
    centre = V[F].mean(axis=1)
    lo = np.array([-sz[0] / 2, 0.0, -sz[2] / 2])
    uv = (centre[:, list(look.axes)] - lo[list(look.axes)]) / sz[list(look.axes)]
    accent = _accent_mask(look.pattern, np.clip(uv, 0.0, 1.0))
    if look.accent_parts:
        accent |= np.abs(S - 1.0) > 1e-6
    colour = np.where(accent[:, None], np.asarray(look.accent, dtype=np.float64)[None, :], base[None, :])
    return V, F, colour * S[:, None]
