"""Entry point of a :class:`ials_zoo.runtime.processes.Zygote`: ``python -m ials_zoo.runtime._zygote FD SETUP``.

``FD`` is the Unix socket to take fork requests from, ``SETUP`` the JSON ``[sys.path, preload]``.
"""

import sys

from ials_zoo.runtime.zygote import zygote_main

if __name__ == "__main__":
    zygote_main(int(sys.argv[1]), sys.argv[2])
