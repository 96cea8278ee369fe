"""Shared helpers of code generation: every function family imports only this module.

Every function takes and returns dense column vectors; matrices are flattened row by row
(``vec(A.T)``), so a batch output of shape ``(n, r*c)`` reshapes to ``(n, r, c)`` directly.
The parameter vector ``p`` is always the last input.
"""

from __future__ import annotations

from collections.abc import Callable

import casadi as ca

from ..definition import PAPER, Definition
from ..symbolic import SX
from ..symbolic import row_major as row_major  # the families take it from here

#: A builder of one function; its argument (default: the paper's robot) is the model definition.
Builder = Callable[..., ca.Function]


def function(name: str, inputs: list[SX], outputs: list[SX], in_names: list[str], out_names: list[str]) -> ca.Function:
    """A CasADi function whose outputs are dense (structural zeros stored), as the drivers expect."""
    return ca.Function(name, inputs, [ca.densify(o) for o in outputs], in_names, out_names)


def symbols(definition: Definition = PAPER) -> tuple[SX, SX, SX]:
    """Joint positions, joint velocities and the parameter vector, sized from the model."""
    n = definition.n_joints
    return SX.sym("q", n), SX.sym("qd", n), SX.sym("p", definition.n_parameters)
