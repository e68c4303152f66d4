"""Entry point of a :class:`ials_zoo.runtime.processes.Worker`: ``python -m ials_zoo.runtime._worker R W B``.

``R`` / ``W`` are the pipe file descriptors to read requests from and write answers to, ``B``
the one to write heartbeats to.
"""

import sys

from ials_zoo.runtime.processes import serve

if __name__ == "__main__":
    serve(*(int(a) for a in sys.argv[1:4]))
