"""Every green's *wave* on any network, every light at once: the vehicles within 50 m of the
light on the lanes the green lets go. It is what greedy (RESCO's MAXWAVE) maximises and what the
``wave`` observation shows a learner (:func:`ials_zoo.sumo_net.mdp.wave`).

A light's lanes are rows of the env's per-lane counts (every light's incoming lanes, concatenated
in network order); a green's wave is one ``bincount`` over the rows of its served lanes.
"""

from __future__ import annotations

import numpy as np

from ials_zoo.sumo_net.network import Network

DISTANCE = 50.0
"""MAXWAVE's detection distance (m), RESCO's ``agents/maxwave.py``; the env's own is 200 m."""


class Waves:
    """The rows of every green's served lanes (module docstring)."""

    def __init__(self, network: Network):
        rows, greens, starts, g, start = [], [], [0], 0, 0
        for x in network.lights:
            for a in range(x.n_actions):
                served = [start + x.lanes.index(lane) for lane in x.served_lanes(a)]
                rows += served
                greens += [g] * len(served)
                g += 1
            starts.append(g)
            start += len(x.lanes)
        self._rows, self._greens = np.asarray(rows, np.int64), np.asarray(greens, np.int64)
        self.green_starts = starts  # light k's greens are entries starts[k]:starts[k + 1] of of_greens
        self.n_greens = g

    def of_greens(self, counts: np.ndarray) -> np.ndarray:
        """Every green's wave, from every lane's count within :data:`DISTANCE` (float64)."""
        return np.bincount(self._greens, weights=np.asarray(counts, np.float64)[self._rows], minlength=self.n_greens)


__all__ = ["DISTANCE", "Waves"]
