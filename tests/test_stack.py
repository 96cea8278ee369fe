"""Stacks of VGT modules: the description, and the n-joint model against independent routes.

- the paper's robot as a stack gives today's 7-joint model (compiled) to 1e-14;
- one module alone against a planar VGT solved here by circle intersections, its Jacobian by
  implicit differentiation of the leg constraints, and central finite differences;
- identical modules standing symmetric: the analytic straight tip, for any plane angles;
- the six-module arm of ``examples/``: physics identities (M symmetric positive definite and the
  Hessian of the kinetic energy, gravity the gradient of the potential, power balance along a
  simulated motion, inverse dynamics of forward dynamics);
- bad stacks refused with one line naming the module and the field.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import replace
from pathlib import Path
from typing import Any

import casadi as ca
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from vgtarm.errors import AssemblyError, ConfigError, InputError
from vgtarm.model.parameters import Body, load_parameters
from vgtarm.model.stack import (
    Stack,
    StackModel,
    StackModule,
    Twist,
    load_stack,
    stack_dynamics,
    stack_from_dict,
    stack_from_parameters,
    stack_margins,
    stack_to_toml,
)

from .conftest import assert_close, central_difference, random_configurations

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def stack_configurations(stack: Stack, n: int, seed: int, margin: float = 0.01) -> np.ndarray:
    """``n`` configurations drawn uniformly inside the limits, every module assemblable with ``margin``."""
    rng = np.random.default_rng(seed)
    chosen: list[np.ndarray] = []
    while sum(len(c) for c in chosen) < n:
        q = rng.uniform(stack.lower, stack.upper, size=(4 * n, stack.n_joints))
        chosen.append(q[(stack_margins(stack, q) > margin).all(axis=(-2, -1))])
    return np.concatenate(chosen)[:n]


def same(actual: np.ndarray, desired: np.ndarray, what: str, tol: float = 1e-14) -> None:
    """Equal to ``tol`` relative to the largest magnitude of ``desired`` (absolute below 1)."""
    scale = max(1.0, float(np.abs(desired).max()))
    error = float(np.abs(np.asarray(actual) - desired).max())
    assert error <= tol * scale, f"{what}: differs by {error:.3g} (scale {scale:.3g})"


# -- the paper's robot ---------------------------------------------------------------------


@pytest.fixture(scope="module")
def paper() -> StackModel:
    return StackModel(stack_from_parameters(load_parameters()))


def test_the_paper_robot_as_a_stack_is_todays_model(robot, paper):
    rng = np.random.default_rng(130)
    q = random_configurations(robot, 8, seed=130)
    qd = rng.normal(scale=0.2, size=q.shape)
    F, qdd = rng.normal(scale=50.0, size=q.shape), rng.normal(scale=1.0, size=q.shape)
    f_tip = rng.normal(scale=20.0, size=(len(q), 3))
    assert paper.stack.joint_names == robot_joint_names()
    fk = robot.forward_kinematics(q)
    for i in range(len(q)):
        mine = paper.forward_kinematics(q[i])
        same(mine.passive, fk.passive[i], "passive angles")
        same(mine.platform_position, fk.platform_position[i], "platform centres")
        same(mine.platform_rotation, fk.platform_rotation[i], "platform frames")
        same(mine.tip, fk.tip[i], "tip")
        same(mine.rotation, fk.rotation[i], "end-effector orientation")
        J_P, J_W = paper.jacobians(q[i])
        same(J_P, robot.tip_jacobian(q[i]), "tip Jacobian")
        same(J_W, robot.angular_jacobian(q[i]), "angular Jacobian")
        same(paper.mass_matrix(q[i]), robot.mass_matrix(q[i]), "M")
        same(paper.bias_forces(q[i], qd[i]), robot.bias_forces(q[i], qd[i]), "C")
        same(paper.gravity_forces(q[i]), robot.bias_forces(q[i], np.zeros(7)), "gravity")
        same(paper.energy(q[i], qd[i]), np.array(robot.energy(q[i], qd[i])), "energies")
        same(
            paper.inverse_dynamics(q[i], qd[i], qdd[i], f_tip[i]),
            robot.inverse_dynamics(q[i], qd[i], qdd[i], f_tip[i]),
            "inverse dynamics",
        )
        # M, C and J_P agree bit for bit; the two linear solves (CasADi's symbolic one, NumPy's
        # Cholesky) then differ by rounding amplified by the condition number of M (up to 1e5)
        expected = robot.forward_dynamics(q[i], qd[i], F[i], f_tip[i])
        tol = 4 * np.finfo(float).eps * np.linalg.cond(robot.mass_matrix(q[i]))
        same(paper.forward_dynamics(q[i], qd[i], F[i], f_tip[i]), expected, "forward dynamics", tol=tol)


def robot_joint_names() -> tuple[str, ...]:
    from vgtarm.model.parameters import JOINT_NAMES

    return JOINT_NAMES


def test_the_shipped_examples_read_back_bit_for_bit():
    """``examples/paper_robot.toml`` is the reference robot; every example survives a TOML round trip."""
    reference = stack_from_parameters(load_parameters())
    assert load_stack(EXAMPLES / "paper_robot.toml") == reference
    for name, n_joints in (("paper_robot", 7), ("planar_module", 3), ("six_modules", 21)):
        stack = load_stack(EXAMPLES / f"{name}.toml")
        assert stack.n_joints == n_joints == len(stack.joint_names)
        again = stack_from_dict(tomllib.loads(stack_to_toml(stack, header="round trip")))
        assert again == stack
        assert np.array_equal(again.vector(), stack.vector())
    six = load_stack(EXAMPLES / "six_modules.toml")
    assert [n for n in six.joint_names if n.startswith("psi")] == ["psi3", "psi5", "psi7"]
    assert [m.plane for m in six.modules] == [0.0, 90.0] * 3


def test_convert_robot_writes_the_reference_robot_as_a_stack(tmp_path, capsys):
    from vgtarm.app.cli.command import main

    out = tmp_path / "sub" / "paper.toml"
    assert main(["convert-robot", "--out", str(out)]) == 0
    assert "stack of 2 modules and 1 twist joint written" in capsys.readouterr().out
    assert load_stack(out) == load_stack(EXAMPLES / "paper_robot.toml")
    assert main(["convert-robot", "--config", str(tmp_path / "missing.toml"), "--out", str(tmp_path / "x.toml")]) == 1
    assert "not found" in capsys.readouterr().err
    assert not (tmp_path / "x.toml").exists()


# -- one module alone ----------------------------------------------------------------------


def planar_vgt(legs: np.ndarray, b: float, d: float, tool: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Tip ``(3,)``, its Jacobian ``(3, 3)`` and the rates of the platform tilt ``(3,)`` of one module
    in the ``u2-u3`` plane, tool ``tool`` on the platform normal: the two top joints by circle
    intersections, their rates by implicit differentiation of the three leg constraints and the
    platform edge."""
    s, v, p = legs
    A, B = np.array([-b, 0.0]), np.array([b, 0.0])
    x = (p**2 - v**2) / (4 * b)  # |B' - A| = p, |B' - B| = v
    Bt = np.array([x, math.sqrt(p**2 - (x + b) ** 2)])  # above the base
    e = (Bt - A) / p
    along = (s**2 - 4 * d**2 + p**2) / (2 * p)  # |A' - A| = s, |A' - B'| = 2d
    At = A + along * e + math.sqrt(s**2 - along**2) * np.array([-e[1], e[0]])  # left of the diagonal
    edge = Bt - At
    theta = math.atan2(edge[1], edge[0])
    centre = (At + Bt) / 2
    tip = np.array([0.0, centre[0] - tool * math.sin(theta), centre[1] + tool * math.cos(theta)])
    # (B'-A).dB' = p dp, (B'-B).dB' = v dv; (A'-A).dA' = s ds, (A'-B').(dA' - dB') = 0
    dBt = np.linalg.solve(np.array([Bt - A, Bt - B]), np.array([[0, 0, p], [0, v, 0]]))
    rows = np.array([At - A, At - Bt])
    dAt = np.linalg.solve(rows, np.array([[s, 0, 0], [0, 0, 0]]) + np.outer([0, 1], (At - Bt) @ dBt))
    d_edge = dBt - dAt
    d_theta = (edge[0] * d_edge[1] - edge[1] * d_edge[0]) / (edge @ edge)
    d_centre = (dAt + dBt) / 2
    jacobian = np.array(
        [
            np.zeros(3),
            d_centre[0] - tool * math.cos(theta) * d_theta,
            d_centre[1] - tool * math.sin(theta) * d_theta,
        ]
    )
    return tip, jacobian, d_theta


@pytest.fixture(scope="module")
def planar() -> StackModel:
    return StackModel(load_stack(EXAMPLES / "planar_module.toml"))


def test_one_module_is_the_hand_derived_planar_vgt(planar):
    stack = planar.stack
    module = stack.modules[0]
    assert stack.tool[:2] == (0.0, 0.0) and stack.tool[2] > 0
    q = stack_configurations(stack, 8, seed=131)
    for legs in q:
        tip, jacobian, d_theta = planar_vgt(legs, module.b, module.d, stack.tool[2])
        J_P, J_W = planar.jacobians(legs)
        assert_close(planar.tip_position(legs), tip, rtol=0, atol=1e-15, what="tip")
        assert_close(J_P, jacobian, rtol=1e-12, atol=1e-13, what="tip Jacobian")
        # the platform turns about u1 only
        assert_close(J_W, [d_theta, np.zeros(3), np.zeros(3)], rtol=1e-12, atol=1e-13, what="angular Jacobian")


def test_one_module_jacobians_match_finite_differences(planar):
    q = stack_configurations(planar.stack, 6, seed=132, margin=0.02)
    fd = central_difference(lambda x: np.array([planar.tip_position(row) for row in x]), q)
    J_P = np.array([planar.jacobians(row)[0] for row in q])
    assert_close(J_P, fd, rtol=1e-7, atol=1e-9, what="J_P against central differences")


# -- identical modules standing straight -----------------------------------------------------


def straight_stack(planes: tuple[float, ...], twists_after: dict[int, float], tool: float) -> Stack:
    platform = Body("platform", 1.0, (0.0, 0.0, 0.0), ((0.01, 0.0, 0.0), (0.0, 0.01, 0.0), (0.0, 0.0, 0.02)))
    home = (0.2844292530665578, 0.2844292530665578, 0.3753664875824692)
    limits = ((0.22, 0.36), (0.22, 0.36), (0.30, 0.46))
    modules = tuple(
        StackModule(
            b=0.15,
            d=0.10,
            plane=plane,
            limits=limits,
            home=home,
            platform=platform,
            twist=Twist(height=twists_after[k], limits=(-4.0, 4.0)) if k in twists_after else None,
        )
        for k, plane in enumerate(planes, start=1)
    )
    return Stack(name="straight", modules=modules, end_effector=platform, tool=(0.0, 0.0, tool))


@pytest.mark.parametrize("planes", [(0.0, 90.0, 0.0, 90.0), (0.0, 37.0, -120.0, 200.0, 90.0)])
def test_identical_modules_standing_symmetric_have_the_analytic_tip(planes):
    twists = {2: 0.07, len(planes): 0.11}
    stack = straight_stack(planes, twists, tool=0.04)
    model = StackModel(stack)
    rng = np.random.default_rng(133)
    b, d = 0.15, 0.10
    for s in rng.uniform(0.23, 0.35, size=3):
        height = math.sqrt(s**2 - (b - d) ** 2)  # each module a symmetric trapezoid
        p = math.hypot(b + d, height)
        psi = rng.uniform(-3.0, 3.0, size=len(twists))
        q = []
        turns = iter(psi)
        for module in stack.modules:
            q += [s, s, p] + ([next(turns)] if module.twist is not None else [])
        fk = model.forward_kinematics(np.array(q))
        expected = len(planes) * height + sum(twists.values()) + 0.04
        assert_close(fk.tip, [0.0, 0.0, expected], rtol=0, atol=1e-14, what="tip")
        c, s_ = math.cos(psi.sum()), math.sin(psi.sum())
        assert_close(fk.rotation, [[c, -s_, 0], [s_, c, 0], [0, 0, 1]], rtol=0, atol=1e-14, what="Rz(sum psi)")
        assert_close(fk.passive[:, 3], np.zeros(len(planes)), rtol=0, atol=1e-14, what="platform tilts")


# -- the six-module arm: physics identities --------------------------------------------------


@pytest.fixture(scope="module")
def six() -> StackModel:
    return StackModel(load_stack(EXAMPLES / "six_modules.toml"))


@pytest.fixture(scope="module")
def six_identities(six) -> ca.Function:
    """The second route, by automatic differentiation of the energies and of ``M`` alone:
    ``d2T/dqd2``, ``dV/dq`` and the Lagrange velocity products ``Mdot qd - 1/2 d/dq (qd' M qd)``."""
    stack = six.stack
    q, qd = ca.SX.sym("q", stack.n_joints), ca.SX.sym("qd", stack.n_joints)
    p = ca.SX.sym("p", stack.n_parameters)
    dyn = stack_dynamics(stack, q, qd, p)
    lagrange = ca.jtimes(dyn.M, q, qd) @ qd - 0.5 * ca.gradient(qd.T @ dyn.M @ qd, q)
    outputs = [ca.hessian(dyn.kinetic_energy, qd)[0], ca.gradient(dyn.potential_energy, q), lagrange]
    return ca.Function("identities", [q, qd, p], outputs)


def test_six_modules_mass_matrix_is_spd_and_the_hessian_of_kinetic_energy(six, six_identities):
    stack = six.stack
    rng = np.random.default_rng(134)
    for q in stack_configurations(stack, 5, seed=134):
        M = six.mass_matrix(q)
        assert M.shape == (stack.n_joints, stack.n_joints) == (21, 21)
        assert_close(M, M.T, rtol=0, atol=1e-14, what="symmetry")
        assert np.linalg.eigvalsh(M)[0] > 0
        qd = rng.normal(size=stack.n_joints)
        hessian, gradient, lagrange = (np.asarray(x) for x in six_identities(q, qd, stack.vector()))
        assert_close(M, hessian, rtol=1e-12, atol=1e-14, what="d2T/dqd2")
        assert_close(six.gravity_forces(q), gradient.ravel(), rtol=1e-12, atol=1e-12, what="dV/dq")
        velocity_products = six.bias_forces(q, qd) - six.gravity_forces(q) - stack.viscous * qd
        assert_close(velocity_products, lagrange.ravel(), rtol=1e-10, atol=1e-10, what="Lagrange C")
        kinetic, _ = six.energy(q, qd)
        assert kinetic == pytest.approx(0.5 * qd @ M @ qd, rel=1e-12)


def test_six_modules_jacobians_match_finite_differences(six):
    q = stack_configurations(six.stack, 2, seed=135, margin=0.02)
    fd = central_difference(lambda x: np.array([six.tip_position(row) for row in x]), q)
    J_P = np.array([six.jacobians(row)[0] for row in q])
    assert_close(J_P, fd, rtol=1e-7, atol=1e-9, what="J_P against central differences")


def test_six_modules_inverse_dynamics_undoes_forward_dynamics(six):
    rng = np.random.default_rng(136)
    n = six.n
    for q in stack_configurations(six.stack, 4, seed=136):
        qd, F = rng.normal(scale=0.1, size=n), rng.normal(scale=30.0, size=n)
        f_tip, m_tip = rng.normal(scale=10.0, size=3), rng.normal(scale=1.0, size=3)
        qdd = six.forward_dynamics(q, qd, F, f_tip, m_tip)
        assert_close(six.inverse_dynamics(q, qd, qdd, f_tip, m_tip), F, rtol=1e-10, atol=1e-9, what="id(fd(F))")


def test_six_modules_power_balance_along_a_simulated_motion(six):
    """``d/dt (T + V) = qd . (F - D qd)`` integrated along 0.2 s of motion under constant efforts
    (gravity compensation at home plus a seeded push; legs move by millimetres)."""
    stack, n = six.stack, six.n
    rng = np.random.default_rng(137)
    q0 = stack.home
    leg = np.array(stack.joint_units) == "m"
    qd0 = rng.normal(size=n) * np.where(leg, 0.02, 0.3)  # m/s, rad/s
    F = six.gravity_forces(q0) + rng.normal(size=n) * np.where(leg, 2.0, 0.005)  # N, N m
    D = stack.viscous

    def rates(_: float, y: np.ndarray) -> np.ndarray:
        q, qd = y[:n], y[n : 2 * n]
        return np.concatenate([qd, six.forward_dynamics(q, qd, F), [qd @ (F - D * qd)]])

    done = solve_ivp(rates, (0.0, 0.2), np.concatenate([q0, qd0, [0.0]]), method="DOP853", rtol=1e-11, atol=1e-13)
    assert done.success, done.message
    q1, qd1, work = done.y[:n, -1], done.y[n : 2 * n, -1], done.y[-1, -1]
    assert np.abs(q1 - q0)[leg].max() > 5e-3  # the legs moved by millimetres
    assert (stack_margins(stack, done.y[:n].T) > 0.0).all()
    energy = [sum(six.energy(q, qd)) for q, qd in ((q0, qd0), (q1, qd1))]
    assert abs(work) > 0.1  # J
    assert energy[1] - energy[0] == pytest.approx(work, rel=1e-8, abs=1e-10)


# -- refusals ----------------------------------------------------------------------------------


def paper_dict() -> dict[str, Any]:
    return tomllib.loads((EXAMPLES / "paper_robot.toml").read_text())


def _set(path: tuple[Any, ...], value: Any) -> dict[str, Any]:
    data = paper_dict()
    target: Any = data
    for key in path[:-1]:
        target = target[key]
    if value is KeyError:
        del target[path[-1]]
    else:
        target[path[-1]] = value
    return data


@pytest.mark.parametrize(
    ("path", "value", "named"),
    [
        (("modules",), [], "field 'modules' = []: expected at least one module"),
        (("modules",), KeyError, "missing key 'modules'"),
        (("modules",), {"b": 1}, "field 'modules'"),
        (("modules", 1, "d"), 0.15, "field 'module2.d' = 0.15: expected d < b = 0.15"),
        (("modules", 0, "d"), 0.2, "field 'module1.d' = 0.2: expected d < b"),
        (("modules", 1, "plane"), math.nan, "field 'module2.plane' = nan: expected a number in [-360, 360] (degrees)"),
        (("modules", 0, "plane"), "90", "field 'module1.plane' = '90': expected a number"),
        (("modules", 0, "plane"), math.inf, "field 'module1.plane' = inf"),
        (
            ("modules", 0, "limits", "s"),
            [0.36, 0.22],
            "field 'module1.limits.s' = (0.36, 0.22): expected [min, max] with min < max",
        ),
        (("modules", 1, "limits", "p"), [0.3], "field 'module2.limits.p' = [0.3]: expected [min, max]"),
        (("modules", 1, "twist", "limits"), [1.0, -1.0], "field 'module2.twist.limits'"),
        (("modules", 1, "twist", "height"), -0.1, "field 'module2.twist.height' = -0.1"),
        (("modules", 0, "home"), [0.22, 0.36, 0.46], "field 'module1.home'"),
        (("modules", 1, "home"), [0.3, 0.3, 0.5], "field 'module2.home[2] (p)' = 0.5"),
        (
            ("modules", 1, "platform"),
            {"mass": -1.0, "com": [0, 0, 0], "inertia": [[1, 0, 0], [0, 1, 0], [0, 0, 1]]},
            "field 'module2.platform.mass' = -1.0",
        ),
        (("modules", 0, "viscous"), [1.0, -1.0, 0.0], "field 'module1.viscous'"),
        (("modules", 0, "wings"), 2, "unknown key 'module1.wings'"),
        (("end_effector", "tool"), [0, 0, math.nan], "field 'end_effector.tool'"),
    ],
)
def test_bad_stacks_are_refused_with_one_line_naming_module_and_field(path, value, named):
    with pytest.raises(ConfigError) as caught:
        stack_from_dict(_set(path, value), source="bad.toml")
    message = str(caught.value)
    assert "\n" not in message
    assert message.startswith("bad.toml: ")
    assert named in message, message


def test_a_stack_built_directly_is_checked_too():
    stack = load_stack(EXAMPLES / "paper_robot.toml")
    with pytest.raises(ConfigError, match=r"field 'module2\.plane' = nan"):
        replace(stack, modules=(stack.modules[0], replace(stack.modules[1], plane=math.nan)))
    with pytest.raises(ConfigError, match="field 'modules' = \\(\\): expected at least one module"):
        replace(stack, modules=())


def test_the_model_refuses_bad_configurations(planar):
    with pytest.raises(InputError, match=r"q must have shape \(\.\.\., 3\), got shape \(7,\)"):
        planar.tip_position(np.zeros(7))
    with pytest.raises(InputError, match=r"q\[1\] \(v1\) = nan"):
        planar.tip_position([0.3, math.nan, 0.4])
    with pytest.raises(AssemblyError, match="module 1 cannot be assembled: 's \\+ 2d > p'"):
        planar.tip_position([0.22, 0.36, 0.46])


@pytest.mark.parametrize(
    ("value", "message"),
    [
        (lambda n: [None] * n, r"q\[0\] \(s1\) = None is not a number"),
        (lambda n: np.full(n, 0.3 + 0j), "complex"),
        (lambda n: ["0.3"] * n, "'0.3'"),
    ],
)
def test_the_interpreted_stack_model_refuses_what_is_not_a_real_number(planar, value, message):
    """The second algorithm refuses the inputs the Robot refuses, naming the user's own value
    (it used to turn None into nan and drop an imaginary part)."""
    with pytest.raises(InputError, match=message):
        planar.tip_position(value(planar.n))
