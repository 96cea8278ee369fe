"""The closed loop's fused step on the recursive model (issue 24): the same results as the separate adapters.

- whole runs of computed force control (``run_case``) with the fused step (the default backend) and
  with the separate adapters of the previous implementation (``RecursiveBackend(stack, fused=False)``)
  are the same bit for bit: Euler and RK4, the momentum observer under the tool force with sensing
  (the controller's state then differs from the plant's, so the CFC law computes its own joints),
  the Kalman estimator, a controller model with other masses (another arm);
- the step functions (``vgt_rec_step_*``), called in an order that hits and misses what a thread
  keeps (states repeated, changed, two arms alternating, a binding in between), equal the batch
  functions bit for bit;
- the tip alone (``vgt_rec_tip``, from the joints' poses) equals forward kinematics' tip bit for bit.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np
import pytest

from tests.test_recursive import EXAMPLES, configurations, varied_stack
from vgtarm.model.recursive import RecursiveModel
from vgtarm.model.recursive.backend import RecursiveBackend
from vgtarm.model.robot import Robot
from vgtarm.model.stack import Stack
from vgtarm.simulation.reference import JointReference

FIELDS = ("q", "qd", "effort", "tip", "tip_error", "f_ext", "effort_estimate", "tip_error_measured")


def long_stack(k: int) -> Stack:
    """``k`` modules: those of :func:`varied_stack` (6) repeated."""
    short = varied_stack(6)
    modules = tuple(short.modules[i % short.n_modules] for i in range(k))
    return replace(short, name=f"long {k}", modules=modules)


def sinusoids(robot: Robot, stack: Stack, samples: int = 400) -> JointReference:
    """Every joint along a sinusoid of 5 % of its span about home (as ``benchmarks recursive-control``)."""
    t = np.arange(samples, dtype=np.float64) * 1e-3
    span = (stack.upper - stack.lower) * 0.05
    phase = np.linspace(0.0, np.pi, stack.n_joints)
    w = 2 * np.pi / 0.4
    q = stack.home + span * np.sin(w * t[:, None] + phase)
    qd = span * w * np.cos(w * t[:, None] + phase)
    qdd = -span * w * w * np.sin(w * t[:, None] + phase)
    return JointReference(t=t, q=q, qd=qd, qdd=qdd, rates="exact", name="sinusoids", tip=robot.tip_position(q))


def _same(a: Any, b: Any) -> None:
    for field in FIELDS:
        x, y = getattr(a, field), getattr(b, field)
        if x is None or y is None:
            assert x is None and y is None, field
            continue
        assert np.array_equal(np.asarray(x), np.asarray(y), equal_nan=True), field


@pytest.mark.parametrize("k", [3, 12])
def test_fused_step_equals_the_separate_adapters(k: int) -> None:
    from vgtarm.experiment.cases import run_case

    stack = varied_stack(k) if k <= 6 else long_stack(k)
    fused, separate = Robot(stack, RecursiveBackend(stack)), Robot(stack, RecursiveBackend(stack, fused=False))
    assert fused.backend.fused and not separate.backend.fused
    reference = sinusoids(fused, stack)
    heavier = replace(
        stack,
        modules=tuple(replace(m, platform=replace(m.platform, mass=1.1 * m.platform.mass)) for m in stack.modules),
    )
    runs: list[dict[str, Any]] = [
        {},
        {"integrator": "rk4", "substeps": 2},
        {"observer": "momentum", "external_force": True, "encoder_resolution": 1e-6, "velocity_noise": 1e-4},
        {"observer": "momentum", "encoder_resolution": 1e-6, "estimator": "kalman"},
        {"controller_model": heavier, "external_force": True},
    ]
    for options in runs:
        a = run_case(separate, 1, reference=reference, **options)
        b = run_case(fused, 1, reference=reference, **options)
        assert a.success and b.success, options
        assert np.isfinite(b.effort).all() and np.abs(b.effort).max() > 0.0
        _same(a, b)


def test_step_functions_equal_the_batch_functions() -> None:
    stacks = [varied_stack(5), long_stack(9)]
    models = [RecursiveModel(s) for s in stacks]
    # the same structure, other masses: another arm of the same size
    heavier = replace(stacks[0], end_effector=replace(stacks[0].end_effector, mass=2.0))
    models.append(RecursiveModel(heavier))
    ffi, lib = models[0]._ffi, models[0]._lib
    rng = np.random.default_rng(3)
    data = []
    for m in models:
        n = m.n
        q = configurations(m.stack, 4, seed=n)
        qd, x = rng.normal(scale=0.5, size=(4, n)), rng.normal(scale=5.0, size=(4, n))
        wrench = rng.normal(size=(4, 6))
        data.append((m, q, qd, x, wrench))

    def ptr(a: np.ndarray) -> Any:
        return ffi.cast("double *", ffi.from_buffer(a))

    def expected(m: RecursiveModel, q: np.ndarray, qd: np.ndarray, x: np.ndarray, w: np.ndarray) -> list[np.ndarray]:
        return [
            m.inverse_dynamics(q, qd, x, w[:3], w[3:]),
            m.forward_dynamics(q, qd, x, w[:3], w[3:]),
            *(np.asarray(v) for v in _tip_state(m, q, qd)),
        ]

    order = [(0, 0), (0, 0), (0, 1), (1, 0), (0, 1), (2, 1), (0, 1), (1, 3), (1, 3), (2, 2), (0, 2)]
    for step, (which, sample) in enumerate(order):
        m, q, qd, x, w = data[which]
        qs, qds, xs, ws = (np.ascontiguousarray(a[sample]) for a in (q, qd, x, w))
        want = expected(m, qs, qds, xs, ws)
        tau, acc, tip, vel, alone = (np.empty(n) for n in (m.n, m.n, 3, 3, 3))
        # in an order that reuses what the thread keeps: tip state, inverse, forward, tip
        assert lib.vgt_rec_step_tip_state(m._arm, ptr(qs), ptr(qds), ptr(tip), ptr(vel)) == 0
        assert lib.vgt_rec_step_inverse(m._arm, ptr(qs), ptr(qds), ptr(xs), ptr(ws), ptr(tau)) == 0
        assert lib.vgt_rec_step_forward(m._arm, ptr(qs), ptr(qds), ptr(xs), ptr(ws), ptr(acc)) == 0
        assert lib.vgt_rec_step_tip(m._arm, ptr(qs), ptr(alone)) == 0
        for got, ref in zip((tau, acc, tip, vel, alone), (*want, want[2]), strict=True):
            assert np.array_equal(got, ref), step
        if step == 5:
            lib.vgt_rec_step_forget()
        # a copy of the state at another address, and a state differing in one velocity's last bit
        other = qds.copy()
        other[-1] = np.nextafter(other[-1], np.inf)
        assert lib.vgt_rec_step_inverse(m._arm, ptr(qs.copy()), ptr(other), ptr(xs), ptr(ws), ptr(tau)) == 0
        assert np.array_equal(tau, m.inverse_dynamics(qs, other, xs, ws[:3], ws[3:]))


def _tip_state(m: RecursiveModel, q: np.ndarray, qd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    tip, vel = np.empty((1, 3)), np.empty((1, 3))
    m._call("vgt_rec_tip_state", 1, np.ascontiguousarray(q[None]), np.ascontiguousarray(qd[None]), tip, vel)
    return tip[0], vel[0]


@pytest.mark.parametrize("k", [1, 2, 5, 6, 30])
def test_tip_alone_equals_forward_kinematics(k: int) -> None:
    stack = varied_stack(k) if k <= 6 else long_stack(k)
    model = RecursiveModel(stack)
    q = configurations(stack, 300, seed=k)
    assert np.array_equal(model.tip_position(q), model.forward_kinematics(q)["tip"])
    assert np.array_equal(model.tip_position(q[0]), model.forward_kinematics(q[0])["tip"])
    fused, separate = Robot(stack, RecursiveBackend(stack)), Robot(stack, RecursiveBackend(stack, fused=False))
    assert np.array_equal(fused.tip_position(q), separate.tip_position(q))


def test_cfc_law_with_bound_gains_equals_the_separate_adapter() -> None:
    """The fused CFC law over the nonzero entries of bound gains (a third of them zero, signs mixed)
    and over every entry of gains not bound equals the separate adapter bit for bit."""
    stack = varied_stack(5)
    backend = RecursiveBackend(stack)
    p = np.ascontiguousarray(stack.vector())
    backend.bind_parameters(p)
    ffi, lib = backend._models[p.tobytes()]._ffi, backend._models[p.tobytes()]._lib
    n = stack.n_joints
    rng = np.random.default_rng(11)

    def ptr(a: np.ndarray) -> Any:
        return ffi.cast("double *", ffi.from_buffer(a))

    Kp = rng.normal(scale=50.0, size=(n, n)) * (rng.uniform(size=(n, n)) > 0.33)
    Kv = rng.normal(scale=5.0, size=(n, n)) * (rng.uniform(size=(n, n)) > 0.33)
    Kp[0, :] = -0.0  # a row of zeros (negative)
    q = configurations(stack, 3, seed=4)
    for bound in (True, False):
        backend.bind_run(Kp, Kv) if bound else backend.bind_run(None, None)
        for s in range(3):
            qd, q_d, qd_d, qdd_d = (rng.normal(size=n) for _ in range(4))
            inputs = [q[s], qd, q[s] + 0.01 * q_d, qd_d, qdd_d]
            args = ffi.new(
                "const double *[8]", [*(ptr(np.ascontiguousarray(a)) for a in inputs), ptr(Kp), ptr(Kv), ptr(p)]
            )
            fused, separate = np.empty(n), np.empty(n)
            assert lib.vgt_rec_fn_cfc_fused(args, ffi.new("double *[1]", [ptr(fused)]), ffi.NULL, ffi.NULL, 0) == 0
            assert lib.vgt_rec_fn_cfc(args, ffi.new("double *[1]", [ptr(separate)]), ffi.NULL, ffi.NULL, 0) == 0
            assert np.array_equal(fused, separate), (bound, s)
    backend.bind_run(None, None)


def test_switching_control_on_the_fused_step_equals_the_separate_adapters() -> None:
    from vgtarm.experiment.cases import run_case

    stack = varied_stack(3)
    fused, separate = Robot(stack, RecursiveBackend(stack)), Robot(stack, RecursiveBackend(stack, fused=False))
    reference = sinusoids(fused, stack, samples=60)
    start = (reference.q[0] + 0.004, np.zeros(stack.n_joints))
    a = run_case(separate, 2, reference=reference, controller="scm", initial_state=start)
    b = run_case(fused, 2, reference=reference, controller="scm", initial_state=start)
    assert a.success and b.success and len(a.activations) == len(b.activations) > 0
    _same(a, b)


def test_runs_that_fail_stop_alike() -> None:
    """Runs driven out of the limits and out of the assembled set (the driver's assembly check over
    the bound margin rows' nonzero entries) stop at the same sample, with the same status and samples."""
    from vgtarm.errors import SimulationError
    from vgtarm.experiment.cases import run_case

    stack = varied_stack(3)
    fused, separate = Robot(stack, RecursiveBackend(stack)), Robot(stack, RecursiveBackend(stack, fused=False))
    reference = sinusoids(fused, stack, samples=100)
    start = (reference.q[0] + 0.01, np.zeros(stack.n_joints))
    for kp, why in ((1e6, "far outside its limits"), (1e7, "can no longer be assembled")):
        failures = []
        for robot in (separate, fused):
            with pytest.raises(SimulationError, match=why) as caught:
                run_case(robot, 1, reference=reference, kp=kp, kv=10.0, initial_state=start)
            failures.append(caught.value)
        assert str(failures[0]) == str(failures[1])
        _same(failures[0].result, failures[1].result)


def test_margin_rows_bound_and_not_bound_agree() -> None:
    """The driver's margin rows (``vgt_rec_margin``) over the nonzero entries of bound rows and over
    every entry: the same sign of every margin, and the same value but for the sign of a zero."""
    stack = varied_stack(4)
    backend = RecursiveBackend(stack)
    ffi, lib = RecursiveModel(stack)._ffi, RecursiveModel(stack)._lib
    robot = Robot(stack, backend)
    G, h = (np.ascontiguousarray(a, dtype=float) for a in robot.margin_form())
    n = stack.n_joints
    assert (G == 0.0).mean() > 0.5  # three legs a row
    Kp = np.ascontiguousarray(np.eye(n))
    rng = np.random.default_rng(2)
    q = np.concatenate([configurations(stack, 50, seed=1), rng.uniform(-1.0, 1.0, size=(50, n))])
    G_ptr = ffi.cast("double *", ffi.from_buffer(G))
    for bound in (False, True):
        backend.bind_run(Kp, Kp, G) if bound else backend.bind_run(None, None)
        values = np.array(
            [
                [
                    lib.vgt_rec_margin(
                        G_ptr, n, row, h[row], ffi.cast("double *", ffi.from_buffer(np.ascontiguousarray(x)))
                    )
                    for row in range(len(h))
                ]
                for x in q
            ]
        )
        if not bound:
            dense = values
    backend.bind_run(None, None)
    assert np.array_equal(values, dense) and np.array_equal(values > 0.0, dense > 0.0)
    assert (dense <= 0.0).any() and (dense > 0.0).any()
    assert np.allclose(dense, q @ G.T + h, rtol=0.0, atol=1e-14)


class _PlantedMargins(RecursiveBackend):
    """A recursive backend that, once a run's margin rows ``G`` are bound, plants a NaN in every zero
    entry of ``G`` (the very array the driver reads): a sum over the bound rows' nonzero entries
    never reads one, a sum over every entry is NaN, which the assembly check refuses."""

    def bind_run(self, Kp: Any, Kv: Any, G: Any = None) -> None:
        super().bind_run(Kp, Kv, G)
        if G is not None:
            G[G == 0.0] = np.nan


def test_the_driver_s_assembly_check_sums_the_margin_rows_through_the_hook() -> None:
    """The recursive library compiles ``closed_loop.c`` itself with ``-DVGT_MARGIN_ROW=vgt_rec_margin``:
    the drivers' assembly check sums the rows a run bound over their nonzero entries. With a NaN in
    every zero entry of ``G`` after the binding, a run of the fused step is the same bit for bit (the
    dense loop of ``closed_loop.c`` would read the NaNs and stop at the first sample), while the
    separate adapters, which bind nothing, sum every entry and stop at the first check."""
    from vgtarm.errors import SimulationError
    from vgtarm.experiment.cases import run_case

    stack = varied_stack(3)
    robot = Robot(stack, RecursiveBackend(stack))
    G, _ = robot.margin_form()
    assert (G == 0.0).any() and (G != 0.0).any()
    reference = sinusoids(robot, stack, samples=60)
    start = (reference.q[0] + 0.004, np.zeros(stack.n_joints))
    plain = run_case(robot, 1, reference=reference, initial_state=start, integrator="rk4")
    planted = run_case(
        Robot(stack, _PlantedMargins(stack)), 1, reference=reference, initial_state=start, integrator="rk4"
    )
    assert plain.success and planted.success
    _same(plain, planted)
    with pytest.raises(SimulationError, match="can no longer be assembled") as caught:
        run_case(Robot(stack, _PlantedMargins(stack, fused=False)), 1, reference=reference, initial_state=start)
    assert np.isnan(caught.value.result.q[1:]).all()  # stopped at the first check


def test_a_run_out_of_the_assembled_set_stops_as_on_the_symbolic_library() -> None:
    """The recursive library's assembly check (``closed_loop.c`` with the hook: the bound rows'
    nonzero entries) and the symbolic library's (the same file without it: every entry) stop a run
    driven out of the assembled set at the same sample for the same reason, the samples before the
    same to rounding (the one-module stack, whose symbolic library the suite builds anyway)."""
    import vgtarm
    from vgtarm.errors import SimulationError
    from vgtarm.experiment.cases import joint_reference, run_case

    path = EXAMPLES / "planar_module.toml"
    symbolic = vgtarm.load_robot(path, model="symbolic")
    if symbolic.backend.kind != "compiled":
        pytest.skip("no C compiler: no symbolic library to hold the recursive one to")
    recursive = vgtarm.load_robot(path, model="recursive")
    assert recursive.backend.kind == "recursive"
    reference = joint_reference(symbolic, 1, duration=0.1)
    start = (reference.q[0] + 0.01, np.zeros(reference.q.shape[1]))
    stops, results = [], []
    for robot in (symbolic, recursive):
        with pytest.raises(SimulationError, match="a leg set can no longer be assembled") as caught:
            run_case(robot, 1, reference=reference, kp=1e7, kv=10.0, initial_state=start)
        stops.append(str(caught.value).split(":")[0])  # "diverged at t = ... s (sample k of n)"
        results.append(caught.value.result)
    a, b = results
    ran = np.isfinite(a.q).all(axis=1)
    assert stops[0] == stops[1] and np.array_equal(ran, np.isfinite(b.q).all(axis=1))
    assert 1 < ran.sum() < len(ran)
    assert np.abs(b.q[ran] - a.q[ran]).max() < 1e-12
