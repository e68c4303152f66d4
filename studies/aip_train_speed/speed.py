"""How long the stacked training of many AIPs takes, on data shaped like a real network's
regions: ``--regions`` regions of ``--sources`` influence sources each (two thirds with 3
classes, a third with 2, as ingolstadt21's entries and exits), ``--dset`` d-set bits, 720 steps
of random data. Prints the median and range of ``--repeats`` trainings of ``--epochs`` epochs.

    python studies/aip_train_speed/speed.py --regions 3 --sources 150 --epochs 5 --repeats 3

Run it at two commits (a git worktree on ``PYTHONPATH``) to compare them on the same machine.
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def _datasets(regions: int, sources: int, dset: int, steps: int) -> dict:
    from ials_zoo.core.region import RegionSpec
    from ials_zoo.influence.dataset import InfluenceDataset

    rng = np.random.default_rng(0)
    classes = tuple(3 if m % 3 else 2 for m in range(sources))
    out = {}
    for g in range(regions):
        names = {"dset": tuple(f"d{i}" for i in range(dset)), "full": tuple(f"f{i}" for i in range(dset + 2))}
        region = RegionSpec("synthetic_v0", f"light{g}", tuple(f"s{m}" for m in range(sources)), classes, names)
        d = (rng.random((1, steps, dset)) < 0.3).astype(np.uint8)
        full = np.concatenate([d, np.zeros((1, steps, 2), np.uint8)], axis=-1)
        u = np.stack([rng.integers(0, k, (1, steps)) for k in classes], axis=-1)
        out[region.agent] = InfluenceDataset(region, {"dset": d, "full": full}, u, {})
    return out


def main(argv=None) -> None:
    from ials_zoo.influence.train import train_predictors

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--regions", type=int, default=3)
    parser.add_argument("--sources", type=int, default=150)
    parser.add_argument("--dset", type=int, default=100)
    parser.add_argument("--epochs", type=int, default=5)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args(argv)
    data = _datasets(args.regions, args.sources, args.dset, 720)
    seconds = []
    for _ in range(args.repeats):
        start = time.perf_counter()
        train_predictors(data, "mlp", hidden=64, lr=3e-3, epochs=args.epochs, batch_size=256)
        seconds.append(time.perf_counter() - start)
    print(f"{args.regions} regions x {args.sources} sources, {args.epochs} epochs: median {np.median(seconds):.2f} s "
          f"[{min(seconds):.2f}, {max(seconds):.2f}] over {args.repeats}")


if __name__ == "__main__":
    main()
