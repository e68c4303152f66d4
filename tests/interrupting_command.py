"""A subcommand for a test of Ctrl-C at start-up: importing it sends this process SIGINT, then
goes on importing (as torch's imports go on in compiled code, where an exception would abort)."""

import os
import signal
import time

os.kill(os.getpid(), signal.SIGINT)
time.sleep(0.2)  # the signal is handled here, in the middle of the import
IMPORTED = True


def configure(parser):
    pass


def run(args):
    raise AssertionError("a command interrupted while starting must not run")
