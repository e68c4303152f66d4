"""Subcommands of ``ials-zoo``; each module defines ``configure(parser)`` and ``run(args)``."""
