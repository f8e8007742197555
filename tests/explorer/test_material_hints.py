"""Material hints: part of the first population on them, mutations drawn toward them."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from intuitf.explorer import (
    Bounds,
    CMAExplorer,
    GeneticExplorer,
    MutationParams,
    explorer_from_state,
    mutate,
)
from intuitf.explorer.hints import STROKE, Hint, as_hints, hint_for, hinted_tf, keep_shown
from intuitf.tf import Gaussian, GaussianTF
from intuitf.tf.defaults import Material

IVORY = (0.98, 0.96, 0.88)
RED = (0.86, 0.12, 0.12)
BONE = Hint("bone", center=0.7, spread=0.02, color=IVORY, height=(0.3, 1.0))
SKIN = Hint("skin", center=0.2, spread=0.015, color=RED, height=(0.03, 0.15))
HINTS = (BONE.to_dict(), SKIN.to_dict())


def _histogram() -> np.ndarray:
    s = (np.arange(256) + 0.5) / 256
    h = 1e5 * np.exp(-0.5 * (s / 0.02) ** 2) + 5.0
    for c, a in ((0.3, 2e4), (0.7, 3e3)):
        h += a * np.exp(-0.5 * ((s - c) / 0.018) ** 2)
    return h


def test_hint_forms_and_checks():
    assert as_hints(HINTS) == (BONE, SKIN)
    assert Hint.from_dict(BONE.to_dict()) == BONE
    with pytest.raises(ValueError):
        Hint("x", center=1.5)
    with pytest.raises(ValueError):
        Hint("x", height=(0.5, 0.1))
    assert hint_for(0.71, (BONE, SKIN)) is BONE
    assert hint_for(0.45, (BONE, SKIN)) is None
    anywhere = Hint("selection", color=(0.8, 0.7, 0.2))
    assert hint_for(0.45, (anywhere,)) is anywhere


def test_hinted_tf_shows_what_the_words_ask_and_keeps_the_rest_quiet():
    rng = np.random.default_rng(0)
    mats = [Material(0.3, 0.018, 0.8), Material(0.7, 0.018, 0.1)]
    for _ in range(20):
        tf = hinted_tf(rng, (BONE, SKIN), mats, 5, Bounds())
        assert len(tf) == 5
        bone = min(tf.gaussians, key=lambda g: abs(g.mean - 0.7))
        skin = min(tf.gaussians, key=lambda g: abs(g.mean - 0.2))
        assert abs(bone.mean - 0.7) < 0.02 and 0.3 <= bone.height <= 1.0
        assert abs(skin.mean - 0.2) < 0.02 and 0.03 <= skin.height <= 0.15
        assert np.abs(np.subtract(bone.color, IVORY)).max() < 0.25
        assert np.abs(np.subtract(skin.color, RED)).max() < 0.25
        others = [g for g in tf.gaussians if g is not bone and g is not skin]
        assert all(g.height <= 0.03 for g in others)  # hidden or faint
    hidden = Hint("fat", center=0.3, spread=0.02, hidden=True)
    tf = hinted_tf(rng, (hidden,), mats, 2, Bounds())
    assert min(tf.gaussians, key=lambda g: abs(g.mean - 0.3)).height == 0.0


def test_a_structures_values_beyond_its_hints_spreads_take_its_colour():
    """The engine's outer part holds values 0.31-0.59; its hint sits where it meets the air
    (0.41) and its bulk (0.56) was a leftover material with any colour, 70 % of the time
    hidden. Now the bulk gets a Gaussian of the outer part's colour and look."""
    blue = (0.59, 0.75, 0.94)
    outer = Hint("outer part", center=0.41, spread=0.05, color=blue, height=(0.08, 0.4),
                 reach=(0.31, 0.59))  # fmt: skip
    assert outer.reaches(0.56) and not outer.reaches(0.65)
    assert Hint.from_dict(outer.to_dict()) == outer
    with pytest.raises(ValueError, match="reach"):
        Hint("x", center=0.4, reach=(0.6, 0.3))
    mats = [Material(0.56, 0.017, 0.56), Material(0.78, 0.014, 0.02)]
    rng = np.random.default_rng(0)
    for _ in range(20):
        tf = hinted_tf(rng, (outer,), mats, 4, Bounds())
        bulk = min(tf.gaussians, key=lambda g: abs(g.mean - 0.56))
        assert abs(bulk.mean - 0.56) < 1e-6 and 0.08 <= bulk.height <= 0.4
        assert np.abs(np.subtract(bulk.color, blue)).max() < 0.25
    # Without a reach the bulk is a material nobody named: never the outer part's Gaussian.
    plain = Hint("outer part", center=0.41, spread=0.05, color=blue, height=(0.08, 0.4))
    tf = hinted_tf(np.random.default_rng(0), (plain,), mats, 4, Bounds())
    assert not plain.reaches(0.56)
    assert all(g.height <= 0.03 for g in tf.gaussians if abs(g.mean - 0.56) < 1e-6)


def test_a_hinted_gaussian_keeps_its_tail_off_another_named_materials_values():
    """An orange inner part (0.74, spread 0.06) drawn 0.08 wide gave the blue outer part's
    highest values (0.59) 14 % of its height: orange faces on the outer part."""
    from intuitf.explorer.hints import NEIGHBOUR_TAIL

    outer = Hint("outer part", center=0.41, spread=0.05, color=(0.59, 0.75, 0.94),
                 reach=(0.31, 0.59))  # fmt: skip
    inner = Hint("inner part", center=0.74, spread=0.06, color=(1.0, 0.55, 0.0),
                 height=(0.4, 1.0), reach=(0.66, 0.9))  # fmt: skip
    rng = np.random.default_rng(1)
    widths = []
    for _ in range(40):
        tf = hinted_tf(rng, (outer, inner), [], 3, Bounds())
        g = min(tf.gaussians, key=lambda g: abs(g.mean - 0.74))
        widths.append(g.width)
        tail = np.exp(-((g.mean - 0.59) ** 2) / (2 * g.width**2))
        assert tail <= NEIGHBOUR_TAIL + 1e-9
    assert max(widths) > 0.045  # narrowed only as far as needed
    # A sketch's strokes have no structure's values: strokes on one material overlap on
    # purpose, and their Gaussians keep their widths.
    # (Kept off the red stroke's spreads, 0.83-0.93, the blue one would be at most 0.03 wide.)
    red = Hint("stroke", center=0.88, spread=0.02, color=(0.86, 0.12, 0.12))
    yellow = Hint("stroke", center=0.89, spread=0.03, color=(1.0, 0.86, 0.0))
    blue = Hint("stroke", center=0.75, spread=0.03, color=(0.25, 0.4, 0.9))
    rng = np.random.default_rng(2)
    blues = []
    for _ in range(40):
        a = hinted_tf(rng, (red, yellow, blue), [], 3, Bounds())
        blues.append(max(g.width for g in a.gaussians if abs(g.mean - 0.75) < 0.03))
    assert max(blues) > 0.04


def test_a_hints_colour_is_the_named_colour_not_a_neighbour():
    """Copies of a hint's colour vary only a little: "orange" stays orange (within ΔE2000 8
    nine times in ten), where a palette colour's full variation reached gold often."""
    from skimage.color import deltaE_ciede2000, rgb2lab

    orange = Hint("inner part", center=0.7, spread=0.03, color=(1.0, 140 / 255, 0.0))
    rng = np.random.default_rng(3)
    cols = []
    for _ in range(200):
        tf = hinted_tf(rng, (orange,), [], 1, Bounds())
        cols.append(tf.gaussians[0].color)
    lab = rgb2lab(np.asarray(cols, dtype=np.float64)[None])[0]
    target = rgb2lab(np.asarray(orange.color, dtype=np.float64)[None, None])[0, 0]
    de = deltaE_ciede2000(np.broadcast_to(target, lab.shape), lab)
    assert (de < 8).mean() >= 0.85
    assert len({tuple(c) for c in cols}) == len(cols)  # still apart: no duplicates


def test_first_population_holds_hinted_candidates():
    ex = GeneticExplorer(population=30, n_gaussians=5, seed=1, histogram=_histogram(), hints=HINTS)
    pop = ex.ask()
    hinted = [c for c in pop if c.origin == "hint"]
    assert len(hinted) == 15  # hint_share 0.5
    assert sum(c.origin == "seed" for c in pop) >= 10  # histogram seeds still there
    # Without hints nothing changes: the same seed gives the same population as before.
    a = GeneticExplorer(population=12, seed=4, histogram=_histogram())
    b = GeneticExplorer(population=12, seed=4, histogram=_histogram(), hints=())
    assert [c.tf for c in a.ask()] == [c.tf for c in b.ask()]


def test_a_sketchs_first_population_is_all_on_its_strokes():
    """A sketch's strokes say which values take which colour: every fresh candidate of the
    first population carries each stroke's colour on its values. (Half were histogram seeds
    with the strokes' colours on materials at random: the tooth's blue root colour on its
    crown's dentin led the first generation, judged on quality alone.)"""
    strokes = tuple(replace(h, name=STROKE) for h in (BONE, SKIN))
    ex = GeneticExplorer(population=20, n_gaussians=5, seed=2, histogram=_histogram(),
                         hints=strokes)  # fmt: skip
    pop = ex.ask()
    assert all(c.origin == "hint" for c in pop)
    for c in pop:
        for h in strokes:
            assert any(
                h.reaches(g.mean) and np.linalg.norm(np.subtract(g.color, h.color)) < 0.1
                and g.height >= h.height[0] * 0.99
                for g in c.tf.gaussians
            ), (c.id, h.name)  # fmt: skip
    # Words keep half of it for histogram seeds (their structures are matched guesses).
    assert not all(c.origin == "hint" for c in GeneticExplorer(
        population=20, n_gaussians=5, seed=2, histogram=_histogram(), hints=HINTS).ask())  # fmt: skip


def test_customize_begins_with_fresh_hinted_tfs_in_place_of_the_bred_tail():
    """Initialization judges quality alone and can drop every hinted TF before the words are
    judged: the customize stage gets a quarter of its population fresh on the hints again,
    in place of roulette-bred children, the elites kept. Refine and runs without hints do
    not."""
    ex = GeneticExplorer(population=16, n_gaussians=5, seed=1, histogram=_histogram(), hints=HINTS)
    pop = ex.ask()
    # Quality ranked every hinted TF last.
    ranking = [c.id for c in pop if c.origin != "hint"] + [c.id for c in pop if c.origin == "hint"]
    ex.tell(ranking)
    before = ex.ask()
    ex.set_stage("customize", generations=3)
    after = ex.ask()
    assert len(after) == 16
    assert [c.id for c in after[:12]] == [c.id for c in before[:12]]  # elites and best kept
    fresh = after[12:]
    assert all(c.origin == "hint" and c.id not in {b.id for b in before} for c in fresh)
    for c in fresh:  # on the hints: an ivory bone and a red skin
        bone = min(c.tf.gaussians, key=lambda g: abs(g.mean - 0.7))
        assert abs(bone.mean - 0.7) < 0.02 and np.abs(np.subtract(bone.color, IVORY)).max() < 0.25
    plain = GeneticExplorer(population=16, n_gaussians=5, seed=1, histogram=_histogram())
    first = plain.ask()
    plain.tell([c.id for c in first])
    bred = plain.ask()
    plain.set_stage("customize", generations=3)
    assert [c.id for c in plain.ask()] == [c.id for c in bred]


def test_mutation_draws_colour_and_height_toward_the_materials_hint():
    p = MutationParams(
        rate=0.0, mean_rate=0.0, mean_step=0.0, width_step=0.0, height_step=0.0,
        color_rate=0.0, hue_step=0.0, sl_step=0.0, swap_prob=0.0, channel_prob=0.0,
        hints=(BONE, SKIN), hint_prob=1.0,
    )  # fmt: skip
    tf = GaussianTF(
        (
            Gaussian(0.2, 0.02, 0.9, (0.1, 0.9, 0.1)),  # skin, too opaque and green
            Gaussian(0.45, 0.02, 0.2, (0.1, 0.1, 0.9)),  # no hint here: unchanged
            Gaussian(0.7, 0.02, 0.01, (0.5, 0.1, 0.5)),  # bone, too faint and purple
        )
    )
    rng = np.random.default_rng(2)
    out = mutate(tf, rng, p, Bounds())
    skin, other, bone = out.gaussians
    assert 0.03 <= skin.height <= 0.15 and np.abs(np.subtract(skin.color, RED)).max() < 0.25
    assert 0.3 <= bone.height <= 1.0 and np.abs(np.subtract(bone.color, IVORY)).max() < 0.25
    assert other == tf.gaussians[1]


def test_refine_hint_recolours_the_selected_feature():
    gold = Hint("selection", color=(0.83, 0.69, 0.22))
    base = GaussianTF(
        (Gaussian(0.3, 0.02, 0.05, (0.9, 0.3, 0.3)), Gaussian(0.8, 0.02, 0.6, (0.95, 0.95, 0.9)))
    )
    ex = GeneticExplorer(population=16, n_gaussians=2, seed=0, hints=[gold.to_dict()])
    ex.set_stage("refine", generations=3, selected=[1], base=base)
    pop = ex.ask()
    near_gold = [
        c for c in pop if np.abs(np.subtract(c.tf.gaussians[1].color, gold.color)).max() < 0.2
    ]
    assert len(near_gold) >= 3  # hint_prob 0.3 in refine
    for c in pop:  # the unselected feature is frozen and as it was
        g = c.tf.gaussians[0]
        assert g.frozen and (g.mean, g.height, g.color) == (0.3, 0.05, (0.9, 0.3, 0.3))


def test_a_named_material_faded_to_nothing_is_raised_to_its_floor():
    """The labelling oracle faded the bonsai's pot to a mean opacity of 0.004: only its rim's
    colour showed. The strongest Gaussian on a named, shown hint, in its colour, keeps at
    least a share of its band's low end; what is already shown, frozen, hidden, in another
    colour or an edit's is left alone."""
    from intuitf.explorer.hints import SHOWN_FLOOR

    b = Bounds()
    faded = GaussianTF(
        (
            Gaussian(0.2, 0.02, 0.001, RED),  # skin, faded
            Gaussian(0.21, 0.02, 0.004, RED),  # skin too, the stronger of the two
            Gaussian(0.45, 0.02, 0.0, (0.1, 0.1, 0.9)),  # no hint here
            Gaussian(0.7, 0.02, 0.5, IVORY),  # bone, shown
        )
    )
    out = keep_shown(faded, (BONE, SKIN), b).gaussians
    assert out[1].height == pytest.approx(SHOWN_FLOOR * SKIN.height[0])
    assert out[0].height == 0.001
    assert out[2:] == faded.gaussians[2:]
    # Already shown: the same TF back.
    assert keep_shown(GaussianTF(out), (BONE, SKIN), b) == GaussianTF(out)
    frozen = faded.with_gaussians(
        [replace(g, frozen=True) if g.mean < 0.3 else g for g in faded.gaussians]
    )
    assert keep_shown(frozen, (BONE, SKIN), b) == frozen
    hidden = Hint("skin", center=0.2, spread=0.015, hidden=True)
    fainter = Hint("skin", center=0.2, spread=0.015, height=(0.03, 0.15), direction="fainter")
    bandless = Hint("skin", center=0.2, spread=0.015, color=RED)
    for h in (hidden, fainter, bandless):
        assert keep_shown(faded, (h,), b) == faded
    # Another colour on the material is not the material shown as asked: left alone.
    green = faded.with_gaussians(
        [replace(g, color=(0.1, 0.9, 0.1)) if g.mean < 0.3 else g for g in faded.gaussians]
    )
    assert keep_shown(green, (BONE, SKIN), b) == green
    # A Gaussian counts for the nearest hint: a faded yellow next to a strong blue is raised.
    blue = Hint("blue", center=0.64, spread=0.008, height=(0.05, 0.8))
    yellow = Hint("yellow", center=0.68, spread=0.008, height=(0.3, 1.0))
    near = GaussianTF((Gaussian(0.64, 0.01, 0.6, (0, 0, 1)), Gaussian(0.68, 0.01, 0.02, (1, 1, 0))))
    assert yellow.reaches(0.66) and blue.reaches(0.66)
    assert keep_shown(near, (blue, yellow), b).gaussians[1].height == pytest.approx(
        SHOWN_FLOOR * 0.3
    )


def test_a_gaussian_raised_on_values_the_words_hide_is_switched_off_again():
    """A faded gold Gaussian at the top of the air's values is nearest the leaves' hint: kept
    shown first and hidden last, it stays off. (Hidden first, then raised, it painted the
    air at the floor's height.)"""
    from intuitf.explorer.hints import as_the_words_say, quiet_hidden

    gold = (0.83, 0.69, 0.22)
    leaves = Hint("leaves", center=0.17, spread=0.026, color=gold, height=(0.05, 0.8))
    air = Hint("background", center=0.002, spread=0.05, hidden=True)
    tf = GaussianTF((Gaussian(0.12, 0.03, 0.001, gold), Gaussian(0.7, 0.02, 0.5, IVORY)))
    assert hint_for(0.12, (leaves,)) is leaves
    out = as_the_words_say(tf, (leaves, air), Bounds())
    assert out.gaussians[0].height == 0.0
    # The other order paints the air.
    hidden_first = quiet_hidden(tf, (leaves, air), Bounds())
    assert keep_shown(hidden_first, (leaves, air), Bounds()).gaussians[0].height > 0.01


def test_every_new_candidate_shows_the_named_materials():
    """Over generations of random verdicts, no bred candidate lets a named material, in its
    colour, fade below its floor (the GA's mutations shrink heights)."""
    from intuitf.explorer.hints import SHOWN_COLOR_REACH, SHOWN_FLOOR

    ex = GeneticExplorer(population=16, n_gaussians=5, seed=3, histogram=_histogram(), hints=HINTS)
    rng = np.random.default_rng(0)
    for _ in range(5):
        pop = ex.ask()
        for c in pop:
            for h in (BONE, SKIN):
                on = [
                    g
                    for g in c.tf.gaussians
                    if hint_for(g.mean, (BONE, SKIN)) is h
                    and np.linalg.norm(np.subtract(g.color, h.color)) <= SHOWN_COLOR_REACH
                ]
                floor = SHOWN_FLOOR * h.height[0] - 1e-12
                assert not on or max(g.height for g in on) >= floor, (c.id, h.name)
        ex.tell([pop[int(i)].id for i in rng.permutation(len(pop))])


@pytest.mark.parametrize("cls", [GeneticExplorer, CMAExplorer])
def test_hints_survive_the_saved_state(cls):
    ex = cls(population=8, n_gaussians=3, seed=5, histogram=_histogram(), hints=HINTS)
    ex.tell([c.id for c in ex.ask()])
    state = json.loads(json.dumps(ex.state_dict()))
    again = explorer_from_state(state)
    assert again.hints == ex.hints == (BONE, SKIN)
    assert [c.tf for c in again.ask()] == [c.tf for c in ex.ask()]
