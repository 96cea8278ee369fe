"""The inverse-kinematics solvers by name.

A solver is a function ``solve(problem, task, state, q_start, options) -> None`` that fills every
row of ``state`` (:class:`~vgtarm.ik.state.BatchState`): for each sample it sets ``q``, and,
where it succeeded, ``converged = True``, the multipliers ``lam`` and ``mu``, the active set and
the model values (``residual``, ``J``, ``H``) at ``q``; it also records ``iterations`` and
``method``. It never raises for a sample it could not solve: it leaves it unconverged, and the
caller re-solves it with the reference solver or reports it unreachable. It may fill the exact
rates of samples (``rates_ready``); the caller computes the others.
"""

from __future__ import annotations

from collections.abc import Callable
from types import MappingProxyType

import numpy as np
from numpy.typing import NDArray

from ..errors import InputError
from . import fast, ipopt, slsqp
from .options import IKOptions
from .problem import IKProblem
from .state import BatchState
from .tasks import Task

Solver = Callable[[IKProblem, Task, BatchState, NDArray[np.float64], IKOptions], None]


def _fast(problem: IKProblem, task: Task, state: BatchState, q_start: NDArray[np.float64], options: IKOptions) -> None:
    fast.solve(problem, task, state, q_start, options.fast)


#: Solvers by name.
SOLVERS: MappingProxyType[str, Solver] = MappingProxyType({"fast": _fast, "slsqp": slsqp.solve, "ipopt": ipopt.solve})
#: Other names of solvers.
ALIASES: MappingProxyType[str, str] = MappingProxyType({"reference": "slsqp"})


def solver_names() -> list[str]:
    """Every accepted name, sorted."""
    return sorted([*SOLVERS, *ALIASES])


def get_solver(name: object) -> tuple[str, Solver]:
    """The canonical name and the solver of ``name``.

    An unknown name raises :class:`InputError` listing the valid ones.
    """
    key = ALIASES.get(name, name) if isinstance(name, str) else None
    if key is None or key not in SOLVERS:
        raise InputError(f"unknown inverse-kinematics solver {name!r}; valid solvers are {', '.join(solver_names())}")
    return key, SOLVERS[key]
