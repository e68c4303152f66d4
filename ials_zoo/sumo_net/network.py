"""The signalised junctions of a SUMO network, read from its ``.net.xml`` before SUMO starts.

For each traffic light (RESCO's ``Signal``): its program-0 phases, its green phases (RESCO's
rule: no ``y`` and some ``g``/``G``, in file order: these are the actions), its incoming lanes in
the order of its controlled links (``linkIndex``), and its movements (incoming lane -> outgoing
lane) for max pressure. Parsed once per file and kept.
"""

from __future__ import annotations

import functools
import os
import xml.etree.ElementTree as ET
from dataclasses import dataclass

from ials_zoo.errors import BadInput

MAX_NET_BYTES = 256 << 20  # ingolstadt21, the largest RESCO map, is 1.9 MB; parsed whole, in memory


@dataclass(frozen=True)
class Light:
    """One traffic light as RESCO controls it.

    Attributes:
        id: the ``tlLogic`` id.
        phases: program 0's ``(duration, state)`` pairs.
        greens: indices into ``phases`` of the green phases (the actions, in order).
        lanes: incoming lanes, unique, in controlled-link order (the observation's rows).
        links: ``(incoming lane, outgoing lane, link index)`` of every controlled link.
        lane_lengths: metres, per incoming lane.
    """

    id: str
    phases: tuple[tuple[float, str], ...]
    greens: tuple[int, ...]
    lanes: tuple[str, ...]
    links: tuple[tuple[str, str, int], ...]
    lane_lengths: tuple[float, ...]

    @property
    def n_actions(self) -> int:
        return len(self.greens)

    def green_states(self) -> list[str]:
        return [self.phases[i][1] for i in self.greens]

    def served_lanes(self, action: int) -> list[str]:
        """Incoming lanes with a green (``G`` or ``g``) link in green ``action``."""
        state = self.green_states()[action]
        return list(dict.fromkeys(i for i, _, k in self.links if k < len(state) and state[k] in "Gg"))

    def movements(self, action: int) -> list[tuple[str, str]]:
        """``(incoming lane, outgoing lane)`` pairs that green ``action`` lets go."""
        state = self.green_states()[action]
        return list(dict.fromkeys((i, o) for i, o, k in self.links if k < len(state) and state[k] in "Gg"))


def is_green(state: str) -> bool:
    """RESCO's green phase: no yellow, some green."""
    return "y" not in state and "g" in state.lower()


@dataclass(frozen=True)
class Network:
    """Every traffic light of a network (file order) and the lanes' lengths."""

    lights: tuple[Light, ...]
    lane_edges: dict  # lane id -> edge id
    lane_shapes: dict  # lane id -> [(x, y), ...] metres (for drawing), internal lanes left out

    def light(self, tls_id: str) -> Light:
        for light in self.lights:
            if light.id == tls_id:
                return light
        raise BadInput(f"no traffic light {tls_id!r} in this network")

    @property
    def ids(self) -> list[str]:
        return [light.id for light in self.lights]


def _parse(path: str):
    size = os.path.getsize(path)
    if size > MAX_NET_BYTES:
        raise BadInput(f"{path}: {size / 2**20:.0f} MiB is more than the {MAX_NET_BYTES >> 20} MiB a network may have")
    try:
        return ET.parse(path).getroot()
    except ET.ParseError as e:
        raise BadInput(f"{path} is not a valid SUMO network ({e})") from None


def _programs(root) -> dict[str, list[tuple[float, str]]]:
    programs = {}
    for logic in root.iter("tlLogic"):
        tls = logic.get("id")
        if tls in programs:  # program 0 is the first one SUMO loads
            continue
        programs[tls] = [(float(p.get("duration", 0)), p.get("state", "")) for p in logic.iter("phase")]
    return programs


def _links(root) -> dict[str, list[tuple[str, str, int]]]:
    links: dict[str, list] = {}
    for c in root.iter("connection"):
        tls = c.get("tl")
        if tls is None:
            continue
        lane_in = f"{c.get('from')}_{c.get('fromLane')}"
        lane_out = f"{c.get('to')}_{c.get('toLane')}"
        links.setdefault(tls, []).append((lane_in, lane_out, int(c.get("linkIndex", -1))))
    return {k: sorted(v, key=lambda x: x[2]) for k, v in links.items()}


@functools.lru_cache(maxsize=16)
def _read_network(path: str, mtime: float) -> Network:
    root = _parse(path)
    lengths, lane_edges, shapes = {}, {}, {}
    for edge in root.iter("edge"):
        for lane in edge.iter("lane"):
            lengths[lane.get("id")] = float(lane.get("length", 0))
            lane_edges[lane.get("id")] = edge.get("id")
            if edge.get("function") != "internal":
                shapes[lane.get("id")] = [tuple(map(float, xy.split(",")[:2])) for xy in lane.get("shape", "").split()]
    links = _links(root)
    lights = []
    for tls, phases in _programs(root).items():
        greens = tuple(i for i, (_, s) in enumerate(phases) if is_green(s))
        tls_links = tuple(links.get(tls, ()))
        lanes = tuple(dict.fromkeys(i for i, _, _ in tls_links))
        if len(greens) < 2 or not lanes:
            # a light that controls nothing, or has one green only (a generated grid's corners): no
            # choice to learn, so no agent; it runs its own program
            continue
        lights.append(Light(tls, tuple(phases), greens, lanes, tls_links, tuple(lengths.get(x, 0.0) for x in lanes)))
    return Network(tuple(lights), lane_edges, shapes)


def read_network(net_file: str) -> Network:
    """The traffic lights of ``net_file`` (a BadInput if it has none or is malformed)."""
    try:
        net = _read_network(net_file, os.path.getmtime(net_file))
    except (ValueError, TypeError, AttributeError) as exc:
        if isinstance(exc, BadInput):
            raise
        raise BadInput(f"{net_file} is not a valid SUMO network ({type(exc).__name__}: {exc})") from None
    if not net.lights:
        raise BadInput(f"{net_file} has no traffic light that controls a lane with two greens or more: nothing to "
                       "learn")
    return net


__all__ = ["Light", "Network", "is_green", "read_network"]
