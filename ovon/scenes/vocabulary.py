"""The household vocabulary: categories with shape family, sizes, placement, rooms and colours, plus the
raw-label cleaning table. Both live in data files under `ovon/scenes/data/`.

Why a shape family: synonyms (couch / sofa) must *look* alike in the embedded world and unrelated
categories must not, otherwise the val_seen_synonyms / val_unseen splits would measure nothing.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field, replace
from functools import lru_cache
from importlib import resources
from typing import Literal

import yaml

Placement = Literal["floor", "surface", "wall", "ceiling"]

# Room types of the procedural houses (and HM3DSem region names we map onto them).
ROOM_TYPES: tuple[str, ...] = (
    "living room",
    "kitchen",
    "dining room",
    "bedroom",
    "bathroom",
    "office",
    "hallway",
    "laundry room",
    "garage",
    "closet",
    "entryway",
    "playroom",
    "gym",
)

# Shape families the procedural generator knows how to build. Synonymous categories share one;
# each family has a distinct silhouette.
FAMILIES: dict[str, str] = {
    "sofa": "long low seat with back and arm rests",
    "armchair": "single seat with back and arm rests",
    "chair": "four legs, seat, tall back",
    "stool": "round seat on legs, no back",
    "bench": "long seat on legs, no back",
    "bed": "mattress on a frame with headboard",
    "table": "top on four legs",
    "round_table": "round top on a central post",
    "desk": "top on two side panels",
    "counter": "solid box with an overhanging top",
    "cabinet": "closed box with door lines",
    "dresser": "box with rows of drawers",
    "wardrobe": "tall closed box",
    "shelf": "open frame with several boards",
    "appliance": "box with a handle/panel front (fridge, washer, oven)",
    "stove": "box with burner discs on top",
    "toilet": "bowl on a base with a tank",
    "sink": "basin on a pedestal or in a counter",
    "bathtub": "open long box",
    "shower": "tall glass-walled box",
    "screen": "thin flat panel on a small stand",
    "wall_flat": "thin panel flush on a wall (picture, mirror, board)",
    "wall_box": "small box mounted on a wall",
    "lamp": "base, thin pole, shade",
    "ceiling_light": "disc hanging under the ceiling",
    "plant": "pot with a sphere-ish crown",
    "bin": "open cylinder",
    "container": "closed cylinder (bottle, vase, can)",
    "box": "small closed box",
    "bowl": "short wide cylinder",
    "cushion": "soft flat box",
    "rug": "very thin floor slab",
    "rod": "thin vertical cylinder",
    "sphere": "ball",
    "fan": "disc with blades on a pole",
    "instrument": "piano-like box on legs",
    "fireplace": "box with an opening against a wall",
    "radiator": "low ribbed panel against a wall",
    "window_frame": "frame on a wall",
    "curtain": "tall thin cloth panel on a wall",
    "towel": "thin hanging cloth",
    "clothes": "soft heap",
    "book": "thin small box",
    "device": "small flat box (laptop, router, speaker)",
    "cone": "cone or pyramid",
}


@dataclass(frozen=True)
class Category:
    name: str
    raw_labels: tuple[str, ...]  # variants seen in annotations (the canonical name included)
    family: str  # key of FAMILIES
    size_min: tuple[float, float, float]  # width (x), height (y), depth (z) in metres
    size_max: tuple[float, float, float]
    placement: Placement
    rooms: dict[str, float]  # room type -> affinity weight (> 0)
    colors: tuple[tuple[int, int, int], ...]  # base RGB colours; instances vary around one of them
    is_surface: bool = False  # small objects can be placed on top of it
    frequency: float = 1.0  # relative chance of being placed when its room is furnished (from HM3DSem counts)
    hm3dsem_instances: int = 0  # instances of this category in HM3DSem v0.2 (after cleaning)


# mpcat40 classes of habitat-sim's HM3DSem table that are parts of the building, not objects
STRUCTURAL_MPCAT40 = frozenset({"wall", "floor", "ceiling", "door", "window", "stairs", "railing", "beam", "column"})
LABEL_OUTCOMES = ("mapped", "structural", "free text", "unmapped")


def normalize_label(raw: str) -> str:
    return " ".join(raw.strip().lower().replace("_", " ").split())


@dataclass(frozen=True)
class LabelMap:
    """Raw annotation label -> canonical vocabulary category, or why it is not a goal category.

    Order (first match wins): our mapping (vocabulary raw labels + `mapping` of label_map.yaml), the same
    after habitat-sim's typo fix and after dropping a room prefix ("kitchen sink"); free text (a `vague`
    label or head noun: "clutter", "kitchen appliance", habitat-sim's "unknown"); structural (a drop
    word as head noun, habitat-sim's mpcat40 class is a building part, or a structural word with a part
    noun as head: "door frame", "ceiling vent"); free text again for "<x> of <y>" ("basket of
    something"); else unmapped (an object name outside the vocabulary). Only mapped labels are goals.
    """

    mapping: dict[str, str]
    drop_words: tuple[str, ...]
    provenance: str = ""
    typo_fixes: dict[str, str] = field(default_factory=dict)  # habitat-sim: raw -> cleaned name
    mpcat40: dict[str, str] = field(default_factory=dict)  # habitat-sim: raw -> mpcat40 class
    structural_words: tuple[str, ...] = ()
    part_words: tuple[str, ...] = ()
    vague: tuple[str, ...] = ()
    room_prefixes: tuple[str, ...] = ()
    fixtures: tuple[str, ...] = ()  # whole labels that are building fixtures (taps, rods, sensors)

    def classify(self, raw: str) -> tuple[str | None, str]:
        """(category or None, outcome) with outcome one of LABEL_OUTCOMES (or "empty")."""
        label = normalize_label(raw)
        if not label:
            return None, "empty"
        hit = self._lookup(label)
        if hit is not None:
            return hit, "mapped"
        if self._vague(label):  # before habitat's fixes, which turn e.g. "wall decoration" into "picture"
            return None, "free text"
        fixed = self.typo_fixes.get(label, label)
        hit = self._lookup(fixed)
        if hit is not None:
            return hit, "mapped"
        words = re.findall(r"[a-z0-9]+", fixed)
        if not words or self._vague(fixed) or fixed == "unknown":
            return None, "free text"
        head = words[-1]
        if (
            head in self.drop_words
            or fixed in self.fixtures
            or label in self.fixtures
            or self.mpcat40.get(label) in STRUCTURAL_MPCAT40
            or (head in self.part_words and any(w in self.structural_words for w in words[:-1]))
        ):
            return None, "structural"
        if " of " in f" {fixed} ":
            return None, "free text"
        return None, "unmapped"

    def _vague(self, label: str) -> bool:
        words = re.findall(r"[a-z0-9]+", label)
        return label in self.vague or bool(words) and words[-1] in self.vague

    def _lookup(self, label: str) -> str | None:
        if label in self.mapping:
            return self.mapping[label]
        for prefix in self.room_prefixes:
            if label.startswith(prefix + " ") and label[len(prefix) + 1 :] in self.mapping:
                return self.mapping[label[len(prefix) + 1 :]]
        return None

    def clean(self, raw: str) -> str | None:
        """Canonical category for an annotated label, or None when it is not a goal category."""
        return self.classify(raw)[0]


def label_coverage(label_map: LabelMap, counts: dict[str, int]) -> dict:
    """Shares of instances per outcome over a {raw label: instance count} table, plus the biggest
    labels of each non-mapped outcome (what to add to label_map.yaml next)."""
    total = sum(counts.values())
    by: dict[str, int] = dict.fromkeys(LABEL_OUTCOMES, 0)
    top: dict[str, list] = {k: [] for k in LABEL_OUTCOMES}
    cats: dict[str, int] = {}
    for raw, n in sorted(counts.items(), key=lambda kv: (-kv[1], kv[0])):
        cat, outcome = label_map.classify(raw)
        outcome = "free text" if outcome == "empty" else outcome
        by[outcome] += n
        top[outcome].append((raw, n))
        if cat is not None:
            cats[cat] = cats.get(cat, 0) + n
    return {
        "instances": total,
        "labels": len(counts),
        "instances_by_outcome": by,
        "share_by_outcome": {k: (v / total if total else 0.0) for k, v in by.items()},
        "labels_by_outcome": {k: len(v) for k, v in top.items()},
        "top_labels": {k: v[:15] for k, v in top.items()},
        "categories": len(cats),
        "instances_by_category": dict(sorted(cats.items(), key=lambda kv: (-kv[1], kv[0]))),
    }


@dataclass
class Vocabulary:
    categories: dict[str, Category] = field(default_factory=dict)
    label_map: LabelMap | None = None

    def __getitem__(self, name: str) -> Category:
        try:
            return self.categories[name]
        except KeyError:
            close = [c for c in self.categories if name.split()[-1] in c][:5]
            raise KeyError(
                f"unknown category {name!r}; {len(self.categories)} categories are known"
                + (f", close ones: {close}" if close else "")
                + " (see `ovon scenes vocabulary` for the list)"
            ) from None

    def __contains__(self, name: str) -> bool:
        return name in self.categories

    def __len__(self) -> int:
        return len(self.categories)

    @property
    def names(self) -> list[str]:
        return sorted(self.categories)

    def family_members(self, family: str) -> list[str]:
        return sorted(c.name for c in self.categories.values() if c.family == family)

    def for_room(self, room: str, placement: Placement | None = None) -> list[Category]:
        return [
            c for c in self.categories.values() if room in c.rooms and (placement is None or c.placement == placement)
        ]

    def clean(self, raw: str) -> str | None:
        assert self.label_map is not None
        return self.label_map.clean(raw)


def _tuple3(v, where: str) -> tuple[float, float, float]:
    if not (isinstance(v, list | tuple) and len(v) == 3):
        raise ValueError(f"{where}: expected [width, height, depth], got {v!r}")
    return tuple(float(x) for x in v)  # type: ignore[return-value]


def _color(v, where: str) -> tuple[int, int, int]:
    if isinstance(v, str):
        s = v.lstrip("#")
        if len(s) != 6:
            raise ValueError(f"{where}: colour {v!r} is not #RRGGBB")
        return (int(s[0:2], 16), int(s[2:4], 16), int(s[4:6], 16))
    if isinstance(v, list | tuple) and len(v) == 3:
        return tuple(int(x) for x in v)  # type: ignore[return-value]
    raise ValueError(f"{where}: bad colour {v!r}")


def parse_vocabulary(
    cats_doc: dict,
    map_doc: dict,
    source: str = "",
    habitat_table: tuple[dict[str, str], dict[str, str]] | None = None,
    counts: dict[str, int] | None = None,
) -> Vocabulary:
    """Vocabulary from its two YAML documents; `habitat_table` = (typo fixes, mpcat40) of habitat-sim's
    HM3DSem table; `counts` = HM3DSem instance counts per raw label, which set the placement frequencies."""
    cats: dict[str, Category] = {}
    for i, entry in enumerate(cats_doc.get("categories", [])):
        where = f"{source} categories[{i}] ({entry.get('name', '?')})"
        try:
            name = str(entry["name"]).strip().lower()
            family = str(entry["family"])
            if family not in FAMILIES:
                raise ValueError(f"{where}: family {family!r} is not one of {sorted(FAMILIES)}")
            placement = entry["placement"]
            if placement not in ("floor", "surface", "wall", "ceiling"):
                raise ValueError(f"{where}: placement {placement!r} must be floor/surface/wall/ceiling")
            rooms = {str(k): float(v) for k, v in dict(entry["rooms"]).items()}
            bad_rooms = set(rooms) - set(ROOM_TYPES)
            if bad_rooms:
                raise ValueError(f"{where}: unknown room types {sorted(bad_rooms)}; valid: {list(ROOM_TYPES)}")
            raw = tuple(dict.fromkeys([name, *[str(r).lower() for r in entry.get("raw_labels", [])]]))
            cat = Category(
                name=name,
                raw_labels=raw,
                family=family,
                size_min=_tuple3(entry["size_min"], where),
                size_max=_tuple3(entry["size_max"], where),
                placement=placement,
                rooms=rooms,
                colors=tuple(_color(c, where) for c in entry["colors"]),
                is_surface=bool(entry.get("is_surface", False)),
                frequency=float(entry.get("frequency", 1.0)),
            )
        except KeyError as e:
            raise ValueError(f"{where}: missing key {e}") from None
        if name in cats:
            raise ValueError(f"{where}: duplicate category {name!r}")
        if any(a > b for a, b in zip(cat.size_min, cat.size_max)):
            raise ValueError(f"{where}: size_min {cat.size_min} exceeds size_max {cat.size_max}")
        cats[name] = cat
    mapping = {str(k).lower(): str(v).lower() for k, v in dict(map_doc.get("mapping", {})).items()}
    for cat in cats.values():
        for raw in cat.raw_labels:
            mapping.setdefault(raw, cat.name)
    drop = tuple(str(w).lower() for w in map_doc.get("drop_words", []))

    def words(key: str) -> tuple[str, ...]:
        return tuple(normalize_label(str(w)) for w in map_doc.get(key, []))

    fixes, mpcat = habitat_table or ({}, {})
    label_map = LabelMap(
        mapping,
        drop,
        str(map_doc.get("provenance", "")),
        fixes,
        mpcat,
        words("structural_words"),
        words("part_words"),
        words("vague"),
        words("room_prefixes"),
        words("fixtures"),
    )
    vocab = Vocabulary(cats, label_map)
    if counts:
        vocab.categories = _real_frequencies(vocab, counts)
    return vocab


@lru_cache(maxsize=1)
def load_vocabulary() -> Vocabulary:
    """The embedded vocabulary shipped with the package."""
    data = resources.files("ovon.scenes") / "data"
    # libyaml's safe loader when PyYAML has it (5x faster; every env worker parses these at start)
    loader = getattr(yaml, "CSafeLoader", yaml.SafeLoader)
    cats_doc = yaml.load((data / "vocabulary.yaml").read_text(), Loader=loader)  # noqa: S506 - a safe loader
    map_doc = yaml.load((data / "label_map.yaml").read_text(), Loader=loader)  # noqa: S506
    return parse_vocabulary(
        cats_doc,
        map_doc,
        source="ovon/scenes/data/vocabulary.yaml",
        habitat_table=habitat_table(),
        counts=hm3dsem_counts(),
    )


def habitat_table() -> tuple[dict[str, str], dict[str, str]]:
    """habitat-sim's HM3DSem mapping table (MIT): (raw -> cleaned name, raw -> mpcat40 class)."""
    text = (resources.files("ovon.scenes") / "data" / "hm3dsem_category_mappings.tsv").read_text(encoding="utf-8")
    fixes: dict[str, str] = {}
    mpcat: dict[str, str] = {}
    for line in text.splitlines()[1:]:
        parts = line.split("\t")
        if len(parts) != 3:
            continue
        raw = normalize_label(parts[0])
        fixes[raw] = normalize_label(parts[1])
        mpcat[raw] = parts[2].strip()
    return fixes, mpcat


@lru_cache(maxsize=1)
def hm3dsem_counts() -> dict[str, int]:
    """Instance count of every raw label in HM3DSem v0.2 (normalised labels, duplicates summed)."""
    text = (resources.files("ovon.scenes") / "data" / "hm3dsem_v0.2_raw_label_counts.csv").read_text(encoding="utf-8")
    out: dict[str, int] = {}
    for line in text.splitlines()[1:]:
        label, sep, n = line.rpartition(";")
        if sep and n.strip().isdigit():
            key = normalize_label(label)
            out[key] = out.get(key, 0) + int(n)
    return out


# Placement frequency from HM3DSem counts: sqrt keeps rare categories possible while common ones
# (chair, pillow, picture, lamp) dominate as they do in real houses; categories HM3DSem never
# annotates get the floor value.
FREQ_FLOOR, FREQ_CAP = 0.05, 8.0


def _real_frequencies(vocab: Vocabulary, counts: dict[str, int]) -> dict[str, Category]:
    per_cat: dict[str, int] = {}
    for raw, n in counts.items():
        cat = vocab.label_map.clean(raw) if vocab.label_map else None
        if cat is not None:
            per_cat[cat] = per_cat.get(cat, 0) + n
    if not per_cat:
        return vocab.categories
    med = float(sorted(per_cat.values())[len(per_cat) // 2])
    out = {}
    for name, c in vocab.categories.items():
        n = per_cat.get(name, 0)
        f = FREQ_FLOOR if n == 0 else min(FREQ_CAP, max(FREQ_FLOOR, (n / med) ** 0.5))
        out[name] = replace(c, frequency=round(f, 4), hm3dsem_instances=n)
    return out
