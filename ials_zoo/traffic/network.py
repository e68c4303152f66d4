"""Build the SUMO files of the traffic domain from code, cached on disk.

Two networks are built here:

* the **grid** (the global simulator, SPEC §2): ``rows x cols`` signalised intersections,
  one lane per direction, every edge 100 m long (inner edges and the fringe edges that
  connect the outer intersections to the boundary), speed limit 10 m/s;
* the **local** network (the local simulator): ``n`` disjoint copies of one intersection with
  its 4 incoming and 4 outgoing 100 m edges, so that one ``simulationStep()`` advances every
  copy.

Naming (the index mapping every other module uses):

* intersection ``i = row * cols + col``, row 0 at the top (north), column 0 on the left
  (west); its SUMO junction and traffic-light id, and the agent name, is ``"tls_<i>"``. In
  the 5 x 5 grid index 12 is the centre and index 18 is row 3, column 3.
* fringe nodes: ``top_<col>``, ``bottom_<col>``, ``left_<row>``, ``right_<row>``.
* the edge from node ``A`` to node ``B`` is ``"A__B"``; its single lane is ``"A__B_0"``.
* approach order everywhere (observation, influence bits, turning tables): **N, E, S, W** --
  the incoming lane from the northern neighbour first, then east, south, west.

Demand (SPEC §2): every fringe entry edge carries a ``<flow probability="p">`` (a car w.p.
``p`` per 1 s step, ``departSpeed="10"``). Its route is drawn, per vehicle, from a
``routeDistribution``: a uniformly random exit among the other fringe exits (the U-turn back
out of the entry's own boundary node is excluded), then uniformly one of the shortest paths
to that exit with the fewest turns (e.g. west->east on the same row: straight through; west
row r -> east row r': the turning column is uniform). Vehicles: IDM, length 5 m, minGap
2.5 m, decel 7.5 m/s^2, accel 2.6 m/s^2, speedFactor exactly 1 (no speed deviation), so the
only randomness is the insertion and the route draw (seeded by SUMO's ``--seed``).

Traffic lights: each intersection's 12 links (right, straight, left from each approach; no
U-turns) are grouped into two greens, phase 0 = north-south green, phase 2 = east-west
green (left turns ``g``: they yield to oncoming traffic), phases 1 / 3 their yellows. The
scripted (non-learning) program is SUMO's ``actuated`` type with SPEC §2's numbers: green 31 s
(min 8, max 45), yellow 6 s (min 3, max 6), ``max-gap`` 3.0, ``detector-gap`` 0.8.

Files are built into ``$IALS_ZOO_CACHE/traffic/<hash>/`` (default
``~/.cache/ials_zoo/traffic/<hash>/``), the hash covering every parameter and the builder
version; a directory is built in a temporary sibling and renamed into place, so a reader
never sees a half-built network.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import subprocess
import tempfile
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ials_zoo.errors import BadInput, BadInputType

BUILDER_VERSION = 3
EDGE_LENGTH = 100.0
SPEED_LIMIT = 10.0
CELL_LENGTH = 10.0
N_CELLS = 9
APPROACHES = ("N", "E", "S", "W")
# unit steps (drow, dcol) of a car *arriving from* each approach: from the north it heads south
_HEADING = {"N": (1, 0), "E": (0, -1), "S": (-1, 0), "W": (0, 1)}
TURNS = ("right", "straight", "left")
MIN_GRID, MAX_GRID = 2, 10
MAX_BUILT_GRID = 20  # what the builders take (sumo_net_v0's grids by name); the env's own option stays within MAX_GRID

GREEN_DUR, GREEN_MIN, GREEN_MAX = 31, 8, 45
YELLOW_DUR, YELLOW_MIN, YELLOW_MAX = 6, 3, 6
MAX_GAP, DETECTOR_GAP = 3.0, 0.8

VTYPE_XML = (
    '<vType id="car" carFollowModel="IDM" length="5" minGap="2.5" accel="2.6" decel="7.5" '
    'maxSpeed="10" speedFactor="1" speedDev="0" tau="1.0"/>'
)


def cache_root() -> Path:
    """Root of the file cache: ``$IALS_ZOO_CACHE/traffic`` or ``~/.cache/ials_zoo/traffic``."""
    base = os.environ.get("IALS_ZOO_CACHE")
    root = Path(base) if base else Path.home() / ".cache" / "ials_zoo"
    return root / "traffic"


def check_grid(grid, max_side: int = MAX_GRID) -> tuple[int, int]:
    """Validate a grid size: a pair of ints, each in ``[2, max_side]`` (the env's: 10)."""
    if isinstance(grid, (str, bytes)) or not hasattr(grid, "__len__") or len(grid) != 2:
        raise BadInput(f"grid must be a pair (rows, cols), got {grid!r}")
    out = []
    for g in grid:
        if isinstance(g, bool) or not isinstance(g, (int, np.integer)):
            raise BadInputType(f"grid sizes must be ints, got {grid!r}")
        if not MIN_GRID <= int(g) <= max_side:
            raise BadInput(
                f"grid sizes must be in [{MIN_GRID}, {max_side}], got {grid!r}"
            )
        out.append(int(g))
    return out[0], out[1]


def check_bool(name: str, value) -> bool:
    if not isinstance(value, (bool, np.bool_)):
        raise BadInputType(f"{name} must be a bool, got {value!r}")
    return bool(value)


def check_probability(p) -> float:
    if isinstance(p, bool) or not isinstance(p, (int, float, np.floating, np.integer)):
        raise BadInputType(f"inflow_probability must be a number, got {p!r}")
    if not 0.0 <= float(p) <= 1.0:
        raise BadInput(f"inflow_probability must be in [0, 1], got {p!r}")
    return float(p)


# ----------------------------------------------------------------------------- grid geometry


def tls_id(index: int) -> str:
    return f"tls_{index}"


def _node_name(rows: int, cols: int, r: int, c: int) -> str:
    """Node at grid coordinate (r, c); the fringe nodes sit just outside the grid."""
    if r == -1:
        return f"top_{c}"
    if r == rows:
        return f"bottom_{c}"
    if c == -1:
        return f"left_{r}"
    if c == cols:
        return f"right_{r}"
    return tls_id(r * cols + c)


def _neighbour(r: int, c: int, approach: str) -> tuple[int, int]:
    dr, dc = _HEADING[approach]
    return r - dr, c - dc


def incoming_edges(grid, index: int) -> tuple[str, ...]:
    """The 4 incoming edges of intersection ``index``, in N, E, S, W order."""
    rows, cols = check_grid(grid, MAX_BUILT_GRID)
    r, c = divmod(index, cols)
    me = tls_id(index)
    return tuple(
        f"{_node_name(rows, cols, *_neighbour(r, c, a))}__{me}" for a in APPROACHES
    )


def outgoing_edges(grid, index: int) -> tuple[str, ...]:
    """The 4 outgoing edges of intersection ``index``, towards N, E, S, W."""
    rows, cols = check_grid(grid, MAX_BUILT_GRID)
    r, c = divmod(index, cols)
    me = tls_id(index)
    return tuple(
        f"{me}__{_node_name(rows, cols, *_neighbour(r, c, a))}" for a in APPROACHES
    )


def _fringe(rows: int, cols: int) -> list[tuple[int, int, str]]:
    """Fringe nodes as (r, c, side), side = the side of the grid they are on."""
    out = [(-1, c, "N") for c in range(cols)]
    out += [(r, cols, "E") for r in range(rows)]
    out += [(rows, c, "S") for c in range(cols)]
    out += [(r, -1, "W") for r in range(rows)]
    return out


def _min_turn_paths(rows: int, cols: int, src: tuple[int, int], dst: tuple[int, int]):
    """Shortest node paths src -> dst through the grid interior with the fewest turns."""
    inside = lambda r, c: 0 <= r < rows and 0 <= c < cols

    def nbrs(r, c):
        for dr, dc in ((1, 0), (-1, 0), (0, 1), (0, -1)):
            rr, cc = r + dr, c + dc
            if inside(rr, cc) or (rr, cc) == dst:
                yield (rr, cc), (dr, dc)

    # BFS distances to dst over the interior (fringe nodes other than dst are dead ends)
    dist = {dst: 0}
    frontier = [dst]
    while frontier:
        nxt = []
        for node in frontier:
            for (rr, cc), _ in nbrs(*node):
                if (rr, cc) not in dist and inside(rr, cc):
                    dist[(rr, cc)] = dist[node] + 1
                    nxt.append((rr, cc))
        frontier = nxt
    best: list[list[tuple[int, int]]] = []
    best_turns = [10**9]

    def dfs(node, heading, turns, path):
        if turns > best_turns[0]:
            return
        if node == dst:
            if turns < best_turns[0]:
                best_turns[0] = turns
                best.clear()
            best.append(list(path))
            return
        for nb, step in nbrs(*node):
            if nb != dst and not inside(*nb):
                continue
            if dist.get(nb, 10**9) != dist[node] - 1:
                continue
            t = turns + (heading is not None and step != heading)
            path.append(nb)
            dfs(nb, step, t, path)
            path.pop()

    # leaving the fringe node: first step goes into the grid
    for nb, step in nbrs(*src):
        if inside(*nb) and nb in dist:
            dist[src] = dist[nb] + 1
    dfs(src, None, 0, [src])
    return best


@dataclass
class GridRoutes:
    """The route set of the grid: per entry edge, a list of (edge list, probability)."""

    routes: dict[str, list[tuple[list[str], float]]]


def grid_routes(grid) -> GridRoutes:
    """Every entry's route distribution (see the module docstring)."""
    rows, cols = check_grid(grid, MAX_BUILT_GRID)
    fringe = _fringe(rows, cols)
    out: dict[str, list[tuple[list[str], float]]] = {}
    for src in fringe:
        exits = [f for f in fringe if f != src]
        entry_edge = None
        dist = []
        for dst in exits:
            paths = _min_turn_paths(rows, cols, src[:2], dst[:2])
            for p in paths:
                names = [_node_name(rows, cols, r, c) for r, c in p]
                edges = [f"{a}__{b}" for a, b in zip(names[:-1], names[1:])]
                entry_edge = edges[0]
                dist.append((edges, 1.0 / len(exits) / len(paths)))
        out[entry_edge] = dist
    return GridRoutes(out)


def _turn_of(in_approach: str, out_heading: tuple[int, int]) -> str:
    h = _HEADING[in_approach]
    if out_heading == h:
        return "straight"
    # headings as (drow, dcol) with row growing southwards: right of south-heading is west
    right = (h[1], -h[0])
    if out_heading == right:
        return "right"
    if out_heading == (-h[0], -h[1]):
        return "uturn"
    return "left"


def turn_probabilities(grid, index: int, inflow_probability: float = 0.1) -> np.ndarray:
    """Expected turning probabilities at intersection ``index`` under the grid's demand.

    Returns an array ``[4, 3]``: for each approach (N, E, S, W) the probability that a car
    arriving from it turns right / goes straight / turns left, computed exactly from the route
    distributions (every entry inserts at the same rate, so congestion aside this is the
    fraction of the cars crossing the intersection). Rows with no traffic are uniform.
    """
    rows, cols = check_grid(grid, MAX_BUILT_GRID)
    check_index(grid, index)
    ins = incoming_edges(grid, index)
    outs = outgoing_edges(grid, index)
    counts = np.zeros((4, 3))
    for dist in grid_routes(grid).routes.values():
        for edges, p in dist:
            for a, b in zip(edges[:-1], edges[1:]):
                if a in ins and b in outs:
                    ia, ob = ins.index(a), outs.index(b)
                    # outgoing towards approach side ob: heading away from me towards it
                    dr, dc = _HEADING[APPROACHES[ob]]
                    turn = _turn_of(APPROACHES[ia], (-dr, -dc))
                    counts[ia, TURNS.index(turn)] += p * inflow_probability
    tot = counts.sum(axis=1, keepdims=True)
    return np.where(tot > 0, counts / np.where(tot > 0, tot, 1), 1.0 / 3.0)


def check_index(grid, index) -> int:
    rows, cols = check_grid(grid, MAX_BUILT_GRID)
    if isinstance(index, bool) or not isinstance(index, (int, np.integer)):
        raise BadInputType(f"intersection index must be an int, got {index!r}")
    if not 0 <= int(index) < rows * cols:
        raise BadInput(
            f"intersection index {index} out of range for a {rows}x{cols} grid "
            f"(0..{rows * cols - 1})"
        )
    return int(index)


# ----------------------------------------------------------------------------- file building


def _write_plain(tmp: Path, nodes: list, edges: list) -> tuple[Path, Path]:
    nod = ["<nodes>"]
    for nid, x, y, typ in nodes:
        nod.append(f'  <node id="{nid}" x="{x:.2f}" y="{y:.2f}" type="{typ}"/>')
    nod.append("</nodes>")
    edg = ["<edges>"]
    for eid, a, b in edges:
        edg.append(
            f'  <edge id="{eid}" from="{a}" to="{b}" numLanes="1" speed="{SPEED_LIMIT}" '
            f'length="{EDGE_LENGTH}" priority="1"/>'
        )
    edg.append("</edges>")
    (tmp / "plain.nod.xml").write_text("\n".join(nod) + "\n")
    (tmp / "plain.edg.xml").write_text("\n".join(edg) + "\n")
    return tmp / "plain.nod.xml", tmp / "plain.edg.xml"


def _netconvert(tmp: Path, nod: Path, edg: Path, internal_links: bool = True) -> Path:
    import sumo

    # sumo.SUMO_HOME, not the environment variable: importing libsumo may point that elsewhere
    exe = Path(sumo.SUMO_HOME) / "bin" / "netconvert"
    net = tmp / "net.net.xml"
    cmd = [
        str(exe), "-n", str(nod), "-e", str(edg), "-o", str(net),
        "--no-turnarounds", "true", "--tls.default-type", "static",
        "--no-internal-links", "false" if internal_links else "true",
        "--no-warnings", "true", "--offset.disable-normalization", "true",
    ]  # fmt: skip
    res = subprocess.run(cmd, capture_output=True, text=True)
    if res.returncode != 0 or not net.exists():
        raise RuntimeError(f"netconvert failed ({res.returncode}): {res.stderr.strip()}")
    return net


def _phase_states(net: Path, approach_of_edge: dict[str, str]) -> dict[str, list[str]]:
    """The 4 light states (NS green, NS yellow, EW green, EW yellow) of every TLS."""
    links: dict[str, dict[int, tuple[str, str]]] = {}
    for conn in ET.parse(net).getroot().iter("connection"):
        tl = conn.get("tl")
        if tl is None:
            continue
        links.setdefault(tl, {})[int(conn.get("linkIndex"))] = (
            approach_of_edge[conn.get("from")],
            conn.get("dir"),
        )
    out = {}
    for tl, lk in links.items():
        n = max(lk) + 1
        if sorted(lk) != list(range(n)):
            raise RuntimeError(f"unexpected link indices at {tl}: {sorted(lk)}")
        states = []
        for group, yellow in (("NS", False), ("NS", True), ("EW", False), ("EW", True)):
            s = []
            for i in range(n):
                app, d = lk[i]
                if app not in group:
                    s.append("r")
                elif yellow:
                    s.append("y")
                else:
                    s.append("g" if d == "l" else "G")
            states.append("".join(s))
        out[tl] = states
    return out


def _tls_additional(states: dict[str, list[str]], tls_ids) -> str:
    lines = ["<additional>"]
    for tl in tls_ids:
        g1, y1, g2, y2 = states[tl]
        lines += [
            f'  <tlLogic id="{tl}" type="actuated" programID="actuated" offset="0">',
            f'    <param key="max-gap" value="{MAX_GAP}"/>',
            f'    <param key="detector-gap" value="{DETECTOR_GAP}"/>',
            f'    <phase duration="{GREEN_DUR}" minDur="{GREEN_MIN}" maxDur="{GREEN_MAX}" state="{g1}"/>',
            f'    <phase duration="{YELLOW_DUR}" minDur="{YELLOW_MIN}" maxDur="{YELLOW_MAX}" state="{y1}"/>',
            f'    <phase duration="{GREEN_DUR}" minDur="{GREEN_MIN}" maxDur="{GREEN_MAX}" state="{g2}"/>',
            f'    <phase duration="{YELLOW_DUR}" minDur="{YELLOW_MIN}" maxDur="{YELLOW_MAX}" state="{y2}"/>',
            "  </tlLogic>",
        ]
    lines.append("</additional>")
    return "\n".join(lines) + "\n"


def _cached_build(kind: str, params: dict, builder) -> Path:
    key = json.dumps({"kind": kind, "v": BUILDER_VERSION, **params}, sort_keys=True)
    digest = hashlib.sha256(key.encode()).hexdigest()[:16]
    root = cache_root()
    final = root / f"{kind}-{digest}"
    if (final / "meta.json").exists():
        return final
    root.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{kind}-{digest}.", dir=root))
    try:
        meta = builder(tmp)
        meta["params"] = params
        (tmp / "meta.json").write_text(json.dumps(meta, indent=1))
        os.chmod(tmp, 0o755)
        try:
            os.rename(tmp, final)
        except OSError:
            # another process finished the same build first: theirs is identical
            if not (final / "meta.json").exists():
                raise
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)
    return final


@dataclass(frozen=True)
class NetworkFiles:
    """Paths of one built network plus its metadata (``meta.json``)."""

    directory: Path
    meta: dict

    @property
    def net(self) -> str:
        return str(self.directory / "net.net.xml")

    @property
    def routes(self) -> str:
        return str(self.directory / "routes.rou.xml")

    @property
    def tls_additional(self) -> str | None:
        p = self.directory / "tls.add.xml"
        return str(p) if p.exists() else None


def build_grid(
    grid=(5, 5), inflow_probability: float = 0.1, internal_links: bool = True, max_side: int = MAX_GRID
) -> NetworkFiles:
    """Build (or fetch from the cache) the grid network, its demand and its actuated lights.

    ``internal_links=False`` builds the network without junction-internal lanes (vehicles
    jump from an incoming lane to the outgoing one): SUMO runs faster, but crossing a
    junction then takes no time and space. ``max_side``: the largest side allowed (the env's
    10; ``sumo_net_v0``'s grids by name go further).
    """
    rows, cols = check_grid(grid, max_side)
    p = check_probability(inflow_probability)
    internal_links = check_bool("internal_links", internal_links)

    def builder(tmp: Path) -> dict:
        nodes, edges = [], []
        height = (rows + 1) * EDGE_LENGTH
        pos = lambda r, c: ((c + 1) * EDGE_LENGTH, height - (r + 1) * EDGE_LENGTH)
        for r in range(rows):
            for c in range(cols):
                nodes.append((tls_id(r * cols + c), *pos(r, c), "traffic_light"))
        for r, c, _ in _fringe(rows, cols):
            nodes.append((_node_name(rows, cols, r, c), *pos(r, c), "priority"))
        approach_of_edge = {}
        for r in range(rows):
            for c in range(cols):
                me = tls_id(r * cols + c)
                for a in APPROACHES:
                    nb = _node_name(rows, cols, *_neighbour(r, c, a))
                    edges.append((f"{nb}__{me}", nb, me))
                    approach_of_edge[f"{nb}__{me}"] = a
                    if nb.startswith(("top", "bottom", "left", "right")):
                        edges.append((f"{me}__{nb}", me, nb))
        nod, edg = _write_plain(tmp, nodes, edges)
        net = _netconvert(tmp, nod, edg, internal_links)
        states = _phase_states(net, approach_of_edge)
        tls_ids = [tls_id(i) for i in range(rows * cols)]
        (tmp / "tls.add.xml").write_text(_tls_additional(states, tls_ids))
        routes = grid_routes((rows, cols)).routes
        rl = ["<routes>", "  " + VTYPE_XML]
        for entry, dist in sorted(routes.items()):
            rl.append(f'  <routeDistribution id="rd_{entry}">')
            for k, (path, prob) in enumerate(dist):
                rl.append(
                    f'    <route id="r_{entry}_{k}" edges="{" ".join(path)}" '
                    f'probability="{prob:.9f}"/>'
                )
            rl.append("  </routeDistribution>")
        for entry in sorted(routes):
            rl.append(
                f'  <flow id="f_{entry}" type="car" route="rd_{entry}" begin="0" end="1e9" '
                f'probability="{p}" departSpeed="10" departLane="0"/>'
            )
        rl.append("</routes>")
        (tmp / "routes.rou.xml").write_text("\n".join(rl) + "\n")
        for f in (nod, edg):
            f.unlink()
        return {"kind": "grid", "grid": [rows, cols], "states": states,
                "entries": sorted(routes)}  # fmt: skip

    params = {"grid": [rows, cols], "inflow_probability": p, "internal_links": internal_links}
    d = _cached_build("grid", params, builder)
    return NetworkFiles(d, json.loads((d / "meta.json").read_text()))


def local_copy_ids(k: int) -> dict:
    """Names in copy ``k`` of the local network: tls id, incoming/outgoing edges (N,E,S,W)."""
    c = f"c{k}"
    return {
        "tls": c,
        "in": tuple(f"{c}_{a}__{c}" for a in APPROACHES),
        "out": tuple(f"{c}__{c}_{a}" for a in APPROACHES),
    }


def build_local(n_copies: int, internal_links: bool = True) -> NetworkFiles:
    """Build (or fetch) ``n_copies`` disjoint single intersections in one network.

    Copy ``k`` has its centre junction / TLS ``c<k>``, boundary nodes ``c<k>_N`` ... and
    edges ``c<k>_N__c<k>`` (incoming from the north) and ``c<k>__c<k>_N`` (outgoing to the
    north). ``meta["routes"][k][a][t]`` is the route id of a car arriving from approach ``a``
    (N, E, S, W) that takes turn ``t`` (right, straight, left).
    """
    if isinstance(n_copies, bool) or not isinstance(n_copies, (int, np.integer)):
        raise BadInputType(f"n_envs must be an int, got {n_copies!r}")
    if n_copies < 1:
        raise BadInput(f"n_envs must be >= 1, got {n_copies}")
    n_copies = int(n_copies)
    internal_links = check_bool("internal_links", internal_links)

    def builder(tmp: Path) -> dict:
        nodes, edges, approach_of_edge = [], [], {}
        routes_xml, route_ids = [], []
        for k in range(n_copies):
            ids = local_copy_ids(k)
            # Every copy at the same coordinates: the copies share no edge, so they never
            # meet, and netconvert computes bitwise the same lane lengths and junction shapes
            # for each (at other offsets rounding differs, and with it a copy's dynamics).
            cx = cy = EDGE_LENGTH
            c = ids["tls"]
            nodes.append((c, cx, cy, "traffic_light"))
            for a in APPROACHES:
                dr, dc = _HEADING[a]
                # the approach's boundary node lies opposite to the heading
                nodes.append((f"{c}_{a}", cx - dc * EDGE_LENGTH, cy + dr * EDGE_LENGTH, "priority"))
                edges.append((f"{c}_{a}__{c}", f"{c}_{a}", c))
                edges.append((f"{c}__{c}_{a}", c, f"{c}_{a}"))
                approach_of_edge[f"{c}_{a}__{c}"] = a
            per_app = []
            for ai, a in enumerate(APPROACHES):
                per_turn = []
                for t in TURNS:
                    for bi, b in enumerate(APPROACHES):
                        dr, dc = _HEADING[b]
                        if bi != ai and _turn_of(a, (-dr, -dc)) == t:
                            rid = f"{c}_{a}_{t}"
                            routes_xml.append(
                                f'  <route id="{rid}" edges="{c}_{a}__{c} {c}__{c}_{b}"/>'
                            )
                            per_turn.append(rid)
                per_app.append(per_turn)
            route_ids.append(per_app)
        nod, edg = _write_plain(tmp, nodes, edges)
        net = _netconvert(tmp, nod, edg, internal_links)
        states = _phase_states(net, approach_of_edge)
        (tmp / "routes.rou.xml").write_text(
            "\n".join(["<routes>", "  " + VTYPE_XML, *routes_xml, "</routes>"]) + "\n"
        )
        for f in (nod, edg):
            f.unlink()
        return {"kind": "local", "n_copies": n_copies, "states": states, "routes": route_ids}

    d = _cached_build("local", {"n_copies": n_copies, "internal_links": internal_links, "layout": "stacked"},
                      builder)
    return NetworkFiles(d, json.loads((d / "meta.json").read_text()))
