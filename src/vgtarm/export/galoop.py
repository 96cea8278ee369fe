"""The exported GA of switching control, compiled and called from Python (issue 25).

:class:`ExportedGA` compiles an export written with ``switching`` (:func:`~.controller.
export_controller`) with ``harness/ga_harness.c`` into a shared library and runs activations of
its ``vgtc_ga_activate``, timed in C, so that tests hold them to the simulation's compiled GA
(:class:`vgtarm.model.closedloop.CompiledGA`) and benchmarks measure them.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from cffi import FFI
from numpy.typing import NDArray

from ..errors import InputError, shown
from ..model.compiled import find_compiler
from .controller import ExportError, run_compiler
from .loop import PROGRAMS, export_settings

HARNESS = Path(__file__).resolve().parent / "harness" / "ga_harness.c"
#: The library's flags: those of the export's Makefile (no contraction: the GA writes its fused
#: multiply-adds out as fmaf).
FLAGS = ("-std=c99", "-O2", "-fPIC", "-shared", "-ffp-contract=off")

_CDEF = """
typedef struct vgtc_ga_opaque vgtc_ga;
typedef struct vgtc_ga_params_opaque vgtc_ga_params;
void vgtc_ga_default_params(vgtc_ga_params *params);
int vgtc_ga_init(vgtc_ga *ga, const vgtc_ga_params *params);
size_t vgtc_ga_size(void);
size_t vgtc_ga_params_size(void);
int vgtc_ga_harness_run(vgtc_ga *ga, long n, const long *start, const long *horizon, const double *q0,
                        const double *qd0, const double *ref, const double *tip_d, const uint64_t *seeds,
                        double *gains, double *costs, long *counts, double *seconds);
"""


@dataclass(frozen=True)
class Activations:
    """Activations of the exported GA, one row each."""

    genes: NDArray[np.float64]  #: (n, 2 nj^2) the gains returned: Kp then Kv, row by row
    best_cost: NDArray[np.float64]  #: (n,) their predicted tip error (m)
    seeded_cost: NDArray[np.float64]  #: (n,) the fixed gains' predicted tip error (m)
    generations: NDArray[np.int64]
    evaluations: NDArray[np.int64]
    exact_steps: NDArray[np.int64]
    dropped: NDArray[np.bool_]
    seconds: NDArray[np.float64]  #: (n,) wall time of each activation (s), measured in C


class ExportedGA:
    """An export's GA compiled into a shared library (its model functions, defaults and GA)."""

    def __init__(self, folder: str | os.PathLike[str], *, compiler: str | None = None, flags: tuple[str, ...] = FLAGS):
        self.folder = Path(folder).absolute()
        self.settings: dict[str, Any] = export_settings(folder)
        if not self.settings.get("switching"):
            raise InputError(
                f"exported controller {shown(str(folder), 200)}: exported without switching control"
                " (export it with switching='safe' or 'paper')"
            )
        self.n_joints = int(self.settings["n_joints"])
        self.n_genes = 2 * self.n_joints**2
        chosen = compiler or find_compiler()
        if chosen is None:
            raise ExportError("no C compiler found (cc, gcc or clang, or $CC) to compile the exported GA")
        sources = [str(p) for p in sorted(self.folder.glob("*.c")) if p.name not in PROGRAMS]
        scratch = tempfile.mkdtemp(prefix="vgtc-ga-")
        try:
            library = Path(scratch) / "libvgtc_ga.so"
            command = [chosen, *flags, "-I", str(self.folder), "-o", str(library), *sources, str(HARNESS), "-lm"]
            run_compiler(command, "the exported GA with its timing harness")
            self.ffi = FFI()
            self.ffi.cdef(_CDEF)
            self.lib: Any = self.ffi.dlopen(str(library))
        finally:
            shutil.rmtree(scratch, ignore_errors=True)
        params = self.ffi.new("char[]", int(self.lib.vgtc_ga_params_size()))
        self.lib.vgtc_ga_default_params(self.ffi.cast("vgtc_ga_params *", params))
        self._memory = self.ffi.new("char[]", int(self.lib.vgtc_ga_size()))
        self._ga = self.ffi.cast("vgtc_ga *", self._memory)
        status = int(self.lib.vgtc_ga_init(self._ga, self.ffi.cast("vgtc_ga_params *", params)))
        if status != 0:
            raise ExportError(f"vgtc_ga_init of {shown(str(self.folder), 200)} returned {status}")

    def run(
        self,
        starts: Any,
        horizons: Any,
        q0: Any,
        qd0: Any,
        ref: Any,
        tip_d: Any | None,
        seeds: Any,
    ) -> Activations:
        """Activations ``i``: from the state ``q0[i], qd0[i]`` over the window of ``horizons[i] + 1``
        rows from row ``starts[i]`` of ``ref`` (rows of q_d, qd_d, qdd_d) and ``tip_d`` (None: the
        model's tip at q_d), with seed ``seeds[i]``."""
        n = len(starts)
        starts_a = np.ascontiguousarray(starts, dtype=np.int64)
        horizons_a = np.ascontiguousarray(horizons, dtype=np.int64)
        q0_a = np.ascontiguousarray(q0, dtype=np.float64).reshape(n, self.n_joints)
        qd0_a = np.ascontiguousarray(qd0, dtype=np.float64).reshape(n, self.n_joints)
        ref_a = np.ascontiguousarray(ref, dtype=np.float64)
        if ref_a.ndim != 2 or ref_a.shape[1] != 3 * self.n_joints:
            raise InputError(f"ref: shape {ref_a.shape}, expected (rows, {3 * self.n_joints})")
        if n and int(np.max(starts_a + horizons_a)) >= len(ref_a):
            raise InputError("starts + horizons: a window runs past the reference's last row")
        tip_a = None if tip_d is None else np.ascontiguousarray(tip_d, dtype=np.float64)
        seeds_a = np.ascontiguousarray(np.asarray(seeds, dtype=np.uint64))
        genes = np.zeros((n, self.n_genes))
        costs = np.zeros((n, 2))
        counts = np.zeros((n, 4), dtype=np.int64)
        seconds = np.zeros(n)
        ffi = self.ffi

        def d(a: NDArray[Any]) -> Any:
            return ffi.cast("double *", a.ctypes.data)

        def lp(a: NDArray[Any]) -> Any:
            return ffi.cast("long *", a.ctypes.data)

        status = int(
            self.lib.vgtc_ga_harness_run(
                self._ga,
                n,
                lp(starts_a),
                lp(horizons_a),
                d(q0_a),
                d(qd0_a),
                d(ref_a),
                ffi.NULL if tip_a is None else d(tip_a),
                ffi.cast("uint64_t *", seeds_a.ctypes.data),
                d(genes),
                d(costs),
                lp(counts),
                d(seconds),
            )
        )
        if status != 0:
            raise ExportError(f"vgtc_ga_activate returned {status}")
        return Activations(
            genes, costs[:, 0], costs[:, 1], counts[:, 0], counts[:, 1], counts[:, 2], counts[:, 3] != 0, seconds
        )
