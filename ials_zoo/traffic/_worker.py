"""Entry point of a SUMO worker process: ``python -m ials_zoo.traffic._worker R W B``.

``R`` / ``W`` are the pipe file descriptors to read requests from and write answers to, ``B``
the one to write heartbeats to (see :class:`ials_zoo.traffic.lease.SimHandle`).
"""

import sys

from ials_zoo.traffic.lease import worker_main

if __name__ == "__main__":
    worker_main(*(int(a) for a in sys.argv[1:4]))
