"""Regions cut from any SUMO network: each light's neighbourhood, from the network file alone.

A light's region (:class:`NetRegion`) is what its local simulator will simulate:

* **incoming chains**: for every edge that feeds one of the light's controlled lanes, that edge
  and, upstream, the edges that lead into it one by one (through nodes that only join a road's
  pieces), up to the upstream junction (a node where several roads meet, another light, or the
  network's fringe) or until the chain covers :data:`CHAIN_CAP_METRES` (RESCO's 200 m
  detection). The region begins that far upstream of the stop line: on the chain's first edge,
  at its **entry offset** (:attr:`NetRegion.entry_offsets`; 0 where the upstream junction is
  nearer). Before that point a vehicle is invisible to the light and is the rest of the network's
  business; the first version began the chains at twice the detection, and its regions held 59%
  of ingolstadt21's vehicle-steps (``docs/sumo_net.md``). With ``reach`` > 0 a road shorter than
  ``reach`` from the stop line goes on through the junction it starts at (not a light), into
  every road feeding it: a tree of roads, each way from a furthest edge to the light a chain.
  The default, :data:`REACH_METRES`, is 0: at 100 m, tried because two of ingolstadt21's lights
  have chains of 0-10 m and DIALS loses most of its delay on them, ingolstadt21's regions held
  1.5x the lane-metres, cost 1.4x as much, replayed the GS's lanes less closely, and DIALS lost
  as much on those lights (``docs/sumo_net.md``);
* **outgoing edges**: every edge a controlled link leads to, so that every link of the light's
  program survives a cut (its phases keep their meaning) and spill-back from them is simulated;
  where one is shorter than :data:`SHORT_EXIT_METRES`, the edges after it too (**beyond**):
  a junction that close (ingolstadt21 has one 12 m past a light) backs its queue into the
  light's lanes, and without it the region's replay of ingolstadt21 missed a whole queue
  (``docs/sumo_net.md``). A vehicle leaves the region :data:`EXIT_METRES` into the last of
  these edges on its way (:attr:`NetRegion.exits`): the light sees none of them, and on
  ingolstadt21 the outgoing roads held 18% of the regions' vehicle-steps.

The **influence sources** are the chains' first edges: a vehicle crossing its entry offset (coming
from upstream, or inserted there) is what the rest of the network does to the region. Vehicles
inserted on a region's other edges are influence as well (their routes start inside). A vehicle
turning off at a junction inside the region, onto a road outside it, leaves at the end of its
last edge inside. :func:`cut_network` writes a region's edges as a network of their own
(``netconvert --keep-edges.explicit``), with the light's program.

Read with ``sumolib`` (SUMO's own reader of its files), once per file.
"""

from __future__ import annotations

import functools
import os
import subprocess
from dataclasses import dataclass
from pathlib import Path

from ials_zoo.errors import BadInput
from ials_zoo.sumo.command import sumo_binary

CHAIN_CAP_METRES = 200.0
SHORT_EXIT_METRES = 50.0
EXIT_METRES = 25.0
REACH_METRES = 0.0  # chains end at the upstream junction (module docstring: 100 m measured, no better)


@dataclass(frozen=True)
class NetRegion:
    """One light's region (module docstring).

    Attributes:
        light: the light's id (the agent).
        incoming: the edges that feed its controlled lanes.
        chains: every way into the light, its edges from the furthest upstream to an incoming
            edge, in ``incoming`` order (several per incoming edge where roads meet upstream).
        outgoing: the edges its controlled links lead to.
        sources: the chains' first edges (where influence enters), in ``chains`` order.
        length: metres of lanes in the region (every lane of every edge).
        beyond: the edges after its short outgoing edges.
        entry_offsets: per source, the lane position (m) where the region begins on it.
        exits: ``(edge, position)`` for every outgoing and beyond edge: where a vehicle whose
            way through the region ends there leaves it.
    """

    light: str
    incoming: tuple[str, ...]
    chains: tuple[tuple[str, ...], ...]
    outgoing: tuple[str, ...]
    sources: tuple[str, ...]
    length: float
    beyond: tuple[str, ...] = ()
    entry_offsets: tuple[float, ...] = ()
    exits: tuple[tuple[str, float], ...] = ()

    @property
    def edges(self) -> tuple[str, ...]:
        """Every edge of the region, chains first."""
        return tuple(dict.fromkeys([e for c in self.chains for e in c] + list(self.outgoing) + list(self.beyond)))


@functools.lru_cache(maxsize=8)
def _read(path: str, mtime: float):
    import sumolib

    return sumolib.net.readNet(path, withPrograms=True, withInternal=False)


def _reverse_of(edge, other) -> bool:
    return edge.getFromNode() is other.getToNode() and edge.getToNode() is other.getFromNode()


def _feeding(edge, lights: set, through_junction: bool) -> list:
    """The edges that lead into ``edge`` and belong to its region: the one edge before it where
    its node only joins a road's pieces; every edge into its node where the node is a junction
    and ``through_junction``; none at a light or the fringe."""
    node = edge.getFromNode()
    if node.getID() in lights or node.getType() == "traffic_light":
        return []
    feeding = [e for e in node.getIncoming() if not _reverse_of(e, edge) and e.getFunction() != "internal"]
    leaving = [e for e in node.getOutgoing() if not _reverse_of(e, feeding[0] if feeding else edge)]
    if len(feeding) == 1 and len(leaving) == 1:
        return feeding
    return feeding if through_junction else []


def _tree(edge, lights: set, cap: float, reach: float, seen: set) -> list[tuple]:
    """The paths (furthest upstream edge first, ``edge`` last) of the roads feeding ``edge``
    within ``cap`` m of its end, through junctions while a path covers less than ``reach`` m.
    ``seen``: edges already in the region (left out, and added to)."""
    paths, stack = [], [((edge,), edge.getLength())]  # (a path, the metres it covers)
    while stack:
        path, covered = stack.pop()
        ups = [] if covered >= cap else [
            e for e in _feeding(path[0], lights, covered < reach) if e.getID() not in seen]
        seen.update(e.getID() for e in ups)
        if not ups:
            paths.append(tuple(e.getID() for e in path))
        stack.extend(((e, *path), covered + e.getLength()) for e in reversed(ups))
    return paths


def regions_of(net_file: str, cap: float = CHAIN_CAP_METRES, short_exit: float = SHORT_EXIT_METRES,
               exit_metres: float = EXIT_METRES, reach: float = REACH_METRES) -> dict[str, NetRegion]:
    """Every light's region of the network ``net_file`` (module docstring), by light id;
    ``cap``: how far upstream of the stop line the region begins (m); ``short_exit``: outgoing
    edges shorter than that (m) bring the edges after them (0: none); ``exit_metres``: how far
    into its last edge a vehicle leaves (m; ``inf``: at the edge's end); ``reach``: a road
    shorter than that (m) from the stop line goes on through the junction it starts at, into
    every road feeding it (0, the default: chains end at every junction)."""
    if not os.path.isfile(net_file):
        raise BadInput(f"network file {net_file!r} does not exist")
    if not cap > 0:
        raise BadInput(f"the chains' length cap must be > 0 m, got {cap!r}")
    if not short_exit >= 0:
        raise BadInput(f"the short exits' length must be >= 0 m, got {short_exit!r}")
    if not exit_metres > 0:
        raise BadInput(f"the exits' distance must be > 0 m, got {exit_metres!r}")
    if not reach >= 0:
        raise BadInput(f"the regions' reach through junctions must be >= 0 m, got {reach!r}")
    return dict(_regions(str(net_file), os.path.getmtime(net_file), cap, short_exit, exit_metres, reach))


@functools.lru_cache(maxsize=16)
def _regions(path: str, mtime: float, cap: float, short_exit: float, exit_metres: float, reach: float) -> dict:
    """:func:`regions_of`, once per file and settings (callers ask for one light's region often)."""
    net = _read(path, mtime)
    lights = {t.getID() for t in net.getTrafficLights()}
    # a light's nodes (a joint light controls several): their edges end chains too
    stops = lights | {n.getID() for t in net.getTrafficLights() for n in _nodes_of(t)}
    return {tls.getID(): _region(net, tls, stops, cap, reach, short_exit, exit_metres)
            for tls in net.getTrafficLights() if tls.getConnections()}


def _region(net, tls, stops: set, cap: float, reach: float, short_exit: float, exit_metres: float) -> NetRegion:
    connections = tls.getConnections()
    incoming = tuple(dict.fromkeys(c[0].getEdge().getID() for c in connections))
    outgoing = tuple(dict.fromkeys(c[1].getEdge().getID() for c in connections))
    seen = set(incoming)  # each incoming edge heads its own roads
    chains = tuple(p for e in incoming for p in _tree(net.getEdge(e), stops, cap, reach, seen))
    inside = set(outgoing).union(*chains)
    beyond = tuple(dict.fromkeys(x.getID() for e in outgoing if net.getEdge(e).getLength() < short_exit
                                 for x in net.getEdge(e).getOutgoing() if x.getID() not in inside))
    edges = dict.fromkeys([e for c in chains for e in c] + list(outgoing) + list(beyond))
    length = sum(lane.getLength() for e in edges for lane in net.getEdge(e).getLanes())
    offsets = tuple(max(0.0, sum(net.getEdge(e).getLength() for e in c) - cap) for c in chains)
    exits = tuple((e, min(exit_metres, net.getEdge(e).getLength())) for e in dict.fromkeys(outgoing + beyond))
    return NetRegion(tls.getID(), incoming, chains, outgoing, tuple(c[0] for c in chains), length,
                     beyond, offsets, exits)


def _nodes_of(tls):
    return {c[0].getEdge().getToNode() for c in tls.getConnections()}


def read_sumolib(net_file: str):
    """``sumolib``'s reading of ``net_file`` (programs in, internal lanes out), read once per file."""
    return _read(str(net_file), os.path.getmtime(net_file))


def edge_lanes(net_file: str, edge: str) -> tuple[str, ...]:
    """The lane ids of ``edge`` in ``net_file``, by index."""
    net = _read(str(net_file), os.path.getmtime(net_file))
    return tuple(lane.getID() for lane in net.getEdge(edge).getLanes())


def network_size(net_file: str) -> tuple[int, float]:
    """``(edges, metres of lanes)`` of the whole network (internal lanes left out)."""
    net = _read(str(net_file), os.path.getmtime(net_file))
    edges = net.getEdges(withInternal=False)
    return len(edges), sum(lane.getLength() for e in edges for lane in e.getLanes())


def netconvert(args: list[str], what: str, timeout: float = 120.0) -> None:
    """Run SUMO's ``netconvert`` (from the eclipse-sumo wheel) with ``args``; a RuntimeError
    naming ``what`` if it fails or outlasts ``timeout`` seconds."""
    binary = Path(sumo_binary()).with_name("netconvert")
    try:
        proc = subprocess.run([str(binary), *args, "--no-warnings"], capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        raise RuntimeError(f"netconvert did not finish within {timeout:.0f} s {what}") from None
    if proc.returncode != 0:
        raise RuntimeError(f"netconvert failed {what}: {proc.stderr.strip()[-500:]}")


REGION_SEPARATOR = "~"


def region_prefix(name: str) -> str:
    """The prefix of one region's ids where several regions share one simulation. netconvert
    leaves an id that already starts with its ``--prefix`` as it is, so the separator must be
    one that networks' ids do not use: ``"__"`` failed on generated grids, whose roads are named
    ``tls_0__tls_1``. SUMO's ids may hold ``~``."""
    return f"{name}{REGION_SEPARATOR}"


def cut_network(net_file: str, region: NetRegion, out_file: str | os.PathLike, timeout: float = 120.0,
                prefix: str = "") -> Path:
    """Write ``region``'s edges as a network of their own (``netconvert --keep-edges.explicit``);
    the light and its program come along. ``prefix`` goes before every id (several regions in
    one simulation). Returns ``out_file``."""
    out_file = Path(out_file)
    clash = [x for x in region.edges if prefix and x.startswith(prefix)]
    if clash:  # netconvert would leave it unprefixed, and the simulation would ask for another id
        raise ValueError(f"the road {clash[0]!r} of {net_file} already starts with the region prefix {prefix!r}")
    args = ["--sumo-net-file", str(net_file), "--keep-edges.explicit", ",".join(region.edges),
            "--output-file", str(out_file)] + (["--prefix", prefix] if prefix else [])
    netconvert(args, f"cutting the region of {region.light}", timeout)
    if not out_file.is_file():
        raise RuntimeError(f"netconvert wrote no network for the region of {region.light}")
    return out_file


__all__ = ["CHAIN_CAP_METRES", "EXIT_METRES", "SHORT_EXIT_METRES", "NetRegion", "REGION_SEPARATOR", "cut_network", "edge_lanes", "netconvert", "network_size", "read_sumolib", "region_prefix", "regions_of"]
