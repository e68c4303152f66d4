"""Domain-agnostic pieces: the region and local-simulator interfaces, the domain registry."""

from ials_zoo.core.domains import Domain, domain_ids, get_domain
from ials_zoo.core.local import LocalSimulator
from ials_zoo.core.region import DSET_KINDS, INFLUENCE_KEY, RegionSpec, dset_key

__all__ = [
    "DSET_KINDS",
    "INFLUENCE_KEY",
    "Domain",
    "LocalSimulator",
    "RegionSpec",
    "domain_ids",
    "dset_key",
    "get_domain",
]
