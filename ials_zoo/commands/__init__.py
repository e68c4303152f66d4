"""Subcommands of ``ials-zoo``; each module defines ``configure(parser)`` and ``run(args)``.

Every command reports bad input the same way: ``ials-zoo <command>: <what is wrong>`` on
stderr, exit status 2, no traceback (``IALS_ZOO_DEBUG=1`` shows the traceback), checked
before any long work starts. A command raises :class:`CommandError` for that.
"""


from ials_zoo.errors import BadInput


class CommandError(BadInput):
    """Bad input to a command: printed as ``ials-zoo <command>: <message>``, exit status 2."""


NET_HELP = "the network, for a domain whose tracks are networks (its `net` option, e.g. a RESCO map)"


def with_network(domain, options: dict, net: str | None) -> dict:
    """``options`` with ``--net`` as their ``net`` (``domain``: a :class:`~ials_zoo.core.domains.Domain`),
    refused where the domain takes no network or ``options`` name another one."""
    if net is None:
        return dict(options)
    if "net" not in domain.track_options:
        raise CommandError(f"--net: {domain.env_id} takes no network")
    if options.get("net", net) != net:
        raise CommandError(f"--net {net!r} and --options' net {options['net']!r} disagree; give one")
    return {**options, "net": net}
