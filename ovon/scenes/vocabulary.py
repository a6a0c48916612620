"""The household vocabulary: categories with shape family, sizes, placement, rooms and colours, plus the
raw-label cleaning table. Both live in data files under `ovon/scenes/data/`.

Why a shape family: synonyms (couch / sofa) must *look* alike in the embedded world and unrelated
categories must not, otherwise the val_seen_synonyms / val_unseen splits would measure nothing.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
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
    frequency: float = 1.0  # relative chance of being placed when its room is furnished


@dataclass(frozen=True)
class LabelMap:
    """raw label -> canonical category; drop words matched as whole words."""

    mapping: dict[str, str]
    drop_words: tuple[str, ...]
    provenance: str = ""

    def clean(self, raw: str) -> str | None:
        """Canonical category for an annotated label, or None when it is structural/vague."""
        label = " ".join(raw.strip().lower().replace("_", " ").split())
        if not label:
            return None
        if label in self.mapping:
            return self.mapping[label]
        # Whole-word rule: a label is structural when its head noun (last word) is a drop word, so
        # "wall" and "kitchen wall" go while "floor lamp" and "wall clock" stay (upstream's substring
        # test dropped those by accident).
        words = re.findall(r"[a-z0-9]+", label)
        if words and words[-1] in self.drop_words:
            return None
        return label


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
            c
            for c in self.categories.values()
            if room in c.rooms and (placement is None or c.placement == placement)
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


def parse_vocabulary(cats_doc: dict, map_doc: dict, source: str = "") -> Vocabulary:
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
    return Vocabulary(cats, LabelMap(mapping, drop, str(map_doc.get("provenance", ""))))


@lru_cache(maxsize=1)
def load_vocabulary() -> Vocabulary:
    """The embedded vocabulary shipped with the package."""
    data = resources.files("ovon.scenes") / "data"
    cats_doc = yaml.safe_load((data / "vocabulary.yaml").read_text())
    map_doc = yaml.safe_load((data / "label_map.yaml").read_text())
    return parse_vocabulary(cats_doc, map_doc, source="ovon/scenes/data/vocabulary.yaml")
