"""Compiled functions of the ik family (model layer; see functions.py for conventions)."""

from __future__ import annotations

from .functions import Builder

#: Functions of this family, by name.
BUILDERS: dict[str, Builder] = {}
