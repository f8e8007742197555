"""Random search: the baseline the GA and CMA-ES are measured against."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from intuitf.explorer.base import BaseExplorer
from intuitf.explorer.candidate import Candidate
from intuitf.tf.gaussian import GaussianTF


class RandomSearchExplorer(BaseExplorer):
    """Each generation: the best so far, unchanged, plus fresh TFs drawn like a first population.

    Fresh TFs come from the same distribution as the GA's initial population (histogram
    seeds and random TFs within the bounds), so a comparison isolates what evolution adds.
    In a freezing stage only the free Gaussians of the best TF are redrawn.
    """

    method = "random"

    def _next_population(
        self, ranked: list[Candidate], fitness: np.ndarray, progress: float
    ) -> list[Candidate]:
        best = ranked[0]
        n_new = self.population_size - 1
        if best.tf.frozen_mask().any():
            made: list[Candidate] = []
            for _ in range(n_new):
                tf = self.dedup(self._redraw_free(best.tf), [best, *made], self._variant_params())
                made.append(self._new(tf, "random", (best.id,)))
            return [best, *made]
        return [best, *self._fresh_population((), size=n_new, keep=[best])]

    def _redraw_free(self, tf: GaussianTF) -> GaussianTF:
        b, rng = self.bounds, self._rng
        gs = [
            g
            if g.frozen
            else replace(
                g,
                mean=float(rng.uniform(*b.mean)),
                width=b.sample_width(rng),
                height=b.sample_height(rng),
                color=self._color(rng),
            )
            for g in tf.gaussians
        ]
        return tf.with_gaussians(gs)
