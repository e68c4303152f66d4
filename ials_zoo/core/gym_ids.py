"""Gymnasium ids of the IALS: ``gymnasium.make("ials_zoo/IALS-<env_id>", agent=..., ...)``.

Every domain's IALS is registered when ``ials_zoo`` is imported (and when a domain is added
with :func:`ials_zoo.register_domain`). Gymnasium 1.x has no plugin entry points any more, so
from a bare ``import gymnasium`` use the module-prefixed id, which imports the zoo first:
``gymnasium.make("ials_zoo:ials_zoo/IALS-warehouse_v0", agent="robot_20")``.

The entry point is a string: registering an id imports nothing of the IALS itself, which is
why this lives beside the domain registry.
"""

from __future__ import annotations

import gymnasium

ENTRY_POINT = "ials_zoo.influence.ials:gymnasium_entry_point"


def gym_id(env_id: str) -> str:
    """The Gymnasium id of the IALS of domain ``env_id``."""
    return f"ials_zoo/IALS-{env_id}"


def register_ials(env_id: str) -> str:
    """Register ``ials_zoo/IALS-<env_id>`` (once); returns the id."""
    name = gym_id(env_id)
    if name not in gymnasium.registry:
        gymnasium.register(id=name, entry_point=ENTRY_POINT, kwargs={"env_id": env_id})
    return name


__all__ = ["ENTRY_POINT", "gym_id", "register_ials"]
