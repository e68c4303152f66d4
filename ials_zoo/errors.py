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


__all__ = ["BadInput", "BadInputType"]
