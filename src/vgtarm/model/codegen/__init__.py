"""Code generation: the named CasADi functions the compiled library exports.

Each family (``model``, ``ik``, ``control``) is a module that imports only :mod:`.core` and the
symbolic definition and exports a ``BUILDERS`` table; :func:`all_builders` merges the tables and
refuses a name defined twice. Every builder takes the model definition
(:mod:`vgtarm.model.definition`, default the paper's robot); :func:`builders_for` binds it, so a
stack of modules gets the same functions for its own joints.
"""

from __future__ import annotations

import functools
from types import ModuleType

from ..definition import PAPER, Definition
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


def builders_for(definition: Definition = PAPER) -> dict[str, Builder]:
    """Every function the compiled library of ``definition`` exports, by name (same names for
    every definition; the paper's robot: :func:`all_builders` itself)."""
    builders = all_builders()
    if definition == PAPER:
        return builders
    return {key: functools.partial(builder, definition) for key, builder in builders.items()}
