"""The names and sizes of every generated function of a model, without its symbolic model.

A cached library is trusted only if it is the library of the model being loaded (the compile
cache's rules in :mod:`.compiled`): its metadata must name this model's structure and give every
function the names and sizes that the code generation gives this model. Building the real
functions to learn those sizes is the costly symbolic construction a cache exists to avoid (3.8 s
for six modules, hours for fifty), so they are computed here from an *outline* of the definition:
the same numbers of joints, parameters and bodies and the same forward-kinematics outputs, with
cheap stand-in expressions (the tip is three of the joints, the orientation the identity, the mass
matrix diagonal). The code generation (:mod:`.codegen`, the one source of the functions) then
builds every function from the outline in milliseconds, and a function's inputs and outputs, their
names and the sizes of its argument and result arrays depend only on those shapes (every output is
densified); only the work sizes depend on the expressions, and the library's own report of those
is checked against the metadata when it is opened. ``tests/test_cache.py`` compares the outline's
sizes with the real functions' for the paper's robot and for stacks.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import casadi as ca

from . import codegen
from .definition import Definition, SymbolicDynamics, SymbolicKinematics
from .symbolic import SX


@dataclass(frozen=True)
class Shape:
    """What identifies one generated function of a model: its C name, the sizes of its inputs and
    outputs, their names and the lengths of its argument and result arrays."""

    name: str
    nnz_in: tuple[int, ...]
    nnz_out: tuple[int, ...]
    in_names: tuple[str, ...]
    out_names: tuple[str, ...]
    sz_arg: int
    sz_res: int


@dataclass(frozen=True)
class _Outline:
    """A definition with the shapes of another and cheap expressions (module docstring)."""

    n_joints: int
    n_parameters: int
    body_names: tuple[str, ...]
    fk_shapes: tuple[tuple[int, int], ...]
    fk_names: tuple[str, ...]
    n_bodies: int
    key: str = "outline"

    def _tip(self, q: SX) -> SX:
        return ca.vertcat(*[q[i % self.n_joints] for i in range(3)])

    def kinematics(self, q: SX, p: SX) -> SymbolicKinematics:
        tip, eye = self._tip(q), SX.eye(3)
        outputs = tuple(SX.ones(rows, cols) * q[0] for rows, cols in self.fk_shapes)
        return SymbolicKinematics(tip, eye, (tip,) * self.n_bodies, (eye,) * self.n_bodies, outputs, self.fk_names)

    def dynamics(self, q: SX, qd: SX, p: SX) -> SymbolicDynamics:
        tip = self._tip(q)
        return SymbolicDynamics(ca.diag(1 + q * q), qd, ca.jacobian(tip, q), ca.sumsqr(qd), ca.sum1(q))


def _outline(definition: Definition) -> _Outline:
    """The outline of ``definition``; its kinematics are built once for their shapes (the forward
    kinematics alone: 0.07 s for fifty modules)."""
    q, p = SX.sym("q", definition.n_joints), SX.sym("p", definition.n_parameters)
    kinematics = definition.kinematics(q, p)
    return _Outline(
        n_joints=definition.n_joints,
        n_parameters=definition.n_parameters,
        body_names=tuple(definition.body_names),
        fk_shapes=tuple((int(o.size1()), int(o.size2())) for o in kinematics.fk_outputs),
        fk_names=tuple(kinematics.fk_names),
        n_bodies=len(kinematics.body_com),
    )


@functools.lru_cache(maxsize=8)
def shapes(definition: Definition) -> dict[str, Shape]:
    """The :class:`Shape` of every function the library of ``definition`` exports, by key."""
    outline = _outline(definition)
    found: dict[str, Shape] = {}
    for key, builder in codegen.all_builders().items():
        f = builder(outline)
        found[key] = Shape(
            name=f.name(),
            nnz_in=tuple(int(f.nnz_in(i)) for i in range(f.n_in())),
            nnz_out=tuple(int(f.nnz_out(i)) for i in range(f.n_out())),
            in_names=tuple(f.name_in()),
            out_names=tuple(f.name_out()),
            sz_arg=int(f.sz_arg()),
            sz_res=int(f.sz_res()),
        )
    return found
