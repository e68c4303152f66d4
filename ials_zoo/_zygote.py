"""Entry point of a :class:`ials_zoo.processes.Zygote`: ``python -m ials_zoo._zygote FD SETUP``.

``FD`` is the Unix socket to take fork requests from, ``SETUP`` the JSON ``[sys.path, preload]``.
"""

import sys

from ials_zoo.zygote import zygote_main

if __name__ == "__main__":
    zygote_main(int(sys.argv[1]), sys.argv[2])
