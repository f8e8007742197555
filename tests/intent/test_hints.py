"""Text → material hints: the words' materials, colours and opacities, placed on a volume."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from intuitf.evaluator.types import Intent
from intuitf.explorer.hints import Hint, as_hints
from intuitf.intent.hints import (
    explorer_hints,
    intent_hints,
    is_hounsfield,
    parse_text,
    place_hints,
)
from intuitf.volume import Volume

DATA = Path(
    os.environ.get("INTUITF_DATA", Path(__file__).resolve().parents[3] / "shared/data/volumes")
)


def by_material(th):
    return {h.material: h for h in th.hints}


def test_clauses_give_each_material_its_colour_and_opacity():
    th = parse_text("Opaque ivory bone, faint red skin")
    assert [(h.material, h.colour, h.opacity) for h in th.hints] == [
        ("bone", "ivory", "opaque"),
        ("skin", "red", "faint"),
    ]
    assert th.unknown == []
    # Two materials in one clause: each takes the words before it.
    th = by_material(parse_text("white bones inside translucent pink soft tissue"))
    assert (th["bone"].colour, th["bone"].opacity) == ("white", None)
    assert (th["soft tissue"].colour, th["soft tissue"].opacity) == ("pink", "semi")
    # Words after the last material of a clause describe it too.
    th = by_material(parse_text("show the bones in gold"))
    assert th["bone"].colour == "gold"


def test_says_which_words_it_does_not_understand():
    th = parse_text("a glowing cyberpunk skull in neon blue")
    assert by_material(th)["bone"].colour == "blue"
    assert th.unknown == ["glowing", "cyberpunk", "neon"]
    assert "not understood: glowing, cyberpunk, neon" in th.summary()
    assert parse_text("Studio Ghibli art style").hints == []


@pytest.mark.parametrize(
    ("text", "material", "look"),
    [
        ("opaque bone", "bone", "opaque"),
        ("the skull in white", "bone", None),
        ("faint skin", "skin", "faint"),
        ("translucent soft tissue", "soft tissue", "semi"),
        ("red blood vessels", "vessels", None),
        ("solid red arteries", "vessels", "opaque"),
        ("transparent lungs", "lungs", "faint"),
        ("blue air", "air", None),
        ("white teeth", "enamel", None),
        ("gold enamel", "enamel", None),
        ("yellow dentin", "dentin", None),
        ("red pulp", "soft tissue", None),
        ("silver metal implants", "metal", None),
        ("a semi-transparent blue engine block", "main material", "semi"),
        ("opaque orange dense parts", "dense parts", "opaque"),
        ("a red inner core", "core", None),
        ("a faint outer shell", "outline", "faint"),
        ("hide the fat", "fat", "hidden"),
        ("grey muscle", "muscle", None),
    ],
)
def test_vocabulary(text, material, look):
    th = parse_text(text)
    assert len(th.hints) == 1, th.summary()
    h = th.hints[0]
    assert (h.material, h.opacity) == (material, look)


def test_a_subject_without_colour_or_opacity_is_context():
    th = parse_text("A tooth with a blue crown, ivory dentin and a faint orange outline")
    got = [(h.material, h.colour, h.opacity) for h in th.hints]
    assert got == [
        ("crown", "blue", None),  # a part: placed on the structure the map calls a crown
        ("dentin", "ivory", None),
        ("outline", "orange", "faint"),
    ]
    # Alone, a material named without colour or opacity is still a hint (shown).
    assert [h.material for h in parse_text("show the bone").hints] == ["bone"]


def histogram(peaks, n=256, background=0.02):
    """Counts over [0, 1]: a big background mode and Gaussian peaks (center, width, voxels)."""
    x = (np.arange(n) + 0.5) / n
    c = 5e6 * np.exp(-0.5 * ((x - background) / 0.01) ** 2)
    for center, width, voxels in peaks:
        c += voxels * np.exp(-0.5 * ((x - center) / width) ** 2)
    return c + 10.0


CT = histogram([(0.30, 0.02, 4e5), (0.70, 0.03, 3e4)])


def test_placed_by_density_order_on_the_histograms_materials():
    th = place_hints(parse_text("opaque ivory bone, faint red skin, pink soft tissue"), CT)
    h = by_material(th)
    assert h["bone"].center == pytest.approx(0.70, abs=0.03)
    assert h["soft tissue"].center == pytest.approx(0.30, abs=0.03)
    # Skin is the body's surface: between the background and the tissue, off the background.
    assert 0.05 < h["skin"].center < 0.28
    assert h["skin"].center - 3 * h["skin"].spread > 0.03
    assert all(x.placed_by == "density order" for x in th.hints)


def test_density_order_is_kept_when_materials_are_few():
    tooth = histogram([(0.64, 0.015, 4e5), (0.92, 0.016, 1.3e5)], background=0.3)
    h = by_material(place_hints(parse_text("white enamel, yellow dentin, red pulp"), tooth))
    assert h["soft tissue"].center < h["dentin"].center < h["enamel"].center
    assert h["enamel"].center == pytest.approx(0.92, abs=0.03)
    assert h["dentin"].center == pytest.approx(0.64, abs=0.03)


def test_roles_for_objects_that_are_not_anatomy():
    engine = histogram(
        [(0.56, 0.017, 4e5), (0.78, 0.014, 1.4e4), (0.85, 0.016, 1.1e4)], background=0.0
    )
    th = place_hints(
        parse_text("a blue translucent engine block with opaque orange dense parts"), engine
    )
    h = by_material(th)
    assert h["main material"].center == pytest.approx(0.56, abs=0.02)
    assert h["main material"].placed_by == "main"
    assert h["dense parts"].center == pytest.approx(0.78, abs=0.02)
    assert h["main material"].height_band[1] < h["dense parts"].height_band[0]


def test_hounsfield_ranges_for_ct_in_hu():
    assert is_hounsfield((-1024.0, 3071.0), "int16")
    assert not is_hounsfield((0.0, 255.0), "uint8")
    counts = histogram([(0.26, 0.01, 4e5), (0.45, 0.05, 3e4)])
    th = place_hints(parse_text("ivory bone and yellow fat"), counts, (-1024.0, 3071.0), "int16")
    h = by_material(th)
    to_hu = lambda v: -1024.0 + v * 4095.0  # noqa: E731
    assert 300 < to_hu(h["bone"].center) < 1000
    assert -150 < to_hu(h["fat"].center) < -50
    assert {x.placed_by for x in th.hints} == {"hounsfield"}


def test_an_edit_applies_to_the_selection():
    th = intent_hints(Intent(kind="edit", text="make the crown gold", selected=(2,)))
    assert [(h.material, h.colour, h.center) for h in th.hints] == [("crown", "gold", None)]
    # With no material word, the colour still applies to the selection.
    th = intent_hints(Intent(kind="edit", text="make it gold", selected=(0,)))
    assert [(h.colour, h.center, h.placed_by) for h in th.hints] == [("gold", None, "selection")]
    hints = explorer_hints(Intent(kind="edit", text="make it gold", selected=(0,)))
    assert as_hints(hints)[0].center is None


def test_explorer_hints_are_what_the_explorer_takes():
    vol = Volume.from_array(
        np.random.default_rng(0).normal(0.3, 0.02, (16, 16, 16)).clip(0, 1).astype(np.float32)
    )
    hints = explorer_hints(Intent(kind="text", text="opaque ivory bone, faint red skin"), vol)
    got = as_hints(hints)
    assert len(got) == 2 and all(isinstance(h, Hint) for h in got)
    bone = next(h for h in got if h.name == "bone")
    assert bone.color == pytest.approx((250 / 255, 245 / 255, 225 / 255))
    assert bone.height[0] >= 0.3
    assert explorer_hints(Intent(kind="text", text="Studio Ghibli"), vol) == []
    assert explorer_hints(Intent(), vol) == []


@pytest.mark.skipif(not (DATA / "tooth_103x94x161_uint8.raw.gz").exists(), reason="no data")
def test_real_tooth_and_engine():
    from intuitf.volume import load_volume

    tooth = load_volume(DATA / "tooth_103x94x161_uint8.raw.gz")
    th = intent_hints(
        Intent(
            kind="text", text="A tooth with a blue crown, ivory dentin and a faint orange outline"
        ),
        tooth,
    )
    h = by_material(th)
    # The crown is a part: it lands on the dense cap at the top (the enamel, peak 0.92).
    assert h["crown"].placed_by == "structure" and 0.8 < h["crown"].center < 0.93
    assert h["dentin"].center == pytest.approx(0.64, abs=0.03)
    assert 0.45 < h["outline"].center < 0.55


def test_the_background_stays_hidden_unless_the_words_name_air():
    rng = np.random.default_rng(1)
    data = rng.normal(0.03, 0.01, (24, 24, 24))
    data[6:18, 6:18, 6:18] = rng.normal(0.4, 0.02, (12, 12, 12))
    data[10:14, 10:14, 10:14] = rng.normal(0.8, 0.02, (4, 4, 4))
    vol = Volume.from_array(data.clip(0, 1).astype(np.float32), value_range=(0.0, 1.0))
    hints = as_hints(
        explorer_hints(Intent(kind="text", text="opaque white bone, faint red skin"), vol)
    )
    bg = [h for h in hints if h.name == "background"]
    assert len(bg) == 1 and bg[0].hidden and bg[0].reaches(0.03)
    assert not any(bg[0].reaches(h.center) for h in hints if h.name != "background")
    with_air = explorer_hints(Intent(kind="text", text="blue air, white bone"), vol)
    assert not any(h["name"] == "background" for h in with_air)


def test_values_under_the_background_are_hidden_too():
    """A scan whose air sits at 0.3 with padding at 0 outside its field of view: the padding
    is background as well (lit, it paints a face of the box)."""
    rng = np.random.default_rng(2)
    data = rng.normal(0.3, 0.01, (24, 24, 24))
    data[:, :, :2] = 0.0  # padding along one face
    data[6:18, 6:18, 6:18] = rng.normal(0.7, 0.02, (12, 12, 12))
    vol = Volume.from_array(data.clip(0, 1).astype(np.float32), value_range=(0.0, 1.0))
    hints = as_hints(explorer_hints(Intent(kind="text", text="opaque white bone"), vol))
    hidden = [h for h in hints if h.hidden]
    assert {h.name for h in hidden} == {"background", "padding"}
    assert any(h.reaches(0.0) for h in hidden) and any(h.reaches(0.3) for h in hidden)
    assert not any(h.reaches(0.7) for h in hidden)
