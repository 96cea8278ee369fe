"""Code generation: the named CasADi functions the compiled library exports.

Each family (``model``, ``ik``, ``control``) is a module that imports only :mod:`.core` and the
symbolic definition and exports a ``BUILDERS`` table; :func:`all_builders` merges the tables and
refuses a name defined twice. Every builder takes the model definition
(:mod:`vgtarm.model.definition`, default the paper's robot); :func:`builders_for` binds it, so a
stack of modules gets the same functions for its own joints.

A stack's functions are built with CasADi's common-subexpression elimination (option ``cse``):
an expression that the symbolic model builds twice (the bodies' Jacobians inside ``M``, ``C`` and
their products, for instance) is then evaluated once. It merges only nodes applying the same
operation to the same operands, so every output keeps its value bit for bit, while the generated
C of a stack shrinks by about 30 % and compiles about 30 % sooner. The paper's robot is built as
before, so its generated C stays byte for byte what it was.
"""

from __future__ import annotations

import functools
from types import ModuleType

import casadi as ca

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
    return {key: functools.partial(_without_repeats, builder, definition) for key, builder in builders.items()}


def _without_repeats(builder: Builder, definition: Definition) -> ca.Function:
    """The function of ``builder`` for ``definition`` with its common subexpressions evaluated once
    (module docstring): the same inputs, outputs and names."""
    f = builder(definition)
    inputs = f.sx_in()
    return ca.Function(f.name(), inputs, f.call(inputs), f.name_in(), f.name_out(), {"cse": True})
