"""Entry point of a SUMO worker process: ``python -m ials_zoo.traffic._worker R W``.

``R`` / ``W`` are the pipe file descriptors to read requests from and write answers to
(see :class:`ials_zoo.traffic.sim.SimHandle`).
"""

import sys

from ials_zoo.traffic.sim import _worker_main

if __name__ == "__main__":
    _worker_main(int(sys.argv[1]), int(sys.argv[2]))
