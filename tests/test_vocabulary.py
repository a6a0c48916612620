"""The shipped vocabulary and label map: schema, coverage, cleaning rules and synonym families."""

from __future__ import annotations

from importlib import resources

import pytest
import yaml

from ovon.scenes.vocabulary import FAMILIES, ROOM_TYPES, Vocabulary, load_vocabulary, parse_vocabulary

REQUIRED_DROP_WORDS = {"ceiling", "door", "floor", "wall", "unknown", "device", "decoration", "object"}
# Families whose wall-mounted members are thin panels (pictures, curtains, towels, screens ...).
THIN_WALL_FAMILIES = {"wall_flat", "curtain", "towel", "window_frame", "screen", "radiator"}


@pytest.fixture(scope="module")
def vocab() -> Vocabulary:
    return load_vocabulary()


@pytest.fixture(scope="module")
def label_doc() -> dict:
    return yaml.safe_load((resources.files("ovon.scenes") / "data" / "label_map.yaml").read_text())


# ---------------------------------------------------------------- size and schema


def test_many_categories(vocab: Vocabulary) -> None:
    assert len(vocab) >= 300


def test_common_hm3dsem_labels_present(vocab: Vocabulary) -> None:
    for name in [
        "chair",
        "couch",
        "bed",
        "toilet",
        "tv",
        "potted plant",
        "table",
        "cabinet",
        "sink",
        "lamp",
        "pillow",
        "towel",
        "mirror",
        "shelf",
        "stool",
        "picture",
        "plant",
        "bathtub",
        "shower",
        "refrigerator",
        "stove",
        "oven",
        "microwave",
        "dishwasher",
        "washing machine",
        "dryer",
        "desk",
        "nightstand",
        "dresser",
        "wardrobe",
        "bookshelf",
        "armchair",
        "ottoman",
        "bench",
        "rug",
        "curtain",
        "blanket",
        "book",
        "box",
        "basket",
        "bottle",
        "vase",
        "clock",
        "fan",
        "fireplace",
        "piano",
        "trash can",
        "kitchen island",
        "counter",
        "coffee table",
        "dining table",
        "side table",
        "tv stand",
        "laptop",
        "computer",
        "monitor",
        "keyboard",
        "printer",
        "speaker",
        "cushion",
        "plate",
        "bowl",
        "cup",
    ]:
        assert name in vocab, name


def test_schema(vocab: Vocabulary) -> None:
    for c in vocab.categories.values():
        assert c.name == c.name.strip().lower() and c.name, c.name
        assert c.family in FAMILIES, (c.name, c.family)
        assert c.placement in ("floor", "surface", "wall", "ceiling"), c.name
        assert all(x > 0 for x in c.size_min), (c.name, c.size_min)
        assert all(a <= b for a, b in zip(c.size_min, c.size_max)), (c.name, c.size_min, c.size_max)
        assert max(c.size_max) <= 3.6, c.name
        assert c.rooms and all(r in ROOM_TYPES and w > 0 for r, w in c.rooms.items()), (c.name, c.rooms)
        assert 1 <= len(c.colors) <= 4, c.name
        assert all(len(col) == 3 and all(0 <= v <= 255 for v in col) for col in c.colors), c.name
        assert c.frequency > 0, c.name
        assert c.name in c.raw_labels


def test_sizes_fit_placement(vocab: Vocabulary) -> None:
    for c in vocab.categories.values():
        w, h, d = c.size_max
        if c.placement == "surface":
            assert w <= 0.8 and d <= 0.8 and h <= 0.8, (c.name, c.size_max)
        elif c.placement == "wall":
            assert d <= 0.5, (c.name, c.size_max)
            if c.family in THIN_WALL_FAMILIES:
                assert d <= 0.15, (c.name, c.size_max)
        elif c.placement == "ceiling":
            assert h <= 0.8, (c.name, c.size_max)
        if c.is_surface:
            assert c.placement in ("floor", "wall"), c.name


def test_families_used_are_valid_and_mostly_used(vocab: Vocabulary) -> None:
    used = {c.family for c in vocab.categories.values()}
    assert used <= set(FAMILIES)
    assert len(used) >= len(FAMILIES) - 3, sorted(set(FAMILIES) - used)


def test_every_room_type_is_furnished(vocab: Vocabulary) -> None:
    for room in ROOM_TYPES:
        floor = vocab.for_room(room, "floor")
        assert len(floor) >= 3, room
        assert vocab.for_room(room, "wall"), room
        assert vocab.for_room(room, "surface"), room
        assert any(c.is_surface for c in floor), room


def test_surface_objects_have_a_support_in_their_rooms(vocab: Vocabulary) -> None:
    for c in vocab.categories.values():
        if c.placement != "surface":
            continue
        for room in c.rooms:
            assert any(s.is_surface for s in vocab.for_room(room, "floor")), (c.name, room)


def test_room_affinities_are_plausible(vocab: Vocabulary) -> None:
    def top_room(name: str) -> str:
        rooms = vocab[name].rooms
        return max(rooms, key=rooms.get)

    assert top_room("bed") == "bedroom"
    assert top_room("toaster") == "kitchen"
    assert vocab["toaster"].placement == "surface"
    assert top_room("bathtub") == "bathroom"
    assert top_room("toilet") == "bathroom"
    assert top_room("workbench") == "garage"
    assert top_room("treadmill") == "gym"
    assert vocab["picture"].placement == "wall" and len(vocab["picture"].rooms) >= 5
    assert vocab["ceiling fan"].placement == "ceiling"
    assert vocab["nightstand"].is_surface and vocab["kitchen island"].is_surface


# ---------------------------------------------------------------- raw labels and the label map


def test_raw_labels_are_unambiguous(vocab: Vocabulary) -> None:
    owner: dict[str, str] = {}
    for c in vocab.categories.values():
        for raw in c.raw_labels:
            assert raw == raw.strip().lower(), raw
            if raw != c.name:
                assert raw not in vocab.categories, f"raw label {raw!r} of {c.name!r} is another canonical name"
            assert owner.setdefault(raw, c.name) == c.name, f"{raw!r} claimed by {owner[raw]!r} and {c.name!r}"
            assert vocab.clean(raw) == c.name, raw


def test_label_map_file(vocab: Vocabulary, label_doc: dict) -> None:
    assert len(label_doc["provenance"]) > 200
    drop = set(label_doc["drop_words"])
    assert REQUIRED_DROP_WORDS <= drop
    mapping = label_doc["mapping"]
    assert len(mapping) >= 60
    raw_owner = {raw: c.name for c in vocab.categories.values() for raw in c.raw_labels}
    for key, target in mapping.items():
        assert target in vocab, (key, target)
        assert key not in vocab.categories, f"mapping key {key!r} would redirect a canonical category"
        assert raw_owner.get(key, target) == target, (key, target, raw_owner.get(key))
        assert vocab.clean(key) == target


def test_no_category_or_raw_label_ends_in_a_drop_word(vocab: Vocabulary) -> None:
    drop = set(vocab.label_map.drop_words)
    for c in vocab.categories.values():
        assert c.name.split()[-1] not in drop, c.name
        for raw in c.raw_labels:
            assert raw.replace("-", " ").split()[-1] not in drop, (c.name, raw)


def test_clean_whole_word_rule(vocab: Vocabulary) -> None:
    clean = vocab.clean
    for structural in [
        "wall",
        "kitchen wall",
        "Wall",
        "door",
        "front door",
        "floor",
        "ceiling",
        "unknown",
        "device",
        "decoration",
        "object",
        "wall_decoration",
        "  ",
    ]:
        assert clean(structural) is None, structural
    assert clean("floor lamp") == "floor lamp"
    assert clean("wall clock") == "wall clock"
    assert clean("wall lamp") == "wall lamp"
    assert clean("ceiling fan") == "ceiling fan"
    assert clean("door mat") == "doormat"
    assert clean("Sofa") == "sofa"
    assert clean("sofas") == "sofa"
    assert clean("love seat") == "loveseat"
    assert clean("trashcan") == "trash can"
    assert clean("fridges") == "fridge"
    assert clean("night_stand") == "nightstand"
    # extra mapping entries
    assert clean("sofa chair") == "armchair"
    assert clean("refridgerator") == "refrigerator"
    assert clean("lampshade") == "lamp"
    # labels outside the vocabulary are not goal categories (they used to pass through, which let free
    # text such as "clutter" become goals); classify() says why
    assert clean("Weird  Gadget") is None
    assert vocab.label_map.classify("Weird  Gadget") == (None, "unmapped")


# ---------------------------------------------------------------- synonym families


SYNONYMS = [
    ("couch", "sofa"),
    ("couch", "loveseat"),
    ("trash can", "garbage bin"),
    ("trash can", "wastebasket"),
    ("picture", "painting"),
    ("picture", "photo"),
    ("refrigerator", "fridge"),
    ("tv", "television"),
    ("nightstand", "bedside table"),
    ("cabinet", "cupboard"),
    ("rug", "carpet"),
    ("lamp", "table lamp"),
    ("armchair", "recliner"),
    ("shelf", "shelving"),
    ("bookshelf", "bookcase"),
    ("toilet", "commode"),
    ("dresser", "chest of drawers"),
    ("wardrobe", "armoire"),
    ("washing machine", "washer"),
    ("dryer", "clothes dryer"),
    ("stove", "range"),
    ("monitor", "computer monitor"),
    ("pillow", "cushion"),
    ("curtain", "drapes"),
    ("potted plant", "plant"),
    ("sink", "washbasin"),
    ("bathtub", "jacuzzi"),
    ("coffee table", "cocktail table"),
    ("side table", "end table"),
    ("mirror", "wall mirror"),
    ("clock", "wall clock"),
    ("whiteboard", "chalkboard"),
    ("cup", "mug"),
    ("suitcase", "luggage"),
    ("telephone", "phone"),
    ("exercise bike", "stationary bike"),
    ("bicycle", "bike"),
    ("ceiling light", "light fixture"),
    ("smoke detector", "smoke alarm"),
    ("radiator", "heater"),
]


@pytest.mark.parametrize(("a", "b"), SYNONYMS)
def test_synonyms_share_a_family(vocab: Vocabulary, a: str, b: str) -> None:
    ca, cb = vocab[a], vocab[b]
    assert ca.family == cb.family, (a, ca.family, b, cb.family)
    assert ca.placement == cb.placement, (a, b)
    for lo_a, lo_b in zip(ca.size_max, cb.size_max):
        assert 0.4 <= lo_a / lo_b <= 2.5, (a, b, ca.size_max, cb.size_max)


@pytest.mark.parametrize(
    ("a", "b"),
    [
        ("couch", "toaster"),
        ("bed", "bottle"),
        ("chair", "refrigerator"),
        ("picture", "rug"),
        ("tv", "plant"),
        ("toilet", "bookshelf"),
        ("lamp", "box"),
        ("towel", "mirror"),
    ],
)
def test_unrelated_categories_differ(vocab: Vocabulary, a: str, b: str) -> None:
    assert vocab[a].family != vocab[b].family


def test_many_synonym_groups(vocab: Vocabulary) -> None:
    # Several canonical categories per family for the val_seen_synonyms split to draw from.
    multi = [f for f in FAMILIES if len(vocab.family_members(f)) >= 2]
    assert len(multi) >= 30


# ---------------------------------------------------------------- loader errors


def _entry(**over) -> dict:
    e = {
        "name": "widget",
        "raw_labels": ["widgets"],
        "family": "box",
        "size_min": [0.1, 0.1, 0.1],
        "size_max": [0.2, 0.2, 0.2],
        "placement": "surface",
        "rooms": {"kitchen": 1.0},
        "colors": ["#112233"],
    }
    e.update(over)
    return e


def test_parse_small_vocabulary() -> None:
    v = parse_vocabulary({"categories": [_entry()]}, {"drop_words": ["wall"], "mapping": {"gizmo": "widget"}})
    assert len(v) == 1 and v["widget"].colors == ((0x11, 0x22, 0x33),)
    assert v.clean("widgets") == "widget" and v.clean("gizmo") == "widget" and v.clean("wall") is None


@pytest.mark.parametrize(
    ("over", "needle"),
    [
        ({"family": "blob"}, "family"),
        ({"rooms": {"dungeon": 1.0}}, "dungeon"),
        ({"size_min": [0.3, 0.1, 0.1]}, "size_min"),
        ({"placement": "air"}, "placement"),
        ({"colors": ["#12"]}, "colour"),
        ({"size_max": [0.2, 0.2]}, "width"),
    ],
)
def test_parse_errors_name_the_entry(over: dict, needle: str) -> None:
    with pytest.raises(ValueError) as err:
        parse_vocabulary({"categories": [_entry(name="ok thing"), _entry(**over)]}, {}, "fixture.yaml")
    msg = str(err.value)
    assert "widget" in msg and "categories[1]" in msg and needle in msg, msg


def test_parse_rejects_duplicates_and_missing_keys() -> None:
    with pytest.raises(ValueError, match="duplicate"):
        parse_vocabulary({"categories": [_entry(), _entry()]}, {})
    bad = _entry()
    del bad["placement"]
    with pytest.raises(ValueError, match="widget.*missing key"):
        parse_vocabulary({"categories": [bad]}, {})
