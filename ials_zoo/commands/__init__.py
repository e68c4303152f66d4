"""Subcommands of ``ials-zoo``; each module defines ``configure(parser)`` and ``run(args)``.

Every command reports bad input the same way: ``ials-zoo <command>: <what is wrong>`` on
stderr, exit status 2, no traceback (``IALS_ZOO_DEBUG=1`` shows the traceback), checked
before any long work starts. A command raises :class:`CommandError` for that.
"""


from ials_zoo.errors import BadInput


class CommandError(BadInput):
    """Bad input to a command: printed as ``ials-zoo <command>: <message>``, exit status 2."""
