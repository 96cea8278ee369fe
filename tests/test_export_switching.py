"""Switching control exported with the controller (issue 25): the real-time GA (``vgtc_ga.c``: no
heap, no threads, no intrinsics) and the period logic (``vgtc_switching.c``).

Held to the simulation's compiled GA (``model/csrc/ga.c``), an independent implementation with
eight-lane vectors, OpenMP and AVX2: the same activations (gains, costs, evaluations, exact steps)
bit for bit, and case 2 with the tool force closed through the exported switching control equals
``simulate`` in every effort sample, bit for bit, in both variants. The folder builds without a
warning on gcc and clang, runs clean under the sanitizers and imports nothing but libm; what is
not exported is refused in one line.
"""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

import vgtarm
from vgtarm.control import SwitchingControl
from vgtarm.errors import InputError
from vgtarm.experiment.cases import case_study, joint_reference
from vgtarm.export import export_controller, simulate_exported
from vgtarm.export.controller import STRICT_FLAGS
from vgtarm.export.galoop import FLAGS, ExportedGA
from vgtarm.export.switching import simulator_fuses
from vgtarm.ga import GAOptions
from vgtarm.model.closedloop import ClosedLoopDriver
from vgtarm.simulation import Scenario, simulate
from vgtarm.simulation.engines import compiled_ga
from vgtarm.simulation.simulator import loop_arrays

from .conftest import make
from .test_export_controller import ALLOWED_IMPORTS, CLANG_MISSING

CASE = case_study(2)
VARIANTS = ("paper", "safe")
#: What the GA adds to the controller's imports (libm, C99).
GA_IMPORTS = {"fmaf", "log1p", "lround"}


@pytest.fixture(scope="module")
def robot() -> vgtarm.Robot:
    return vgtarm.load_robot()


@pytest.fixture(scope="module")
def reference(robot: vgtarm.Robot):
    return joint_reference(robot, 2, duration=0.2)


@pytest.fixture(scope="module")
def exports(robot: vgtarm.Robot, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("switching")
    return {
        variant: export_controller(robot, root / variant, kp=CASE.kp, kv=CASE.kv, switching=_scm(variant)).folder
        for variant in VARIANTS
    }


def _scm(variant: str, **options: int) -> SwitchingControl:
    scm = CASE.controller("scm", variant=variant, **options)  # type: ignore[arg-type]
    assert isinstance(scm, SwitchingControl)
    return scm


#: The GA's builds: portable -O2 (the vector code generic), the Makefile's -march=native (AVX2 and
#: FMA here), and the plain C99 arrays that compilers without GCC's vector extensions build.
BUILDS = {
    "portable": FLAGS,
    "native": (*FLAGS, "-march=native"),
    "arrays": (*FLAGS, "-DVGTC_GA_NO_VECTORS"),
}


@pytest.mark.parametrize("build", BUILDS)
@pytest.mark.parametrize("variant", VARIANTS)
def test_activations_equal_the_simulations_ga(variant, build, robot, reference, exports):
    """The same windows, states and seeds: the exported GA returns the simulation's activation bit
    for bit (its gains, its costs and its work), including windows cut short at the end, built
    with its vector code (portable and native) and with plain arrays."""
    scm = _scm(variant)
    arrays = loop_arrays(robot, robot, reference, initial_state=(reference.q[0], reference.qd[0]))
    theirs = compiled_ga(scm, ClosedLoopDriver(robot.backend), robot, arrays, reference.dt)
    rng = np.random.default_rng(11)
    n = len(reference.t)
    ks = [3, 60, 120, n - 6]
    q0 = np.array([reference.q[k] + rng.normal(scale=3e-4, size=7) for k in ks])
    qd0 = np.array([reference.qd[k] + rng.normal(scale=3e-3, size=7) for k in ks])
    seeds = rng.integers(0, 2**63, size=len(ks))
    horizons = [min(scm.horizon, n - 1 - k) for k in ks]
    inp = arrays.inputs
    rows = np.hstack([inp["q_d"], inp["qd_d"], inp["qdd_d"]])
    mine = ExportedGA(exports[variant], flags=BUILDS[build]).run(ks, horizons, q0, qd0, rows, inp["tip_d"], seeds)
    exact = 0
    for i, k in enumerate(ks):
        r = theirs.activate(k, q0[i], qd0[i], int(seeds[i]))
        np.testing.assert_array_equal(mine.genes[i], r.genes)
        assert (mine.best_cost[i], mine.seeded_cost[i]) == (r.best_cost, r.seeded_cost)
        assert (mine.generations[i], mine.evaluations[i]) == (r.generations, r.evaluations)
        assert (mine.exact_steps[i], bool(mine.dropped[i])) == (r.exact_steps, r.dropped)
        exact += r.exact_steps
    assert exact > 0  # the trust region's exact steps are exercised too
    assert (mine.seconds > 0).all()


@pytest.mark.parametrize(
    ("variant", "options"),
    [("paper", {}), ("safe", {}), ("safe", {"encoder_resolution": 1e-6})],
    ids=["paper", "safe", "safe, encoders"],
)
def test_closed_through_the_exported_switching_control_equals_simulate(variant, options, robot, reference, tmp_path):
    """Case 2 with the tool force, switching control closed through the exported C: every effort
    sample, state and activation equals simulate's, bit for bit (within 1e-12 a fortiori)."""
    scm = _scm(variant)
    scenario = Scenario(external_force=CASE.external_force, **options)
    folder = export_controller(robot, tmp_path / "x", scenario=scenario, kp=CASE.kp, kv=CASE.kv, switching=scm).folder
    theirs = simulate(robot, reference, scm, scenario)
    mine = simulate_exported(folder, robot, reference, scenario, controller=scm)
    assert len(theirs.activations) >= 3  # the GA ran
    assert np.abs(mine.effort - theirs.effort).max() <= 1e-12
    np.testing.assert_array_equal(mine.effort, theirs.effort)
    np.testing.assert_array_equal(mine.q, theirs.q)
    np.testing.assert_array_equal(mine.mode, theirs.mode)
    # the safe variant's held sets dropped when their error rose (vgtarm with the drop rule)
    assert mine.metadata.get("scm_hold_drops") == theirs.metadata.get("scm_hold_drops")
    assert [(a.sample, a.evaluations, a.best_fitness, a.fixed_gains_fitness) for a in mine.activations] == [
        (a.sample, a.evaluations, a.best_fitness, a.fixed_gains_fitness) for a in theirs.activations
    ]


def test_another_switching_controller_than_the_exported_one_is_refused(robot, reference, exports):
    other = _scm("paper", horizon=10)
    with pytest.raises(InputError, match="horizon") as caught:
        simulate_exported(exports["paper"], robot, reference, controller=other)
    assert "\n" not in str(caught.value)


def _compilers() -> list:
    return [
        pytest.param("gcc", marks=pytest.mark.skipif(shutil.which("gcc") is None, reason="gcc is not installed")),
        pytest.param("clang", marks=pytest.mark.skipif(shutil.which("clang") is None, reason=CLANG_MISSING)),
    ]


def _make(folder: Path, build: Path, compiler: str, flags: str) -> Path:
    shutil.copytree(folder, build)
    done = make(build, f"CC={compiler}", f"CFLAGS={flags}", f"LDFLAGS={flags}")
    assert done.returncode == 0, done.stderr
    assert done.stderr == ""  # not a single warning
    return build


@pytest.mark.parametrize("compiler", _compilers())
def test_builds_strict_and_times_its_activations(compiler, exports, tmp_path):
    """-std=c99 -Wall -Wextra -Werror -pedantic -O2, and the Makefile's own -O2 -march=native: no
    warning; ga_timing runs activations and reports their times (not asserted: measured)."""
    strict = " ".join(f for f in STRICT_FLAGS if f != "-ffp-contract=off")
    for variant in VARIANTS:
        build = _make(exports[variant], tmp_path / f"{variant}-{compiler}", compiler, strict)
        done = subprocess.run([str(build / "ga_timing"), "3"], capture_output=True, text=True)
        assert done.returncode == 0, done.stderr
        assert "activation" in done.stdout and "p99" in done.stdout
    native = tmp_path / f"native-{compiler}"
    shutil.copytree(exports["safe"], native)
    done = make(native, f"CC={compiler}")
    assert done.returncode == 0 and done.stderr == "", done.stderr


#: A driver of vgtc_switching_step (a tiny threshold: every period activates, sets held in the safe
#: variant), for the sanitizers.
_DRIVER = r"""
#include <math.h>
#include <stdio.h>
#include "vgtc_switching.h"
static vgtc_switching sw;
static double ref[60 * 3 * VGTC_NJ], tip[60 * 3];
int main(void)
{
    vgtc_params control;
    vgtc_ga_params ga;
    vgtc_switching_params params;
    double q[VGTC_NJ], qd[VGTC_NJ], F[VGTC_NJ];
    long activations = 0;
    vgtc_default_params(&control);
    vgtc_ga_default_params(&ga);
    vgtc_switching_default_params(&params);
    ga.generations = 3;
    params.threshold = 1e-12;
    if (vgtc_switching_init(&sw, &control, &ga, &params) != VGTC_OK) return 2;
    for (int k = 0; k < 60; ++k) {
        for (int i = 0; i < VGTC_NJ; ++i) {
            const double a = vgtc_joint_is_angle[i] ? 1e-2 : 1e-3;
            ref[k * 3 * VGTC_NJ + i] = vgtc_home[i] + a * sin(0.05 * k);
            ref[k * 3 * VGTC_NJ + VGTC_NJ + i] = a * 50.0 * cos(0.05 * k);
            ref[k * 3 * VGTC_NJ + 2 * VGTC_NJ + i] = -a * 2500.0 * sin(0.05 * k);
        }
        for (int j = 0; j < 3; ++j) tip[3 * k + j] = 0.0;
    }
    for (int k = 0; k < 60; ++k) {
        for (int i = 0; i < VGTC_NJ; ++i) {
            q[i] = ref[k * 3 * VGTC_NJ + i] + 2e-4;
            qd[i] = ref[k * 3 * VGTC_NJ + VGTC_NJ + i];
        }
        int status = vgtc_switching_step(&sw, 1e-3 * k, q, qd, ref + k * 3 * VGTC_NJ, 60 - k, tip + 3 * k, NAN,
                                         NULL, (uint64_t)k + 1, F);
        if (status < 0) return 3;
        activations += sw.ran;
    }
    printf("%ld activations\n", activations);
    return activations > 0 ? 0 : 4;
}
"""


@pytest.mark.skipif(shutil.which("gcc") is None, reason="gcc is not installed")
@pytest.mark.parametrize("variant", VARIANTS)
def test_clean_under_address_and_undefined_behaviour_sanitizers(variant, exports, tmp_path):
    flags = "-std=c99 -O1 -g -fno-omit-frame-pointer -fsanitize=address,undefined -fno-sanitize-recover=all"
    build = _make(exports[variant], tmp_path / "asan", "gcc", flags)
    (build / "driver.c").write_text(_DRIVER)
    done = subprocess.run(
        ["gcc", *flags.split(), "-ffp-contract=off", "-o", "driver", "driver.c", "libvgtc.a", "-lm"],
        cwd=build,
        capture_output=True,
        text=True,
    )
    assert done.returncode == 0, done.stderr
    for program in (["./driver"], ["./ga_timing", "5"]):
        done = subprocess.run(program, cwd=build, capture_output=True, text=True)
        assert done.returncode == 0, done.stderr
        assert "runtime error" not in done.stderr and "activations" in done.stdout


def test_the_library_uses_only_libm_and_string_functions(exports, tmp_path):
    """No heap, no threads, no I/O in the library: its objects import libm and memcpy/memset only."""
    build = _make(exports["safe"], tmp_path / "nm", "gcc", "-std=c99 -O2")
    undefined = subprocess.run(["nm", "-u", str(build / "libvgtc.a")], capture_output=True, text=True, check=True)
    defined = subprocess.run(
        ["nm", "--defined-only", str(build / "libvgtc.a")], capture_output=True, text=True, check=True
    )
    names = {line.split()[-1] for line in undefined.stdout.splitlines() if line.strip() and not line.endswith(":")}
    names -= {line.split()[-1] for line in defined.stdout.splitlines() if len(line.split()) == 3}
    assert names <= ALLOWED_IMPORTS | GA_IMPORTS, sorted(names - ALLOWED_IMPORTS - GA_IMPORTS)


@pytest.mark.parametrize(
    ("options", "field"),
    [
        ({"ga": GAOptions(n_bits=10)}, "n_bits"),
        ({"prediction": "exact"}, "prediction"),
        ({"ga": GAOptions(stall_generations=5)}, "stall_generations"),
    ],
)
def test_what_is_not_exported_is_refused_in_one_line(options, field, robot, tmp_path):
    bounds = {"kp_bounds": CASE.kp_bounds, "kv_bounds": CASE.kv_bounds, "variant": "paper"}
    scm = SwitchingControl.with_gains(CASE.kp, CASE.kv, 7, **bounds, **options)
    with pytest.raises(InputError, match=field) as caught:
        export_controller(robot, tmp_path / "out", switching=scm)
    assert "\n" not in str(caught.value)
    assert not (tmp_path / "out").exists()
    with pytest.raises(InputError, match="switching"):
        export_controller(robot, tmp_path / "out", switching="fast")
    assert not (tmp_path / "out").exists()


def test_the_exported_ga_of_an_export_without_switching_is_refused(robot, tmp_path):
    folder = export_controller(robot, tmp_path / "cfc", check_build=False).folder
    with pytest.raises(InputError, match="without switching control"):
        ExportedGA(folder)


def test_the_fused_kernel_is_recognised_from_the_cpu_flags(monkeypatch):
    """ga.c's kernel fuses on x86-64 only in its x86-64-v3 clone: every v3 flag is needed."""
    import platform

    monkeypatch.setattr(platform, "machine", lambda: "x86_64")
    v3 = "flags\t\t: fpu sse2 avx avx2 bmi1 bmi2 f16c fma abm movbe xsave\n"
    assert simulator_fuses(v3)
    assert not simulator_fuses(v3.replace(" fma", ""))
    assert not simulator_fuses("flags\t\t: fpu sse2\n")
    monkeypatch.setattr(platform, "machine", lambda: "aarch64")
    assert simulator_fuses("")
