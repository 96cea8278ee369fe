"""Switching control's GA in the exported controller (``csrc/vgtc_ga.c``, issue 25).

:func:`ga_export` turns a :class:`~vgtarm.control.SwitchingControl` into what the export writes:
the sizes of ``vgtc_ga.h`` (``vgtc_config.h`` lines) and ``vgtc_ga_default_params`` (for
``vgtc_defaults.c``), with every value the simulation's compiled GA gets from
:func:`vgtarm.simulation.engines.compiled_ga` (bounds, seeded individuals, GA settings, the safe
variant's admitted interval and damping grid), so that an activation of the export equals the
simulation's bit for bit.
"""

from __future__ import annotations

import math
import platform
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..control.scm import SwitchingControl
from ..errors import InputError, shown
from ..ga import GAOptions
from ..model.actuators import Actuators
from ..model.closedloop import bit_words, pack_bits

#: Flags an x86-64 CPU needs for the x86-64-v3 kernel of the simulation's GA (``vgt_ga.h``, picked
#: by ``ga.c`` at run time), the one that fuses.
_X86_64_V3 = ("avx", "avx2", "bmi1", "bmi2", "f16c", "fma", "abm", "movbe", "xsave")
#: Variants of switching control the export writes.
VARIANTS = ("safe", "paper")


def simulator_fuses(cpuinfo: str | None = None) -> bool:
    """Whether the simulation's GA kernel (``vgt_ga.h``'s, built by ``ga.c`` in an x86-64-v4, v3 and
    baseline version picked at run time, fusing in v3 and v4) runs with fused multiply-adds on this
    machine: on x86-64 when the CPU takes the x86-64-v3 version (``cpuinfo``: the text of
    /proc/cpuinfo, read when None), elsewhere always (the other 64-bit ISAs fuse in their baseline)."""
    machine = platform.machine().lower()
    if machine not in ("x86_64", "amd64"):
        return True
    if cpuinfo is None:
        try:
            cpuinfo = Path("/proc/cpuinfo").read_text(errors="replace")
        except OSError:
            return False
    flags = set()
    for line in cpuinfo.splitlines():
        if line.startswith("flags"):
            flags.update(line.partition(":")[2].split())
            break
    return all(flag in flags for flag in _X86_64_V3)


@dataclass(frozen=True)
class GAExport:
    """What the export writes for switching control."""

    config: tuple[str, ...]  #: lines of vgtc_config.h
    defaults: tuple[str, ...]  #: the function vgtc_ga_default_params, line by line
    settings: dict[str, Any]  #: what export.json records


def switching_controller(switching: str | SwitchingControl, kp: Any, kv: Any, n: int) -> SwitchingControl:
    """The controller of ``switching``: a variant name builds the switching method around the fixed
    gains with the GA's gains searched in [0, gain] (case 2's bounds for its gains)."""
    if isinstance(switching, SwitchingControl):
        return switching
    if switching not in VARIANTS:
        raise InputError(f"switching = {switching!r}: expected one of {[None, *VARIANTS]} or a SwitchingControl")
    kp_top, kv_top = float(np.max(kp)), float(np.max(kv))
    return SwitchingControl.with_gains(kp, kv, n, kp_bounds=(0.0, kp_top), kv_bounds=(0.0, kv_top), variant=switching)


def ga_export(
    controller: SwitchingControl,
    n: int,
    dt: float,
    velocity_filter: float | None,
    fuses: bool,
    actuators: Actuators | None = None,
) -> GAExport:
    """The GA's part of an export for a robot of ``n`` joints at period ``dt``; the safe variant is
    admitted on a loop whose velocities are filtered with ``velocity_filter`` (None: measured); with
    ``actuators`` (the robot's) the prediction clips the effort to them, as the simulation's does.
    What the export does not reproduce is refused in one line."""
    _check_exportable(controller, n)
    options = controller.ga
    lower, upper = controller.bounds()
    n_genes = len(lower)
    words = bit_words(n_genes * options.n_bits)
    seeded = pack_bits(np.atleast_2d(controller.initial_bits()), words)
    n_seeded = len(seeded) if seeded.size else 0
    max_flips = _max_flips(options, n_genes)
    safe = _safe_terms(controller, dt, velocity_filter)
    n_kv = len(safe.damping[1]) if safe.damping is not None else 0
    config = (
        "/* switching control's GA (vgtc_ga.h) */",
        "#define VGTC_SWITCHING 1",
        f"#define VGTC_GA_POPULATION {options.population_size}",
        f"#define VGTC_GA_WORDS {words}",
        f"#define VGTC_GA_HORIZON {controller.horizon}",
        f"#define VGTC_GA_SEEDED {max(n_seeded, 1)}",
        f"#define VGTC_GA_NKV {max(n_kv, 1)}",
        f"#define VGTC_GA_MAX_FLIPS {max_flips}",
        f"#define VGTC_GA_FMA {int(fuses)}     /* the simulation's kernel fuses multiply-adds here */",
    )
    bits = seeded.ravel() if n_seeded else np.zeros(1, dtype=np.uint64)
    lines = _default_params(controller, lower, upper, bits, n_seeded, dt, safe, _limit_lines(actuators))
    return GAExport(config, (*(line for line in lines if line), ""), _settings(controller, fuses))


def _limit_lines(actuators: Actuators | None) -> list[str]:
    """The lines of ``vgtc_ga_default_params`` that set the actuators the prediction clips to (the
    robot's; ``saturation`` stays 0 without)."""
    if actuators is None:
        return []
    return [
        _array("force_limit", actuators.force),
        _array("speed_limit", actuators.speed),
        _array("force_speed", actuators.force_speed.astype(float)),
        "    params->saturation = 1;",
        "    memcpy(params->force_limit, force_limit, sizeof force_limit);",
        "    memcpy(params->speed_limit, speed_limit, sizeof speed_limit);",
        "    memcpy(params->force_speed, force_speed, sizeof force_speed);",
    ]


def _check_exportable(controller: SwitchingControl, n: int) -> None:
    """Refuse, in one line, a controller the export does not reproduce: gains of another size than
    the robot's ``n`` joints, genes of other than 8 bits, the exact prediction, a GA that stops on
    stalling."""
    options = controller.ga
    if controller.fixed.Kp.shape != (n, n):
        raise InputError(
            f"switching: the controller's gains are {controller.fixed.Kp.shape[0]} x {controller.fixed.Kp.shape[1]},"
            f" the robot has {n} joints"
        )
    if options.n_bits != 8:
        raise InputError(f"switching: ga.n_bits = {shown(options.n_bits)}: the export codes 8-bit genes (expected 8)")
    if controller.prediction not in ("linear", "quadratic"):
        raise InputError(
            f"switching: prediction = {controller.prediction!r}: the export predicts 'linear' or 'quadratic'"
            " (the exact prediction integrates the model and is not exported)"
        )
    if options.stall_generations is not None:
        raise InputError(
            f"switching: ga.stall_generations = {shown(options.stall_generations)}: the export runs every"
            " generation (expected None, as the simulation's compiled GA)"
        )


def _max_flips(options: GAOptions, n_genes: int) -> int:
    """The most bits one generation's mutation flips in the export (``VGTC_GA_MAX_FLIPS``): the
    mean of the children's flips with a margin of 64 plus eight standard deviations, at most all
    their bits."""
    total = (options.population_size - options.elite_count) * n_genes * options.n_bits
    max_flips = 64 + int(4.0 * options.mutation_probability * float(total)) + 8 * int(math.sqrt(float(total) + 1.0))
    return min(max_flips, total)


@dataclass(frozen=True)
class _SafeTerms:
    """The safe variant's values in the GA's parameters (zero and None for the paper's variant)."""

    safe: bool = False
    kv: float = 0.0  #: the fixed gains' damping
    lo: float = 0.0  #: the admitted interval of the eigenvalues of Kp (1/s^2)
    hi: float = 0.0
    damping: tuple[float, tuple[float, ...], tuple[float, ...]] | None = None  #: the damping grid (step, lo, hi)


def _safe_terms(controller: SwitchingControl, dt: float, velocity_filter: float | None) -> _SafeTerms:
    """The safe variant's admitted interval and damping grid for period ``dt`` and ``velocity_filter``;
    fixed gains outside the interval are refused in one line."""
    if controller.variant != "safe":
        return _SafeTerms()
    lo, hi = controller.admitted_interval(dt, velocity_filter)
    eig = np.linalg.eigvalsh(controller.fixed.Kp)
    if not (lo <= eig[0] and eig[-1] <= hi):
        raise InputError(
            f"switching: fixed Kp eigenvalues [{eig[0]:g}, {eig[-1]:g}]: the safe variant expects them in the"
            f" admitted interval [{lo:g}, {hi:g}]"
        )
    kv0 = float(controller.fixed.Kv[0, 0])
    return _SafeTerms(True, kv0, lo, hi, controller.damping_table(dt, velocity_filter))


def _default_params(
    controller: SwitchingControl,
    lower: np.ndarray,
    upper: np.ndarray,
    bits: np.ndarray,
    n_seeded: int,
    dt: float,
    safe: _SafeTerms,
    limits: list[str],
) -> list[str]:
    """The C functions ``vgtc_ga_default_params`` and ``vgtc_switching_default_params``, line by line
    (an empty line: none; ``bits``: the seeded individuals' words; ``limits``: the actuators' lines)."""
    options = controller.ga
    lines = [
        "void vgtc_ga_default_params(vgtc_ga_params *params)",
        "{",
        _array("lower", lower),
        _array("upper", upper),
        "    static const uint64_t seeded[] = {" + ", ".join(f"0x{int(b):016X}ULL" for b in bits) + "};",
        "    vgtc_params controller; /* the controller's model: the GA predicts with it */",
        "    vgtc_default_params(&controller);",
        "    memset(params, 0, sizeof *params);",
        "    memcpy(params->model, controller.model, sizeof params->model);",
        f"    params->dt = {_hex(dt)};",
        f"    params->population = {options.population_size};",
        f"    params->generations = {options.max_generations};",
        f"    params->elite = {options.elite_count};",
        f"    params->n_seeded = {n_seeded};",
        f"    params->p_crossover = {_hex(options.crossover_probability)};",
        f"    params->p_mutation = {_hex(options.mutation_probability)};",
        f"    params->horizon = {controller.horizon};",
        f"    params->exact_above = {_hex(controller.exact_above)};",
        f"    params->quadratic = {int(controller.prediction == 'quadratic')};",
        "    memcpy(params->lower, lower, sizeof lower);",
        "    memcpy(params->upper, upper, sizeof upper);",
        "    memcpy(params->initial_bits, seeded, sizeof seeded);" if n_seeded else "",
        f"    params->safe = {int(safe.safe)};",
        f"    params->safe_kv = {_hex(safe.kv)};",
        f"    params->safe_lo = {_hex(safe.lo)};",
        f"    params->safe_hi = {_hex(safe.hi)};",
    ]
    if safe.damping is not None:
        lines += [
            _array("kv_lo", safe.damping[1]),
            _array("kv_hi", safe.damping[2]),
            f"    params->safe_nkv = {len(safe.damping[1])};",
            f"    params->safe_kv_step = {_hex(safe.damping[0])};",
            "    memcpy(params->safe_lo_tab, kv_lo, sizeof kv_lo);",
            "    memcpy(params->safe_hi_tab, kv_hi, sizeof kv_hi);",
        ]
    return (
        lines
        + limits
        + [
            "}",
            "void vgtc_switching_default_params(vgtc_switching_params *params)",
            "{",
            "    memset(params, 0, sizeof *params);",
            f"    params->threshold = {_hex(controller.threshold)};",
            f"    params->hold = {controller.hold_periods};",
            f"    params->watch_from = {_watch_from(controller)};",
            "}",
        ]
    )


def _settings(controller: SwitchingControl, fuses: bool) -> dict[str, Any]:
    """What ``export.json`` records of switching control (its ``switching``)."""
    options = controller.ga
    return {
        "variant": controller.variant,
        "threshold_m": controller.threshold,
        "horizon": controller.horizon,
        "prediction": controller.prediction,
        "exact_above": controller.exact_above,
        "population": options.population_size,
        "generations": options.max_generations,
        "elite": options.elite_count,
        "hold": controller.hold_periods,
        "switch_on": "measured" if controller.measured_switching else "true",
        "watch_from": _watch_from(controller),
        "fused_multiply_add": bool(fuses),
    }


def switching_readme(settings: dict[str, Any] | None) -> str:
    """The export README's part on switching control (``settings``: export.json's ``switching``)."""
    if not settings:
        return " Switching control (the paper's GA) is not part of this export (`--switching safe|paper`)."
    hold = settings["hold"]
    return f"""

## Switching control ({settings["variant"]} variant)

`vgtc_switching.h` runs the switching control method around the controller: while the tip error
stays within {settings["threshold_m"]:g} m the fixed gains control; in a period above it one GA
activation ({settings["population"]} individuals, {settings["generations"]} generations, the
{settings["prediction"]} prediction over {settings["horizon"]} periods) chooses the gains
{"of that period" if hold == 1 else f"of that period and, when admitted, of the next {hold - 1}"}.
The threshold is tested on {
        "the tip error the controller sees, |tip_d - P^(q_meas)| (pass NAN)"
        if settings["switch_on"] == "measured"
        else "the true tip error, which the controller does not see: a tracker measures it"
    }.

```c
static vgtc_switching sw;         /* the controller, its GA and their work arrays: no heap */
vgtc_params p; vgtc_ga_params g; vgtc_switching_params s;
vgtc_default_params(&p); vgtc_ga_default_params(&g); vgtc_switching_default_params(&s);
if (vgtc_switching_init(&sw, &p, &g, &s) != VGTC_OK) ...;
/* each period: `rows` reference rows (q_d, qd_d, qdd_d) and desired tips from this one on */
int status = vgtc_switching_step(&sw, t, q_meas, qd_meas, ref_rows, rows, tip_d_rows,
                                 NAN /* or the measured tip error */, f_meas, seed, efforts);
```

`vgtc_switching_step_feedforward` takes the expected tool force of the period after `f_meas`
(`vgtc_step_feedforward`'s `f_exp`), fed forward under the fixed gains and the GA's alike.

`vgtc_ga.c` runs the simulation's GA for a real-time target: the GA's operations are one file,
`vgt_ga.h`, which the simulation compiles too (its `ga.c`); here every buffer is sized
at compile time (`vgtc_config.h`), no heap, no threads, no intrinsics; the same random stream
(xoshiro256** seeded through splitmix64, one seed per activation) and the same arithmetic, so an
activation from the same state, window and seed returns the simulation's gains bit for bit
(tested, and the loop closed through this folder equals `vgtarm simulate`). The simulation's
kernel fuses multiply-adds on this machine: `VGTC_GA_FMA` = {int(settings["fused_multiply_add"])}
writes them as `fmaf`. With GCC or Clang the eight candidates of a block are one vector of the
compilers' extensions per quantity, so the prediction's values stay in registers; other C99
compilers (or `-DVGTC_GA_NO_VECTORS`) build the same arithmetic on plain arrays, the same bits.
For speed build with `-O2 -march=native` (the Makefile's default here): `fmaf` becomes an
instruction; at a portable -O2 (no FMA instruction) an activation is tens of times slower. An
activation takes 0.6 to 0.9 ms on one core of the x86-64 server this was measured on (p99 under
1 ms on case 2's windows; `./ga_timing 1000` measures it here), so a period with an activation
fits a 1 ms period only just: give the GA its own core a period ahead, or fewer generations
(`vgtc_ga_params.generations`), where the rest of the period is needed. `ga_timing`'s one argument,
the number of activations, is a whole number (digits only) from 1 to 10,000,000
(`GA_MAX_ACTIVATIONS` in `ga_timing.c`); anything else is refused in one line, exit status 1."""


def _watch_from(controller: SwitchingControl) -> int:
    """The first held period whose error may drop a held set (the hold: never); a controller
    without the drop rule (``watch_period``) never drops one."""
    return int(getattr(controller, "watch_period", controller.hold_periods))


def _hex(x: float) -> str:
    x = float(x)
    if math.isnan(x):
        return "NAN"
    if math.isinf(x):
        return "INFINITY" if x > 0 else "-INFINITY"
    return x.hex()


def _array(name: str, values: Any) -> str:
    body = ", ".join(_hex(v) for v in np.asarray(values, dtype=float).ravel())
    return f"    static const double {name}[] = {{{body}}};"
