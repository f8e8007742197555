"""The structure map: materials split into parts with descriptors, and words matched to them."""

from __future__ import annotations

import pytest

from helpers.data import DATA
from helpers.shapes import potted_tree
from intuitf.evaluator.types import Intent
from intuitf.intent.hints import explorer_hints, intent_hints
from intuitf.intent.parts import kind_of, match_parts
from intuitf.intent.structures import StructureMap, build_structure_map


def test_a_potted_tree_splits_into_pot_trunk_and_leaves():
    smap = build_structure_map(potted_tree())
    assert smap.up_axis == 2 and smap.up_sign == 1
    bg = smap.background()
    assert len(bg) == 1 and bg[0].value_range[1] < 0.1
    fg = smap.foreground()
    pot = next(s for s in fg if s.value_range[0] > 0.7)
    trunk = next(s for s in fg if 0.4 < s.center < 0.6)
    leaves = next(s for s in fg if s.center < 0.3)
    assert pot.position == "bottom" and pot.shape in ("plate", "shell", "blob")
    assert trunk.shape in ("thin", "elongated") and trunk.extents[0] > 3 * trunk.extents[1]
    assert leaves.shape == "scattered" and leaves.position == "top" and leaves.pieces > 20
    # Words find them by their descriptors, each on its own material.
    got = match_parts(["container", "stem", "foliage"], smap)
    assert (got["container"].id, got["stem"].id, got["foliage"].id) == (
        pot.id, trunk.id, leaves.id,
    )  # fmt: skip


def test_the_map_round_trips_and_names_win():
    smap = build_structure_map(potted_tree())
    again = StructureMap.from_dict(smap.to_dict())
    assert again.to_dict() == smap.to_dict()
    trunk = next(s for s in smap.foreground() if 0.4 < s.center < 0.6)
    # A structure a model named "pot" is the pot, whatever its descriptors say.
    named = smap.named({trunk.id: "the pot"})
    assert match_parts(["container"], named)["container"].id == trunk.id
    assert kind_of("golden leaves") == "foliage" and kind_of("the casing") == "outer"


def test_part_words_land_on_their_structures():
    from intuitf.volume import Volume

    vol = Volume.from_array(potted_tree(), value_range=(0.0, 1.0))
    th = intent_hints(Intent(kind="text", text="brown pot, silver branch and golden leaves"), vol)
    by = {h.material: h for h in th.hints}
    assert set(by) == {"pot", "branch", "leaves"}
    assert all(h.placed_by == "structure" for h in th.hints)
    assert 0.75 < by["pot"].center < 0.9
    assert 0.4 < by["branch"].center < 0.6
    assert 0.12 < by["leaves"].center < 0.3
    hints = explorer_hints(Intent(kind="text", text="brown pot, golden leaves"), vol)
    assert any(h["name"] == "background" and h["hidden"] for h in hints)


@pytest.mark.skipif(not (DATA / "bonsai_256x256x256_uint8.raw.gz").exists(), reason="no data")
def test_real_bonsai_stands_along_y_and_its_words_land():
    from intuitf.volume import load_volume

    vol = load_volume(DATA / "bonsai_256x256x256_uint8.raw.gz", max_dim=96)
    th = intent_hints(
        Intent(kind="text", text="A potted tree with brown pot, silver branch and golden leaves"),
        vol,
    )
    by = {h.material: h for h in th.hints}
    # Looked at in slices: pot wall >= 0.73, trunk and soil 0.27-0.72, leaves 0.13-0.26.
    assert by["pot"].center > 0.72
    assert 0.3 < by["branch"].center < 0.7
    assert 0.12 < by["leaves"].center < 0.27
    from intuitf.intent.hints import structure_map_of

    assert structure_map_of(vol).up_axis == 1  # the tree grows along +y in this scan


@pytest.mark.skipif(not (DATA / "bonsai_256x256x256_uint8.raw.gz").exists(), reason="no data")
def test_the_branch_is_the_trunk_not_the_soil_the_pot_encloses():
    from intuitf.volume import load_volume

    # At 64³ the soil in the pot (0.48-0.69) is one branching piece, larger than the trunk
    # (0.29-0.46): the word "branch" goes to the one standing in the open.
    vol = load_volume(DATA / "bonsai_256x256x256_uint8.raw.gz", max_dim=64)
    th = intent_hints(Intent(kind="text", text="brown pot, silver branch, golden leaves"), vol)
    by = {h.material: h for h in th.hints}
    assert 0.27 < by["branch"].center < 0.47
    assert by["pot"].center > 0.72 and by["leaves"].center < 0.27


@pytest.mark.skipif(not (DATA / "engine_256x256x128_uint8.raw.gz").exists(), reason="no data")
@pytest.mark.parametrize("max_dim", [64, 96, None])
def test_the_engines_outer_part_is_its_casing_at_any_loaded_size(max_dim):
    """Loaded at 64³, the engine's map has a handful of small parts of low values (0.15-0.26,
    the casing's blurred edge, 6 % of the object and less) beside its casing (0.28-0.48,
    34 %): ranked by density first, "outer part" went to the largest of those edges. An
    outer part is a large share of the object, whatever the size it was loaded at."""
    from intuitf.volume import load_volume

    vol = load_volume(DATA / "engine_256x256x128_uint8.raw.gz", max_dim=max_dim)
    text = "light blue translucent outer part and orange solid inner part"
    by = {h.material: h for h in intent_hints(Intent(kind="text", text=text), vol).hints}
    # Looked at in slices: the casing 0.28-0.62, the dense inner parts above 0.66.
    assert 0.28 < by["outer part"].center < 0.62
    assert by["inner part"].center > 0.66


@pytest.mark.parametrize(
    ("name", "bone_from", "max_dim"),
    [
        # Looked at in slices: the chest's ribs and spine above 0.42, the head's skull above 0.53.
        ("chestlidc2_256x256x133_uint8.raw.gz", 0.42, 64),
        ("chestlidc2_256x256x133_uint8.raw.gz", 0.42, None),
        ("ctheadstanford_256x256x113_uint16.raw.gz", 0.53, 64),
        ("ctheadstanford_256x256x113_uint16.raw.gz", 0.53, None),
    ],
)
def test_bone_is_the_bone_not_the_soft_tissue_around_it(name, bone_from, max_dim):
    """Ivory bone on a CT: the soft tissue is the body's main material and not the lowest
    one when a thin material of blurred edges (or the patient table) lies below it; with
    nothing else against it, its share won "bone" over the ribs and the skull."""
    from intuitf.volume import load_volume

    if not (DATA / name).exists():
        pytest.skip("no data")
    vol = load_volume(DATA / name, max_dim=max_dim)
    th = intent_hints(Intent(kind="text", text="ivory bone and faint red skin"), vol)
    bone = next(h for h in th.hints if h.material == "bone")
    assert bone.placed_by == "structure" and bone.center > bone_from
