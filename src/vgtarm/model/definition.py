"""Which symbolic model the generated functions are built from: the paper's robot or a stack.

The code generation (:mod:`vgtarm.model.codegen`) builds every compiled function from a
*definition*: the number of joints and parameters, the kinematics (tip, end-effector orientation,
the bodies' centres of mass and frames, and the forward-kinematics outputs) and the dynamics. Two
definitions exist:

- :data:`PAPER`: the fixed 7-joint model of :mod:`vgtarm.model.symbolic` (the reference robot);
  the functions it gives are, expression for expression, the ones generated before stacks existed.
- :class:`StackDefinition`: any stack of modules (:mod:`vgtarm.model.stack.symbolic`). Only its
  *structure* (the plane angles, which twist joints and twist bodies exist) shapes the expressions;
  lengths, masses and the rest are the runtime parameter vector, so one compiled library serves
  every stack of the same structure. Two definitions are equal when their structures are.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from .parameters import BODY_NAMES, N_JOINTS, N_PARAMETERS
from .symbolic import SX, dynamics, kinematics, row_major

if TYPE_CHECKING:
    from .stack.description import Stack


@dataclass(frozen=True)
class SymbolicKinematics:
    """What the generated functions need of the kinematics, as expressions of ``q`` and ``p``."""

    tip: SX  # (3, 1) tip point in F0
    C03: SX  # (3, 3) end-effector orientation
    body_com: tuple[SX, ...]  # centres of mass of the bodies in F0, in the model's body order
    body_rotation: tuple[SX, ...]  # orientations of the body frames
    fk_outputs: tuple[SX, ...]  # the outputs of the function "fk", in order
    fk_names: tuple[str, ...]


@dataclass(frozen=True)
class SymbolicDynamics:
    """Terms of ``M qdd + C = F + J_P^T f`` (paper eq. 15) and the energies."""

    M: SX
    C: SX
    J_P: SX
    kinetic_energy: SX
    potential_energy: SX


@dataclass(frozen=True)
class PaperDefinition:
    """The paper's 7-joint robot (:func:`vgtarm.model.symbolic.kinematics` and ``dynamics``)."""

    n_joints: int = N_JOINTS
    n_parameters: int = N_PARAMETERS
    body_names: tuple[str, ...] = BODY_NAMES
    #: Identifies the structure in the compile cache's key; the paper's model adds nothing to it.
    key: str = ""

    def kinematics(self, q: SX, p: SX) -> SymbolicKinematics:
        k = kinematics(q, p)
        outputs = (k.passive, k.O1, row_major(k.C01), k.O2, row_major(k.C02), k.tip, row_major(k.C03))
        names = ("passive", "O1", "C01", "O2", "C02", "tip", "C03")
        return SymbolicKinematics(k.tip, k.C03, k.body_com, k.body_rotation, outputs, names)

    def dynamics(self, q: SX, qd: SX, p: SX) -> SymbolicDynamics:
        d = dynamics(q, qd, p)
        return SymbolicDynamics(d.M, d.C, d.J_P, d.kinetic_energy, d.potential_energy)


#: The definition of the paper's robot.
PAPER = PaperDefinition()

#: One module's structure: plane angle (degrees), whether a twist follows, whether it has a body.
ModuleStructure = tuple[float, bool, bool]


@dataclass(frozen=True)
class StackDefinition:
    """A stack's structure, with one stack of that structure to build the expressions from.

    Build with :meth:`of`. Equality and hashing use the structure only.
    """

    structure: tuple[ModuleStructure, ...]
    stack: Stack = field(compare=False, hash=False, repr=False)

    @classmethod
    def of(cls, stack: Stack) -> StackDefinition:
        structure = tuple(
            (
                float(module.plane),
                module.twist is not None,
                module.twist is not None and module.twist.body is not None,
            )
            for module in stack.modules
        )
        return cls(structure, stack)

    @property
    def n_joints(self) -> int:
        return self.stack.n_joints

    @property
    def n_parameters(self) -> int:
        return self.stack.n_parameters

    @property
    def body_names(self) -> tuple[str, ...]:
        return self.stack.body_names

    @property
    def key(self) -> str:
        """The structure as text, e.g. ``stack:0.0,-,-;90.0,T,-`` (T: a twist, B: its body)."""
        parts = [f"{plane!r},{'T' if twist else '-'},{'B' if body else '-'}" for plane, twist, body in self.structure]
        return "stack:" + ";".join(parts)

    def kinematics(self, q: SX, p: SX) -> SymbolicKinematics:
        import casadi as ca

        from .stack.symbolic import stack_kinematics

        k = stack_kinematics(self.stack, q, p)
        outputs = (
            k.passive,
            ca.vertcat(*k.platform_origins),
            ca.vertcat(*[row_major(r) for r in k.platform_rotations]),
            k.tip,
            row_major(k.end_effector_rotation),
        )
        names = ("passive", "O", "C", "tip", "C03")
        return SymbolicKinematics(k.tip, k.end_effector_rotation, k.body_com, k.body_rotation, outputs, names)

    def dynamics(self, q: SX, qd: SX, p: SX) -> SymbolicDynamics:
        from .stack.symbolic import stack_dynamics

        d = stack_dynamics(self.stack, q, qd, p)
        return SymbolicDynamics(d.M, d.C, d.J_P, d.kinetic_energy, d.potential_energy)


Definition = PaperDefinition | StackDefinition
