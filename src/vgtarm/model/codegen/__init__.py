"""Code generation: the named CasADi functions the compiled library exports.

Each family (``model``, ``ik``, ``control``) is a module that imports only :mod:`.core` and the
symbolic definition and exports a ``BUILDERS`` table; :func:`all_builders` merges the tables and
refuses a name defined twice.
"""

from __future__ import annotations

from types import ModuleType

from . import control, ik, model
from .core import Builder

#: The families of compiled functions, in the order they are generated.
FAMILIES: tuple[ModuleType, ...] = (model, ik, control)


def all_builders() -> dict[str, Builder]:
    """Every function the compiled library exports, by name."""
    builders: dict[str, Builder] = {}
    for family in FAMILIES:
        table: dict[str, Builder] = family.BUILDERS
        clash = set(builders) & set(table)
        if clash:
            raise RuntimeError(f"duplicate compiled function names in {family.__name__}: {sorted(clash)}")
        builders.update(table)
    return builders
