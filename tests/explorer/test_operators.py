"""Variation and selection operators, schedules, encoding and seeds, with real numbers."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from intuitf.explorer import (
    CUSTOMIZE,
    INITIALIZE,
    Bounds,
    Decay,
    GeneticExplorer,
    StagePreset,
    crossover,
    decode,
    elite_count,
    encode,
    mutate,
    near_duplicate,
    paper_settings,
    random_tf,
    rgb_to_hsl,
    roulette,
)
from intuitf.explorer.fitness import rank_fitness
from intuitf.tf import Gaussian, GaussianTF

B = Bounds()


def _tf(rng, n=5, bounds=B):
    return random_tf(rng, n, bounds)


def test_mutation_respects_bounds_and_frozen():
    rng = np.random.default_rng(0)
    bounds = Bounds(width=(0.01, 0.04), height=(0.0, 0.6), lightness=(0.35, 0.75), hue=(0.1, 0.6))
    params = INITIALIZE.mutation_params(0.0).forced()  # every attribute moves, big steps
    for _ in range(200):
        tf = _tf(rng, 5, bounds).freeze([1, 3])  # 1 and 3 free, the rest frozen
        out = mutate(tf, rng, params, bounds)
        assert bounds.contains(out)
        for i in (0, 2, 4):
            assert out.gaussians[i] == tf.gaussians[i]
    # The free ones did move (forced params change every attribute).
    assert out.gaussians[1] != tf.gaussians[1] and out.gaussians[3] != tf.gaussians[3]


def test_mutation_of_fully_frozen_tf_is_identity():
    rng = np.random.default_rng(1)
    tf = _tf(rng).freeze([])
    assert mutate(tf, rng, INITIALIZE.mutation_params(0.0).forced(), B) is tf


def test_height_steps_are_multiplicative():
    # A faint Gaussian stays in its order of magnitude under a height step, unlike an
    # additive step of the same schedule that would often zero it.
    rng = np.random.default_rng(2)
    g = Gaussian(0.5, 0.02, 0.01, (1.0, 0.5, 0.5))
    tf = GaussianTF((g,))
    p = replace(
        INITIALIZE.mutation_params(0.5), rate=1.0, mean_rate=0.0, color_rate=0.0, toggle_prob=0.0
    )
    h = np.array([mutate(tf, rng, p, B).gaussians[0].height for _ in range(2000)])
    ratio = np.log(h / 0.01)
    assert abs(np.median(ratio)) < 0.05  # unbiased in log space
    assert (h > 0.001).mean() > 0.99 and np.std(ratio) == pytest.approx(p.height_step, rel=0.1)


def test_toggle_hides_a_visible_feature_and_reveals_a_hidden_one():
    rng = np.random.default_rng(4)
    shown = Gaussian(0.3, 0.02, 0.2, (1.0, 0.5, 0.5))
    hidden = Gaussian(0.7, 0.02, 0.0, (0.5, 0.5, 1.0))
    tf = GaussianTF((shown, hidden))
    p = replace(
        INITIALIZE.mutation_params(0.0), rate=0.0, mean_rate=0.0, color_rate=0.0, toggle_prob=1.0
    )
    for _ in range(50):
        out = mutate(tf, rng, p, B)
        # Hidden is 0, not the floor: 0.001 per voxel over air is a visible haze.
        assert out.gaussians[0].height == 0.0
        assert B.height_init[0] <= out.gaussians[1].height <= B.height_init[1]


def test_hue_step_wraps_around():
    rng = np.random.default_rng(3)
    red = (1.0, 0.0, 0.0)  # hue 0: steps go to both ~0.98 and ~0.02
    tf = GaussianTF((Gaussian(0.5, 0.02, 0.1, red),))
    p = replace(
        INITIALIZE.mutation_params(0.0), rate=0.0, mean_rate=0.0, color_rate=1.0, channel_prob=0.0
    )
    hues = np.array([rgb_to_hsl(mutate(tf, rng, p, B).gaussians[0].color)[0] for _ in range(400)])
    assert (hues > 0.9).mean() > 0.3 and (hues < 0.1).mean() > 0.3


def test_crossover_exchanges_attributes_pairs_by_position_and_skips_frozen():
    a = GaussianTF(
        (
            Gaussian(0.7, 0.03, 0.5, (1.0, 0.0, 0.0)),
            Gaussian(0.2, 0.01, 0.1, (0.0, 1.0, 0.0)),
            Gaussian(0.5, 0.02, 0.2, (0.0, 0.0, 1.0), frozen=True),
        )
    )
    b = GaussianTF(
        (
            Gaussian(0.25, 0.05, 0.05, (0.5, 0.5, 0.5)),
            Gaussian(0.75, 0.06, 0.9, (0.9, 0.9, 0.1)),
            Gaussian(0.45, 0.04, 0.3, (0.2, 0.3, 0.4)),
        )
    )
    rng = np.random.default_rng(0)
    ca, cb = crossover(a, b, rng, attr_prob=1.0, groups=(("color",), ("width", "height")))
    # Everything in the groups was swapped; positions stay (not in groups).
    assert ca.gaussians[2] == a.gaussians[2]  # frozen, untouched
    # a's lowest free (index 1, mean 0.2) pairs with b's lowest (index 0, mean 0.25).
    assert ca.gaussians[1].color == b.gaussians[0].color and ca.gaussians[1].mean == 0.2
    assert ca.gaussians[1].width == 0.05 and ca.gaussians[1].height == 0.05
    assert cb.gaussians[0].color == a.gaussians[1].color and cb.gaussians[0].mean == 0.25
    # a's index 0 (mean 0.7) pairs with b's second lowest (index 2, mean 0.45).
    assert ca.gaussians[0].color == b.gaussians[2].color
    assert cb.gaussians[2].color == a.gaussians[0].color
    assert cb.gaussians[1] == b.gaussians[1]  # b's third had no free partner
    # The two children together hold exactly the parents' attribute values.
    for attr in ("mean", "width", "height", "color"):
        before = sorted(getattr(g, attr) for g in a.gaussians + b.gaussians)
        after = sorted(getattr(g, attr) for g in ca.gaussians + cb.gaussians)
        assert before == after


def test_crossover_never_changes_frozen_over_many_draws():
    rng = np.random.default_rng(5)
    for _ in range(100):
        a, b = _tf(rng).freeze([1, 3]), _tf(rng).freeze([0])
        ca, cb = crossover(a, b, rng, attr_prob=0.6)
        assert all(ca.gaussians[i] == a.gaussians[i] for i in (0, 2, 4))
        assert all(cb.gaussians[i] == b.gaussians[i] for i in range(1, 5))


def test_rates_and_steps_decay_over_the_stage_and_restart():
    p0, p5, p1 = (INITIALIZE.mutation_params(t) for t in (0.0, 0.5, 1.0))
    for name in ("rate", "mean_step", "width_step", "height_step", "color_rate", "hue_step"):
        v0, v5, v1 = getattr(p0, name), getattr(p5, name), getattr(p1, name)
        assert v0 > v5 >= v1 > 0, name
    assert Decay(0.4, 0.1).at(0.25) == pytest.approx(0.3) and Decay(0.4, 0.1).at(0.9) == 0.1
    # Customization raises rates again but moves positions far less.
    c0 = CUSTOMIZE.mutation_params(0.0)
    assert c0.rate > p1.rate and c0.mean_rate < 0.5 * p0.mean_rate
    assert c0.mean_step < 0.5 * p0.mean_step
    # Empirically: more attributes change early than late.
    rng = np.random.default_rng(4)
    tfs = [_tf(rng) for _ in range(300)]

    def changed(p):
        n = 0
        for tf in tfs:
            out = mutate(tf, rng, p, B)
            n += sum(
                (ga.mean != gb.mean) + (ga.width != gb.width) + (ga.height != gb.height)
                for ga, gb in zip(tf.gaussians, out.gaussians, strict=True)
            )
        return n

    assert changed(p0) > 2 * changed(p1)


def test_explorer_rates_follow_progress():
    ex = GeneticExplorer(population=6, n_gaussians=2, generations=5, seed=0)
    seen = []
    for _ in range(6):
        seen.append(ex.progress)
        ex.tell([c.id for c in ex.ask()])
    assert seen == [0.0, 0.25, 0.5, 0.75, 1.0, 1.0]
    ex.set_stage("customize", generations=3)
    assert ex.progress == 0.0


def test_roulette_favours_top_ranks_more_as_pressure_rises():
    rng = np.random.default_rng(0)
    n, draws = 20, 20000
    early = roulette(rank_fitness(n, 0.0), draws, rng)
    late = roulette(rank_fitness(n, 1.0), draws, rng)
    top5_early, top5_late = (early < 5).mean(), (late < 5).mean()
    # Uniform choice would give 25 %; fitness (n - r + 1)^p gives 46.0 % at p = 1.2 and
    # 75.3 % at p = 4 (exact shares for n = 20); 20000 draws: standard error ~0.35 %.
    assert abs(top5_early - 0.4596) < 0.015 and abs(top5_late - 0.7533) < 0.015
    counts = np.bincount(early, minlength=n)
    assert counts[0] > counts[10] > counts[19]


def test_explorer_parents_come_mostly_from_top_ranks():
    ex = GeneticExplorer(population=40, n_gaussians=3, generations=10, seed=1)
    cands = ex.ask()
    ranking = [c.id for c in cands]
    ex.tell(ranking)
    pos = {cid: k for k, cid in enumerate(ranking)}
    parent_ranks = [pos[p] for c in ex.ask() if c.origin != "elite" for p in c.parents if p in pos]
    assert np.mean(np.array(parent_ranks) < 10) > 0.4  # top quarter: 25 % by chance


def test_elite_count():
    assert [elite_count(s, 50) for s in (0.05, 0.10, 0.15)] == [2, 5, 7]
    assert elite_count(0.05, 10) == 1 and elite_count(2.0, 10) == 10


def test_encode_decode_round_trip_and_bounds():
    rng = np.random.default_rng(7)
    for _ in range(50):
        tf = _tf(rng, 4)
        x = encode(tf, B)
        assert x.shape == (24,) and (x >= 0).all() and (x <= 1).all()
        back = decode(x, tf, B)
        assert near_duplicate(back, tf, tol=1e-6)
        y = rng.normal(0.5, 1.0, size=24)  # anything decodes to a TF inside the bounds
        assert B.contains(decode(y, tf, B))
    # Frozen Gaussians are left out of the vector and kept by decode.
    tf = _tf(rng, 4).freeze([2])
    x = encode(tf, B)
    assert x.shape == (6,)
    out = decode(np.zeros(6), tf, B)
    assert [g for i, g in enumerate(out.gaussians) if i != 2] == [
        g for i, g in enumerate(tf.gaussians) if i != 2
    ]
    assert out.gaussians[2].mean == 0.0 and out.gaussians[2].width == pytest.approx(B.width[0])


def test_near_duplicate_tolerance():
    rng = np.random.default_rng(8)
    tf = _tf(rng, 3)
    g = tf.gaussians[1]
    assert near_duplicate(tf, tf.with_gaussians(reversed(tf.gaussians)))  # order does not matter
    nudged = tf.with_gaussians([tf.gaussians[0], replace(g, mean=g.mean + 5e-4), tf.gaussians[2]])
    moved = tf.with_gaussians([tf.gaussians[0], replace(g, mean=g.mean + 0.01), tf.gaussians[2]])
    assert near_duplicate(tf, nudged) and not near_duplicate(tf, moved)
    # A hidden feature's colour and position do not show: only visible Gaussians count.
    hidden = replace(g, height=0.0)
    a = tf.with_gaussians([tf.gaussians[0], hidden, tf.gaussians[2]])
    b = tf.with_gaussians(
        [tf.gaussians[0], replace(hidden, mean=0.9, color=(0.0, 1.0, 0.0)), tf.gaussians[2]]
    )
    assert near_duplicate(a, b) and not near_duplicate(a, tf)
    assert not near_duplicate(a, a.with_gaussians(list(a.gaussians)[:2]))  # one shown less


def test_stage_preset_serialises():
    for p in (INITIALIZE, CUSTOMIZE, *paper_settings().values()):
        assert StagePreset.from_dict(p.to_dict()) == p


def test_sampled_heights_favour_low_opacity():
    rng = np.random.default_rng(9)
    h = np.array([g.height for _ in range(400) for g in _tf(rng).gaussians])
    assert h.min() >= 0.005 and h.max() <= 0.5
    assert np.median(h) < 0.1  # log-uniform on [0.005, 0.5]: median 0.05


def test_crossover_pairs_gaussians_on_the_same_material_by_mean():
    # a has an extra Gaussian below the others: by position it would swap 0.1 with 0.5.
    a = GaussianTF(
        (
            Gaussian(0.1, 0.02, 0.1, (1.0, 0.0, 0.0)),
            Gaussian(0.5, 0.02, 0.1, (0.0, 1.0, 0.0)),
            Gaussian(0.8, 0.02, 0.1, (0.0, 0.0, 1.0)),
        )
    )
    b = GaussianTF(
        (Gaussian(0.52, 0.03, 0.2, (1.0, 1.0, 0.0)), Gaussian(0.79, 0.03, 0.2, (0.0, 1.0, 1.0)))
    )
    rng = np.random.default_rng(0)
    kw = dict(attr_prob=1.0, groups=(("color",),))
    ca, _ = crossover(a, b, rng, by_mean=True, **kw)
    assert [g.color for g in ca.gaussians] == [
        (1.0, 0.0, 0.0),  # unpaired: kept
        (1.0, 1.0, 0.0),  # from b's 0.52
        (0.0, 1.0, 1.0),  # from b's 0.79
    ]
    cp, _ = crossover(a, b, rng, by_mean=False, **kw)
    assert [g.color for g in cp.gaussians][:2] == [(1.0, 1.0, 0.0), (0.0, 1.0, 1.0)]


def test_recolour_mutation_draws_from_the_palette():
    rng = np.random.default_rng(5)
    palette = ((0.95, 0.55, 0.15), (0.35, 0.6, 0.95))
    tf = GaussianTF((Gaussian(0.5, 0.02, 0.1, (0.5, 0.5, 0.5)),))
    p = replace(CUSTOMIZE.mutation_params(0.0, palette), rate=0.0, mean_rate=0.0, swap_prob=0.0)
    always = replace(p, recolor_prob=1.0)
    colours = np.array([mutate(tf, rng, always, B).gaussians[0].color for _ in range(200)])
    dist = np.abs(colours[:, None, :] - np.array(palette)[None]).max(axis=2).min(axis=1)
    # Near one of the palette's colours: only a small HSL jitter (a uniform draw over the
    # colour space would be this close about 1 time in 20).
    assert (dist < 0.4).all() and np.median(dist) < 0.1
    near = [(np.abs(colours - c).max(axis=1) < 0.25).mean() for c in palette]
    assert min(near) > 0.3  # both palette colours are used
    # Without a palette the same rate does nothing special: grey stays near grey.
    no_palette = replace(always, palette=(), color_rate=0.0)
    assert mutate(tf, rng, no_palette, B).gaussians[0].color == (0.5, 0.5, 0.5)


def test_rank_fitness_follows_the_pressure_schedule():
    from intuitf.explorer.fitness import PressureSchedule, rank_fitness

    fit = rank_fitness(8, progress=0.0)
    assert fit[0] == pytest.approx(8**1.2) and fit[-1] == pytest.approx(1.0)
    late = rank_fitness(8, progress=1.0, schedule=PressureSchedule(1.2, 4.0))
    assert late[0] == pytest.approx(8**4.0) and list(late) == sorted(late, reverse=True)
