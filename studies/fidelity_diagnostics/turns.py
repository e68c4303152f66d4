"""Diagnostic: the turns cars actually make at a light in the GS vs the LS's turning probabilities."""

import numpy as np

from ials_zoo.core.domains import get_domain
from ials_zoo.traffic.network import (
    _HEADING,
    APPROACHES,
    TURNS,
    _turn_of,
    incoming_edges,
    outgoing_edges,
    turn_probabilities,
)

dom = get_domain("traffic_grid_v0")
agents = dom.agents()
gs = dom.parallel_env(learners=agents, scripted_learners=True)
for idx in (0, 1, 12):
    ins, outs = incoming_edges((5, 5), idx), outgoing_edges((5, 5), idx)
    counts = np.zeros((4, 3))
    seen = set()
    for ep in range(3):
        gs.reset(seed=ep)
        while gs.agents:
            gs.step({a: 0 for a in gs.agents})
            for ia, e in enumerate(ins):
                for v in gs.sumo_query("lane", "getLastStepVehicleIDs", e + "_0"):
                    if (ep, v) in seen:
                        continue
                    seen.add((ep, v))
                    route = gs.sumo_query("vehicle", "getRoute", v)
                    i = route.index(e)
                    if i + 1 < len(route):
                        ob = outs.index(route[i + 1])
                        dr, dc = _HEADING[APPROACHES[ob]]
                        counts[ia, TURNS.index(_turn_of(APPROACHES[ia], (-dr, -dc)))] += 1
    emp = counts / counts.sum(1, keepdims=True)
    print(
        f"tls_{idx} (right, straight, left) per approach N,E,S,W\n  GS actual  {np.round(emp, 2).tolist()}  n={counts.sum(1).astype(int).tolist()}\n  LS probs   {np.round(turn_probabilities((5, 5), idx), 2).tolist()}"
    )
gs.close()
