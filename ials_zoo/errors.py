"""The error for bad input, and only for it.

Everything the zoo checks before work starts (arguments, options, seeds, files' contents,
result files) raises :class:`BadInput` (or :class:`BadInputType` for a value of the wrong
type) with a message that names the problem. ``ials-zoo`` prints those as ``ials-zoo
<command>: <message>`` with exit status 2 and no traceback; any other exception, a
``ValueError`` from numpy or torch included, is a bug and shows its traceback. Both are
``ValueError`` / ``TypeError`` subclasses, so ``except ValueError`` keeps catching them.
"""


class BadInput(ValueError):
    """Bad input, named by the message."""


class BadInputType(BadInput, TypeError):
    """Bad input of the wrong type, named by the message."""


# Run-time failures that name themselves (a SUMO simulation's error, a worker that died or
# stopped): printed in one line with exit status 1. By name: importing the SUMO lease here
# would import libsumo.
RUN_FAILURES = ("SimulationError", "SimulationBusyError", "WorkerDiedError", "WorkerUnresponsiveError",
                "WorkerError")


def is_run_failure(exc: BaseException) -> bool:
    """Whether ``exc`` is one of :data:`RUN_FAILURES` (or a subclass of one)."""
    return any(c.__name__ in RUN_FAILURES for c in type(exc).__mro__)


__all__ = ["RUN_FAILURES", "BadInput", "BadInputType", "is_run_failure"]
