"""A worker object and a zygote preload for tests of what a worker does when its parent is
killed mid-call: the zygote lingers 1.5 s in its exit (an atexit sleep), so the worker's answer
meets a closed pipe."""

import atexit
import time


def linger_at_exit():
    atexit.register(time.sleep, 1.5)


class Slow:
    def nap(self):
        time.sleep(0.3)
        return "x" * 10
