"""Pressure on any network, every light at once: what max pressure scores, MPLight observes
and its reward counts (RESCO's ``states.mplight`` and ``rewards.pressure``, on our greens).

A light's lanes are rows of the env's measures (every light's incoming lanes, concatenated in
network order). A *movement* of a green is the pair (incoming edge, outgoing edge) of the links
it lets go; its pressure is the queue on its incoming lanes minus the queue on the outgoing
edge's lanes where they enter another light (RESCO's downstream term). A green's pressure is the
sum over its movements (:class:`Pressures.of_greens`); a light's (the reward's) is the queue on
all its incoming lanes minus the queue on every lane of its outgoing edges that enters another
light, each lane once (:class:`Pressures.of_lights`). Both are one sparse product per decision.
"""

from __future__ import annotations

import numpy as np
from scipy import sparse

from ials_zoo.sumo_net.network import Network


def _entering(network: Network) -> dict[str, int]:
    """Every light's incoming lane -> its row among all lights' lanes."""
    rows, start = {}, 0
    for x in network.lights:
        for k, lane in enumerate(x.lanes):
            rows.setdefault(lane, start + k)
        start += len(x.lanes)
    return rows


def _edge_lanes(network: Network) -> dict[str, list[str]]:
    out: dict[str, list[str]] = {}
    for lane, edge in network.lane_edges.items():
        out.setdefault(edge, []).append(lane)
    return out


class Pressures:
    """The sparse tables of a network's pressures (module docstring)."""

    def __init__(self, network: Network):
        entering, edge_lanes = _entering(network), _edge_lanes(network)
        green_rows, light_rows = [], []  # (row, lane row, sign) triplets
        starts, g, start = [0], 0, 0
        for k, x in enumerate(network.lights):
            outgoing: set[int] = set()
            for a in range(x.n_actions):
                moves: dict[tuple, set] = {}
                for lane_in, lane_out in x.movements(a):
                    key = (network.lane_edges.get(lane_in), network.lane_edges.get(lane_out))
                    moves.setdefault(key, set()).add(start + x.lanes.index(lane_in))
                for (_, out_edge), rows in moves.items():
                    down = [entering[lane] for lane in edge_lanes.get(out_edge, []) if lane in entering]
                    green_rows += [(g, r, 1.0) for r in rows] + [(g, r, -1.0) for r in down]
                    outgoing.update(down)
                g += 1
            light_rows += [(k, start + i, 1.0) for i in range(len(x.lanes))] + [(k, r, -1.0) for r in sorted(outgoing)]
            start += len(x.lanes)
            starts.append(g)
        self.green_starts = starts  # light k's greens are rows starts[k]:starts[k + 1] of of_greens
        self._greens = _matrix(green_rows, g, start)
        self._lights = _matrix(light_rows, len(network.lights), start)

    def of_greens(self, queues: np.ndarray) -> np.ndarray:
        """Every light's greens' pressures, concatenated (light ``k``'s: rows
        ``green_starts[k]:green_starts[k + 1]``), from every lane's queue."""
        return self._greens @ np.asarray(queues, np.float64)

    def of_lights(self, queues: np.ndarray) -> np.ndarray:
        """Every light's pressure (RESCO's ``pressure`` reward is minus it)."""
        return self._lights @ np.asarray(queues, np.float64)


def _matrix(triplets, rows: int, cols: int):
    """Duplicates add up: a lane in two movements of one green counts twice, as max pressure counts it."""
    if not triplets:
        return sparse.csr_matrix((rows, cols))
    r, c, v = zip(*triplets)
    return sparse.csr_matrix((v, (r, c)), shape=(rows, cols))


__all__ = ["Pressures"]
