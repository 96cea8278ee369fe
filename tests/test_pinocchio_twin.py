"""The Pinocchio twin of the truss (benchmarks/pinocchio_twin.py, issue 35 item 5) against our model.

The twin is the truss as a multibody system (each leg a revolute and a prismatic joint, the loops
closed by 3-D point constraints) built from the robot's parameters; Pinocchio's
``constraintDynamics`` on it knows nothing of our closed-form modules or our virtual-work dynamics,
so its agreement checks both. Our state maps onto the twin's through our passive angles and the
twin's own constraints (the passive rates), which are checked here too.
"""

from __future__ import annotations

import numpy as np
import pytest

import vgtarm
from vgtarm.model.robot import recursive_robot
from vgtarm.model.stack.description import LEG_NAMES

from .conftest import random_configurations
from .test_recursive import relative, states, varied_stack

pin = pytest.importorskip(
    "pinocchio", reason="Pinocchio is optional (PyPI `pin`): pip install 'vgtarm[bench]' to run these"
)

from benchmarks.pinocchio_twin import FASTEST, Twin, build_twin  # noqa: E402

#: States of the paper robot checked (each a few ms).
N_STATES = 12


@pytest.fixture(scope="module")
def paper() -> vgtarm.Robot:
    return vgtarm.load_robot()


@pytest.fixture(scope="module")
def twin(paper: vgtarm.Robot) -> Twin:
    return build_twin(paper.parameters)


def _paper_states(robot: vgtarm.Robot) -> list[tuple[np.ndarray, ...]]:
    rng = np.random.default_rng(35)
    n = robot.n_joints
    return [
        (q, rng.normal(scale=0.3, size=n), rng.normal(scale=20.0, size=n), rng.normal(scale=5.0, size=3))
        for q in random_configurations(robot, N_STATES, seed=35, margin=0.002)
    ]


def test_twin_has_the_robot_s_shape_and_mass(paper: vgtarm.Robot, twin: Twin) -> None:
    n_modules = len(paper.parameters.modules)
    assert twin.n_joints == paper.n_joints
    legs = len(LEG_NAMES)
    # a revolute and a prismatic joint per leg, the platform's joint; then the twists
    assert twin.model.nv == (2 * legs + 1) * n_modules + (paper.n_joints - legs * n_modules)
    assert len(twin.constraints) == 2 * n_modules
    assert all(c.type == pin.ContactType.CONTACT_3D for c in twin.constraints)
    assert pin.computeTotalMass(twin.model) == pytest.approx(paper.parameters.total_mass, rel=1e-14)


def test_twin_dynamics_equal_ours(paper: vgtarm.Robot, twin: Twin) -> None:
    """Tip, and accelerations of our joints under efforts, friction, gravity and a tip force."""
    for q, qd, F, f in _paper_states(paper):
        fk = paper.forward_kinematics(q)
        x = twin.configuration(q, fk.passive)
        np.testing.assert_allclose(twin.tip(x), fk.tip, rtol=0, atol=1e-14)
        theirs = twin.accelerations(q, qd, F, fk.passive, f)
        ours = paper.forward_dynamics(q, qd, F, f)
        # our compiled forward dynamics is a symbolic solve (CasADi's QR of M): 2e-10 from LAPACK's
        # at the worst conditioned states near the assembly boundary (cond M 2e5)
        assert relative(theirs[None], ours[None]) < 1e-8
        # against LAPACK's solve of our M, C and J_P: measured within 1.5e-14 (1,000 states), and
        # 2.3e-12 with the benchmark's one proximal iteration
        M, C, J = paper.mass_matrix(q), paper.bias_forces(q, qd), paper.tip_jacobian(q)
        exact = np.linalg.solve(M, F + J.T @ f - C)
        assert relative(theirs[None], exact[None]) < 1e-13
        fastest = twin.accelerations(q, qd, F, fk.passive, f, proximal=FASTEST)
        assert relative(fastest[None], exact[None]) < 1e-11


def test_twin_velocity_solves_its_loops(paper: vgtarm.Robot, twin: Twin) -> None:
    """The passive rates solve the constraints and are the derivatives of our passive angles."""
    h = 1e-6
    for q, qd, _, _ in _paper_states(paper)[:4]:
        x = twin.configuration(q, paper.forward_kinematics(q).passive)
        v = twin.velocity(x, qd)
        assert np.abs(twin.constraint_jacobian(x) @ v).max() < 1e-12
        ahead = twin.configuration(q + h * qd, paper.forward_kinematics(q + h * qd).passive)
        behind = twin.configuration(q - h * qd, paper.forward_kinematics(q - h * qd).passive)
        np.testing.assert_allclose(v, (ahead - behind) / (2 * h), rtol=0, atol=1e-7)


def test_twin_of_other_stacks_equals_the_recursive_model() -> None:
    """Planes at 0, 90, 30 degrees, twists with and without bodies, a tool offset, tilted gravity."""
    stack = varied_stack(3)
    robot = recursive_robot(stack)
    twin = build_twin(stack)
    s = states(stack, 4, seed=3)
    for i in range(4):
        fk = robot.forward_kinematics(s["q"][i])
        x = twin.configuration(s["q"][i], fk.passive)
        np.testing.assert_allclose(twin.tip(x), fk.tip, rtol=0, atol=1e-14)
        theirs = twin.accelerations(s["q"][i], s["qd"][i], s["F"][i], fk.passive, s["f"][i])
        ours = robot.forward_dynamics(s["q"][i], s["qd"][i], s["F"][i], s["f"][i])
        assert relative(theirs[None], ours[None]) < 1e-12
