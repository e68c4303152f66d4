"""Objects for tests of workers, importable by a worker (``tests/`` is on its ``sys.path``)."""

import atexit
import re
import time


def linger_at_exit():
    """A zygote preload: the zygote lingers 1.5 s in its exit (an atexit sleep), so a worker's
    answer to a killed parent meets a closed pipe."""
    atexit.register(time.sleep, 1.5)


class Slow:
    def nap(self):
        time.sleep(0.3)
        return "x" * 10


class GilHoldingCore:
    """A simulation core whose ``reset`` computes for about ``seconds`` in compiled code that
    holds Python's lock (as libsumo does while it loads a network): no heartbeat meanwhile."""

    def __init__(self, a_count: int = 25, stall: bool = False):
        self.a_count, self.stall = a_count, stall

    def reset(self):
        if self.stall:  # holds the lock and computes nothing: a hang, not a load
            import ctypes

            ctypes.PyDLL(None).usleep(3_000_000)
            return "stalled"
        re.match(r"(a+)+$", "a" * self.a_count + "b")  # backtracks in C, the lock held throughout
        return "loaded"

    def close(self):
        pass
