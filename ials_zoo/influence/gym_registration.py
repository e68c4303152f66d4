"""Gymnasium ids of the IALS (:mod:`ials_zoo.core.gym_ids`) and :func:`register_all`."""

from __future__ import annotations

from ials_zoo.core.gym_ids import ENTRY_POINT, gym_id, register_ials


def register_all() -> list[str]:
    """Register the IALS of every available domain."""
    from ials_zoo.core.domains import domain_ids

    return [register_ials(env_id) for env_id in domain_ids()]


__all__ = ["ENTRY_POINT", "gym_id", "register_all", "register_ials"]
