"""Experiment: traffic fidelity with the LS inserting cars from neighbours at SPEED (GS mean entry ~8.2 m/s) instead of 10."""

import sys

import torch

torch.set_num_threads(1)
speed = sys.argv[1]
from ials_zoo.traffic import cores
from ials_zoo.traffic.network import incoming_edges

FRINGE = ("top_", "bottom_", "left_", "right_")
table = [[("10" if incoming_edges((5, 5), k)[a].startswith(FRINGE) else speed) for a in range(4)] for k in range(25)]


def step(self, actions, inserts):
    ls = self.ls
    self.lights.act(actions)
    if inserts:
        add = ls._libsumo.vehicle_add
        for k, a, t in inserts:
            self.counters[k] += 1
            add(f"c{k}.{self.counters[k]:09d}", self.route_ids[k][a][t], "car", "now", "0", "base", table[k][a])
    self._sim_step(0.0)
    occ, entries, reward = self.reader.read()
    self.lights.tick()
    return occ, entries, reward, cores.np.array(self.lights.phase, cores.np.int64)


if speed != "10":
    cores.LocalCore.step = step
from ials_zoo.influence.fidelity import fidelity_report, markdown

TP = "leaderboard/policies/0f22715d32627b9c6b2e3a00514da869d8737da43dccfb7107d3949f8e7d985e.safetensors"
r = fidelity_report(
    "traffic_grid_v0", ["random", "constant", TP], episodes=10, predictor="on-policy-autoregressive", progress=False
)
print(markdown(r))
