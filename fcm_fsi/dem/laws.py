"""The contact laws of the DEM, registered in one place.

A contact law is carried by two interactions (hook contract in ``fcm_fsi/dem/__init__.py``):
one between the spheres of different blocks, ``spheres(materials, skin, clip_normal)``, and
one between the spheres and the static walls, ``walls(walls, materials, ns, clip_normal)``
(None when the case has no walls). :func:`fcm_fsi.dem.model.build_system` builds a case's
contact from :data:`LAWS` only.

``fused`` states whether the fused step (``fused.py``: the pair kernel, then one pass over the
blocks) implements the law. It has no default: a new law says so when it is registered, and a
law registered with ``fused=False`` always runs stage by stage (``DEMSystem.step``). A law
registered as fused must pass the bit-for-bit comparison of the two steps
(``tests/dem/test_dem_fused.py`` runs it for every fused law).
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from .contact import SphereContact
from .wall_contact import WallContact
from .walls import wall_contact


@dataclass(frozen=True, kw_only=True)
class ContactLaw:
    """One contact law: the classes of its two interactions, how to build them, and whether
    the fused step implements it."""

    name: str
    sphere_type: type
    wall_type: type
    spheres: Callable
    walls: Callable
    fused: bool

    def __post_init__(self) -> None:
        if not isinstance(self.fused, bool):
            raise TypeError(f"contact law {self.name!r}: fused must be True or False, got {self.fused!r}")


#: name → law; :func:`register` adds to it
LAWS: dict[str, ContactLaw] = {}

#: the law of every case (paper eqs 18–20)
DEFAULT_LAW = "spring_dashpot"


def register(law: ContactLaw) -> ContactLaw:
    """Add ``law`` to :data:`LAWS`; a name registered twice is an error."""
    if law.name in LAWS:
        raise ValueError(f"contact law {law.name!r} is already registered")
    LAWS[law.name] = law
    return law


register(ContactLaw(name="spring_dashpot", sphere_type=SphereContact, wall_type=WallContact,
                    spheres=SphereContact, walls=wall_contact, fused=True))


def fused_parts(interactions: list) -> tuple | None:
    """(sphere interaction, wall interaction or None) when ``interactions`` are exactly the
    sphere interaction, optionally followed by the wall interaction, of one law registered
    with ``fused=True``; None otherwise (the step then runs stage by stage)."""
    if not 1 <= len(interactions) <= 2:
        return None
    for law in LAWS.values():
        if not law.fused or type(interactions[0]) is not law.sphere_type:
            continue
        if len(interactions) == 1:
            return interactions[0], None
        if type(interactions[1]) is law.wall_type:
            return interactions[0], interactions[1]
    return None
