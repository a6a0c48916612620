"""Looks that carry meaning (issue 37): siblings of a shape family look different, synonyms look alike, and
dressing a house changes colours only, never geometry or navigability."""

from __future__ import annotations

import numpy as np
import pytest

from ovon.scenes.procedural import generate_house
from ovon.scenes.procedural.config import HouseConfig
from ovon.scenes.procedural.looks import PATTERNS, look_key, look_of, split_faces, synonym_groups
from ovon.scenes.procedural.seeds import PRETRAIN_BASE, house_seed, is_pretrain_house
from ovon.scenes.vocabulary import load_vocabulary


@pytest.fixture(scope="module")
def vocab():
    return load_vocabulary()


def test_synonym_groups_name_known_categories_of_one_family(vocab) -> None:
    seen: set[str] = set()
    for group in synonym_groups():
        assert len(group) >= 2
        assert all(n in vocab for n in group), group
        assert len({vocab[n].family for n in group}) == 1, group
        assert not seen & set(group), group
        seen |= set(group)


def test_synonyms_share_a_look_and_siblings_differ(vocab) -> None:
    assert look_of(vocab["couch"], vocab) == look_of(vocab["sofa"], vocab)
    assert look_of(vocab["tv"], vocab) == look_of(vocab["television"], vocab)
    assert look_of(vocab["fridge"], vocab) == look_of(vocab["refrigerator"], vocab)
    # within every family, distinct look keys get distinct looks
    by_family: dict[str, dict[str, object]] = {}
    for name in vocab.names:
        fam = by_family.setdefault(vocab[name].family, {})
        fam[look_key(name)] = look_of(vocab[name], vocab)
    for family, looks in by_family.items():
        values = [(lk.pattern, lk.accent, lk.accent_parts) for lk in looks.values()]
        assert len(set(values)) == len(values), family
    chair, office = look_of(vocab["chair"], vocab), look_of(vocab["office chair"], vocab)
    assert (chair.pattern, chair.accent) != (office.pattern, office.accent)
    assert {lk.pattern for looks in by_family.values() for lk in looks.values()} <= set(PATTERNS)


def test_looks_change_colours_not_geometry() -> None:
    dressed = generate_house(4)
    plain = generate_house(4, cfg=HouseConfig(looks="family"))
    assert [o.category for o in dressed.objects] == [o.category for o in plain.objects]
    for a, b in zip(dressed.objects, plain.objects):
        np.testing.assert_allclose(a.aabb_min, b.aabb_min, atol=1e-5)
        np.testing.assert_allclose(a.aabb_max, b.aabb_max, atol=1e-5)

    # the same surface: per instance, the dressed faces cover the same area
    def area(scene, iid):
        V, F = scene.mesh.vertices.astype(np.float64), scene.mesh.faces[scene.mesh.face_instance == iid]
        return np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1).sum() / 2

    for o in dressed.objects[-20:]:
        assert area(dressed, o.id) == pytest.approx(area(plain, o.id), rel=1e-4)
    again = generate_house(4)
    np.testing.assert_array_equal(dressed.mesh.face_colors, again.mesh.face_colors)


def test_split_faces_keeps_area_and_cuts_on_the_plane() -> None:
    V = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]])
    F = np.array([[0, 1, 2]], dtype=np.int32)
    V2, F2, K = split_faces(V, F, np.array([7.0]), np.array([1.0, 0, 0]), 0.3)
    assert len(F2) == 3 and (K == 7).all()
    area = np.linalg.norm(np.cross(V2[F2[:, 1]] - V2[F2[:, 0]], V2[F2[:, 2]] - V2[F2[:, 0]]), axis=1).sum() / 2
    assert area == pytest.approx(0.5)
    centres = V2[F2].mean(axis=1)[:, 0]
    assert ((centres < 0.3) | (centres > 0.3)).all()


def test_pretrain_houses_are_disjoint_from_every_dataset_seed() -> None:
    from ovon.scenes.procedural.seeds import MAX_DATASET_SEED

    last_val = house_seed(MAX_DATASET_SEED, "val", 19_999)
    assert house_seed(0, "pretrain", 0) == PRETRAIN_BASE > last_val
    assert is_pretrain_house(house_seed(0, "pretrain", 5)) and not is_pretrain_house(house_seed(0, "val", 0))
    with pytest.raises(ValueError, match="pretrain holds at most"):
        house_seed(0, "pretrain", 10**6)
