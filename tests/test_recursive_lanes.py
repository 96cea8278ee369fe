"""The recursive model's batches in vector lanes (``csrc/vgt_rec_lanes.h``) against its one-sample code.

Forward and inverse dynamics and the mass matrix run their batches in blocks of samples side by
side, one per lane of a vector, every operation that of the one-sample code in the same order:
each sample's results must be those of the one-sample code, bit for bit (the contract is 1e-12
relative), on every instruction set this CPU and library have, for batches of any length (the last
ones one by one), with and without a tip wrench, on one thread or several. The one-sample code is
the same library with the lanes off (``vgt_rec_lanes(0)``) and single-sample calls.
"""

from __future__ import annotations

import platform
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest

from vgtarm.model.recursive import RecursiveModel, library
from vgtarm.model.stack import Stack

from .test_recursive import long_stack, relative, states, varied_stack

#: The instruction sets of the lanes: the baseline (not on x86-64), x86-64-v3 (AVX2), x86-64-v4 (AVX-512).
LEVELS = (1, 2, 3)
#: Batch lengths around the block (8 lanes): shorter, one block, blocks and a rest.
COUNTS = (1, 7, 8, 9, 16, 21)


@contextmanager
def lanes(model: RecursiveModel, level: int) -> Iterator[int]:
    """The lanes of instruction set ``level`` (0: none) for the block, then the CPU's best again."""
    width = model._lib.vgt_rec_lanes(level)
    try:
        yield width
    finally:
        assert model._lib.vgt_rec_lanes(-1) in (0, 8)


def both(model: RecursiveModel, s: dict[str, np.ndarray], count: int, wrench: bool) -> tuple[np.ndarray, ...]:
    """Forward and inverse dynamics and the mass matrices of the first ``count`` samples of ``s``."""
    f, m = (s["f"][:count], s["m"][:count]) if wrench else (None, None)
    q, qd = s["q"][:count], s["qd"][:count]
    return (
        model.forward_dynamics(q, qd, s["F"][:count], f, m),
        model.inverse_dynamics(q, qd, s["qdd"][:count], f, m),
        model.mass_matrix(q),
    )


STACKS = {"varied1": lambda: varied_stack(1), "varied2": lambda: varied_stack(2), "varied5": lambda: varied_stack(5)}
STACKS |= {"long10": lambda: long_stack(10), "long50": lambda: long_stack(50)}


@pytest.mark.parametrize("name", sorted(STACKS))
def test_the_lanes_give_the_one_sample_codes_numbers(name):
    stack: Stack = STACKS[name]()
    model = RecursiveModel(stack)
    s = states(stack, max(COUNTS), seed=len(name))
    for wrench in (False, True):
        with lanes(model, 0) as width:
            assert width == 0
            alone = [both(model, {k: v[i : i + 1] for k, v in s.items()}, 1, wrench) for i in range(max(COUNTS))]
            one = [np.concatenate(parts) for parts in zip(*alone, strict=True)]
            off = both(model, s, max(COUNTS), wrench)
        assert all(np.array_equal(a, b) for a, b in zip(off, one, strict=True))
        for level in LEVELS:
            with lanes(model, level) as width:
                if width < 0:  # not on this CPU, or not in this library
                    continue
                for count in COUNTS:
                    for got, expected in zip(both(model, s, count, wrench), one, strict=True):
                        assert relative(got, expected[:count]) <= 1e-12
                        assert np.array_equal(got, expected[:count]), (level, count)


def test_the_lanes_on_several_threads_and_a_long_batch():
    stack = long_stack(10)
    model, threaded = RecursiveModel(stack), RecursiveModel(stack, threads=2)
    s = states(stack, 203, seed=3)
    with lanes(model, 0):
        off = both(model, s, 203, True)
    for m in (model, threaded):
        assert all(np.array_equal(a, b) for a, b in zip(both(m, s, 203, True), off, strict=True))


def test_the_lanes_keep_each_samples_numbers_apart():
    """A sample far from the others in its block (huge velocities, a tip wrench on one lane) leaves
    the others' results as they are alone."""
    stack = varied_stack(3)
    model = RecursiveModel(stack)
    s = states(stack, 8, seed=5)
    s["qd"][3] *= 1e6
    s["f"][:] = 0.0
    s["f"][5] = (1e8, -1e8, 3e7)
    with lanes(model, 0):
        alone = [both(model, {k: v[i : i + 1] for k, v in s.items()}, 1, True) for i in range(8)]
    block = both(model, s, 8, True)
    for i, sample in enumerate(alone):
        assert all(np.array_equal(a[i], b[0]) for a, b in zip(block, sample, strict=True)), i


def test_the_lane_levels_this_cpu_and_library_have():
    """Eight lanes where AVX2 is (x86-64-v3 and v4 builds); none below it (the baseline's vectors are
    left out on x86-64); a level the CPU lacks is refused and changes nothing."""
    model = RecursiveModel(varied_stack(1))
    flags = Path("/proc/cpuinfo").read_text() if Path("/proc/cpuinfo").is_file() else ""
    x86 = platform.machine() in ("x86_64", "AMD64")
    widths = {level: model._lib.vgt_rec_lanes(level) for level in LEVELS}
    assert model._lib.vgt_rec_lanes(-1) in (0, 8)
    if x86:
        assert widths[1] == -1
        assert widths[2] == (8 if " avx2 " in flags.replace("\n", " ") else -1) or not flags
    else:
        assert widths[1] == 8 and widths[2] == widths[3] == -1
    best = model._lib.vgt_rec_lanes(-1)
    assert best == (8 if any(w == 8 for w in widths.values()) else 0)


def test_the_module_functions_on_vectors_are_the_generated_ones():
    """``module_lanes`` turns the generated module functions into ``lane_module`` and
    ``lane_module_kin`` statement by statement, and gives nothing (the joints one sample at a time)
    for code it does not know."""
    source = """
int vgt_rec_module_kin(const casadi_real** arg, casadi_real** res, casadi_int* iw, casadi_real* w, int mem){
  return casadi_f0(arg, res, iw, w, mem);
}
int vgt_rec_module(const casadi_real** arg, casadi_real** res, casadi_int* iw, casadi_real* w, int mem){
  return casadi_f1(arg, res, iw, w, mem);
}
static int casadi_f0(const casadi_real** arg, casadi_real** res, casadi_int* iw, casadi_real* w, int mem) {
  casadi_real a0;
  a0=arg[1]? arg[1][3] : 0;
  a0=casadi_sq(a0);
  if (res[2]!=0) res[2][1]=a0;
  return 0;
}
static int casadi_f1(const casadi_real** arg, casadi_real** res, casadi_int* iw, casadi_real* w, int mem) {
  casadi_real a0, a1;
  a0=arg[0]? arg[0][2] : 0;
  a1=-2.5e-01;
  a1=(a1*sin(a0));
  if (res[0]!=0) res[0][0]=a1;
  return 0;
}
"""
    text = library.module_lanes(source)
    kin = text.index("LANE_INLINE void lane_module_kin(const vd *const *arg, vd *const *res) {")
    full = text.index("LANE_INLINE void lane_module(const vd *const *arg, vd *const *res) {")
    assert "#define VGT_REC_MODULE_LANES 1" in text and full < kin
    for line in ("vd a0, a1;", "a0=arg[0][2];", "a1=LANE_SPLAT(-2.5e-01);", "a1=(a1*lane_sin(a0));"):
        assert f"\n    {line}\n" in text[full:kin]
    for line in ("vd a0;", "a0=arg[1][3];", "a0=lane_sq(a0);", "if (res[2]!=0) res[2][1]=a0;"):
        assert f"\n    {line}\n" in text[kin:]
    assert "if (res[0]!=0) res[0][0]=a1;" in text and "return" not in text
    assert library.module_lanes(source.replace("sin(a0)", "tanh(a0)")) == ""
    assert library.module_lanes(source.replace("a1=(a1*", "w[0]=(a1*")) == ""
    assert library.module_lanes(source.replace("a1=-2.5e-01;", "a1=(a0<a1 ? a0 : a1);")) == ""
    assert library.module_lanes(source.replace("a1=-2.5e-01;", "a1=casadi_inf;")) == ""
    assert library.module_lanes(source.replace("a1=-2.5e-01;", "a1=2.5E-01;")) == ""
    assert library.module_lanes(source.replace("a0=casadi_sq(a0);", "a0=fabs(a0);")) == ""
    assert library.module_lanes(source.split("static int casadi_f0")[0]) == ""
