"""What each of the arrays' rules gives on the replay contract (issue 50): the GS's entries of
NET's first SECONDS recorded once, then replayed on the arrays (lanes calibrated) with every rule,
and with each rule taken out in turn; two seeds each. Prints vehicles / halting per variant.

  all          the arrays as they are
  no-start     every program begins at its first phase (the arrays before commit 8547e25)
  no-turn      no braking for a turn's speed limit
  no-entry     an entry keeps the lane it came in on
  entry=P      the entries' lane penalty P (vehicles per share) instead of ENTRY_PENALTY

The rules are taken out by replacing what the simulator reads (module constants and functions),
in this process only. Usage: python studies/arrays_local/ablate.py NET [--seconds 1800]
[--variants all,no-start,no-turn,no-entry,entry=4]. Nothing is written.
"""

from __future__ import annotations

import argparse
import tempfile
from contextlib import contextmanager

import numpy as np

VARIANTS = ("all", "no-start", "no-turn", "no-entry")


@contextmanager
def variant(name: str):
    """The arrays with one rule taken out (or the entries' penalty changed) inside the block."""
    from ials_zoo.sumo_net import arrays

    saved = {k: getattr(arrays, k) for k in ("ENTRY_PENALTY", "free_speed")}
    reset = arrays.ArraySim.reset

    def first_phase_reset(self, seed):
        reset(self, seed)
        self.phase[:], self.elapsed[:] = 0, -1.0

    try:
        if name == "no-start":
            arrays.ArraySim.reset = first_phase_reset
        elif name == "no-turn":
            arrays.free_speed = lambda dist, target, b: np.full(np.shape(dist), np.inf)
        elif name == "no-entry":
            arrays.ENTRY_PENALTY = np.inf
        elif name.startswith("entry="):
            arrays.ENTRY_PENALTY = float(name.split("=", 1)[1])
        elif name != "all":
            raise ValueError(f"unknown variant {name!r}: {', '.join(VARIANTS)} or entry=P")
        yield
    finally:
        arrays.ArraySim.reset = reset
        for k, v in saved.items():
            setattr(arrays, k, v)


def record(net: str, seconds: int) -> tuple:
    """The scenario, the GS's lane states and the arguments of one arrays replay of its entries."""
    from ials_zoo.sumo_net import replay
    from ials_zoo.sumo_net.arrays_calibration import lane_shares
    from ials_zoo.sumo_net.regions import regions_of
    from ials_zoo.sumo_net.scenario import make_scenario

    scenario = make_scenario(net=net)
    captured, original = {}, replay.replay_arrays

    def capture(scenario, regions, entries, observed, seed=0, shares=None):
        captured.update(regions=regions, entries=entries, observed=observed, shares=shares)
        return original(scenario, regions, entries, observed, seed, shares)

    replay.replay_arrays = capture
    try:
        with tempfile.TemporaryDirectory() as tmp:
            out = replay.replay_regions(scenario, regions_of(scenario.net_file), seconds, tmp, local="arrays",
                                        calibration=lane_shares(scenario))
    finally:
        replay.replay_arrays = original
    return scenario, out["gs"], captured


def main() -> None:
    from ials_zoo.sumo_net.replay import replay_arrays, replay_error

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("net")
    parser.add_argument("--seconds", type=int, default=1800)
    parser.add_argument("--variants", default=",".join(VARIANTS))
    args = parser.parse_args()
    names = args.variants.split(",")
    for name in names:  # a bad name is refused before the GS runs
        try:
            with variant(name):
                pass
        except ValueError as exc:
            parser.error(f"--variants: {exc}")
    scenario, gs, c = record(args.net, args.seconds)
    for name in names:
        with variant(name):
            errors = [replay_error(gs, replay_arrays(scenario, c["regions"], c["entries"], c["observed"], seed,
                                                     c["shares"])[0]) for seed in (0, 1)]
        print(f"{args.net} {name}: vehicles {np.mean([e['vehicles'] for e in errors]):.3f} "
              f"halting {np.mean([e['halting'] for e in errors]):.3f}", flush=True)


if __name__ == "__main__":
    main()
