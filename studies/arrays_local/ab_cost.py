"""The array simulator of this checkout against its own version at a git revision, timed turn by
turn in one process (issue 50): µs per agent-decision of every light's IALS on arrays, 64 copies,
random lights, AIPs of the GS's entry frequencies; the ratio of each turn, median [min, max].

The other version's ``ials_zoo/sumo_net/arrays.py`` is read from git and loaded beside this one
(it must fit this checkout's layout, ``arrays_layout``). Usage: python studies/arrays_local/ab_cost.py
REV [--net grid10x10] [--copies 64] [--decisions 40] [--turns 7]. Nothing is written.
"""

from __future__ import annotations

import argparse
import importlib.util
import subprocess
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]


def arrays_at(rev: str, folder: Path):
    """The module ``ials_zoo/sumo_net/arrays.py`` as it was at ``rev``."""
    text = subprocess.run(["git", "show", f"{rev}:ials_zoo/sumo_net/arrays.py"], cwd=ROOT, capture_output=True,
                          text=True, check=True).stdout
    path = folder / "arrays_at_rev.py"
    path.write_text(text)
    spec = importlib.util.spec_from_file_location("arrays_at_rev", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("rev")
    parser.add_argument("--net", default="grid10x10")
    parser.add_argument("--copies", type=int, default=64)
    parser.add_argument("--decisions", type=int, default=40)
    parser.add_argument("--turns", type=int, default=7)
    args = parser.parse_args()
    if min(args.copies, args.decisions, args.turns) < 1:
        parser.error("--copies, --decisions and --turns must be positive")
    if subprocess.run(["git", "rev-parse", "--verify", f"{args.rev}^{{commit}}"], cwd=ROOT,
                      capture_output=True).returncode:
        parser.error(f"rev: {args.rev!r} is not a commit of this repository")

    from ials_zoo.sumo_net import arrays, arrays_core
    from ials_zoo.sumo_net.arrays_vec import ArrayIALSCopies
    from ials_zoo.sumo_net.benchmark import _ials_episode
    from ials_zoo.sumo_net.island import gs_marginal_predictors
    from ials_zoo.sumo_net.network import read_network
    from ials_zoo.sumo_net.scenario import scenario_of

    lights = read_network(scenario_of(net=args.net).net_file).ids
    aips = gs_marginal_predictors(lights, net=args.net, max_cycles=args.decisions)
    with tempfile.TemporaryDirectory() as tmp:
        envs = {}
        for name, module in (("this checkout", arrays), (args.rev, arrays_at(args.rev, Path(tmp)))):
            arrays_core.ArraySim = module.ArraySim  # the core builds its simulator from this name
            envs[name] = ArrayIALSCopies(None, aips, list(range(args.copies)), net=args.net,
                                         max_cycles=args.decisions)
        arrays_core.ArraySim = arrays.ArraySim
        took = {name: [] for name in envs}
        for turn in range(args.turns):
            for name, env in envs.items():
                took[name].append(_ials_episode(env, args.decisions, turn) / args.copies / len(lights) * 1e6)
    ratio = np.array(took["this checkout"]) / np.array(took[args.rev])
    print(f"{args.net} x{args.copies}: this checkout {np.median(took['this checkout']):.1f} µs, {args.rev} "
          f"{np.median(took[args.rev]):.1f} µs per agent-decision; this / {args.rev}: {np.median(ratio):.3f} "
          f"[{ratio.min():.3f}, {ratio.max():.3f}] over {args.turns} turns")


if __name__ == "__main__":
    main()
