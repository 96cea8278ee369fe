"""The calibration's solver against ``scipy.optimize.least_squares`` on the same problem, timed in
the same process (docs/calibration.md): the issue's synthetic case (every length +-2 mm, each leg
sensor +-2 mm off, 0.05 mm noise, the 50 poses ``plan_poses`` chooses), both robot formats.

Prints a Markdown table: median wall time of each solver over ``REPEATS`` runs, the model
evaluations it made, and its distance to our optimum in standard errors.

Run: ``python -m benchmarks calibration``.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import scipy.optimize

import vgtarm
from vgtarm.calibration import kinematic as K

REPEATS = 20
EXAMPLES = Path(__file__).resolve().parent.parent / "examples"


def _timed(run):
    times, out = [], None
    for _ in range(REPEATS):
        start = time.perf_counter()
        out = run()
        times.append(time.perf_counter() - start)
    return float(np.median(times)), out


def _solvers(problem: K.CalibrationProblem) -> dict:
    """Each solver as a function of nothing giving ``(z, model evaluations)``."""

    def ours():
        problem.evaluations = 0
        z = K._levenberg_marquardt(problem, problem.z0, 100, 1e-10)[0]
        return z, problem.evaluations

    def scipy_run(method, jac):
        def run():
            problem.evaluations = 0
            tight = {"xtol": 1e-15, "ftol": 1e-15, "gtol": 1e-15} if jac is not None else {}
            found = scipy.optimize.least_squares(
                problem.residuals, problem.z0, jac=jac or "2-point", method=method, **tight
            )
            return found.x, problem.evaluations

        return run

    return {
        "ours (LM, AD Jacobian)": ours,
        "scipy lm, AD Jacobian": scipy_run("lm", problem.jacobian),
        "scipy trf, AD Jacobian": scipy_run("trf", problem.jacobian),
        "scipy trf, finite differences": scipy_run("trf", None),
    }


def _rows(label: str, config: str | None) -> None:
    robot = vgtarm.load_robot(config)
    plan = K.plan_poses(robot, 50, seed=0)
    truth = K.perturbed_values(robot, seed=1)
    measured = K.synthetic_measurements(robot, plan.q, truth, noise=0.05e-3, seed=2)
    fit = K.calibrate(robot, measured)
    problem = K.least_squares_problem(robot, measured)
    free, se = fit.identifiability.free, fit.standard_errors
    base = None
    for name, run in _solvers(problem).items():
        seconds, (z, evaluations) = _timed(run)
        base = seconds if base is None else base
        gap = np.abs(problem.full(z) - fit.values)[free] / se[free]
        print(f"| {label} | {name} | {1e3 * seconds:.2f} | {seconds / base:.2f} | {evaluations} | {gap.max():.1e} |")


def run() -> None:
    print("| robot | solver | median time (ms) | ratio to ours | model evaluations | max abs(x - ours) / std. error |")
    print("|---|---|---|---|---|---|")
    _rows("paper", None)
    _rows("stack", str(EXAMPLES / "paper_robot.toml"))
