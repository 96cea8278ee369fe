"""The recursive model of a stack (issue 24) against today's symbolic stack model, and identities.

- stacks of 1 to 6 modules of every kind (plane angles that are and are not multiples of 90
  degrees, twists with and without bodies, off-centre bodies, a tool offset, tilted gravity,
  friction) and ``examples/six_modules.toml``: forward kinematics, both Jacobians, ``M``, ``C``,
  inverse and forward dynamics with a tip force and moment equal the symbolic model's (CasADi,
  virtual work) to 1e-10 relative, on 1,000 random states each;
- the compiled symbolic libraries already in the cache (one module, the paper's robot as a stack,
  the six-module arm) through :class:`~vgtarm.Robot`, batches of 1,000;
- identities on stacks up to the 50-module maximum: ``M`` symmetric positive definite, inverse
  dynamics undoes forward dynamics, the mass matrix of composite rigid bodies is the inverse of
  the articulated-body algorithm's columns, Jacobians are central differences of the kinematics;
- a second arm compiles nothing; bad input is refused with one line.
"""

from __future__ import annotations

import math
import os
import shutil
from collections.abc import Callable
from functools import partial
from pathlib import Path

import numpy as np
import pytest

from vgtarm.errors import AssemblyError, InputError
from vgtarm.model import compiled
from vgtarm.model.definition import StackDefinition
from vgtarm.model.parameters import Body
from vgtarm.model.recursive import RecursiveModel, library, stack_from_vector
from vgtarm.model.robot import recursive_robot
from vgtarm.model.stack import Stack, StackModel, StackModule, Twist, load_stack, stack_margins

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
TOLERANCE = 1e-10
STATES = 1000


def configurations(stack: Stack, n: int, seed: int, margin: float = 0.005) -> np.ndarray:
    """``n`` configurations uniform inside the limits, every module assemblable with ``margin`` (m)."""
    rng = np.random.default_rng(seed)
    chosen: list[np.ndarray] = []
    while sum(len(c) for c in chosen) < n:
        q = rng.uniform(stack.lower, stack.upper, size=(4 * n, stack.n_joints))
        chosen.append(q[(stack_margins(stack, q) > margin).all(axis=(-2, -1))])
    return np.concatenate(chosen)[:n]


def states(stack: Stack, n: int, seed: int) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed + 1)
    shape = (n, stack.n_joints)
    return {
        "q": configurations(stack, n, seed),
        "qd": rng.normal(scale=0.5, size=shape),
        "qdd": rng.normal(scale=2.0, size=shape),
        "F": rng.normal(scale=50.0, size=shape),
        "f": rng.normal(scale=20.0, size=(n, 3)),
        "m": rng.normal(scale=2.0, size=(n, 3)),
    }


def relative(actual: np.ndarray, desired: np.ndarray) -> float:
    """The largest difference of each sample over the largest magnitude of its reference, worst sample."""
    axes = tuple(range(1, np.ndim(desired)))
    error = np.abs(actual - desired).max(axis=axes)
    scale = np.maximum(np.abs(desired).max(axis=axes), 1e-300)
    return float((error / scale).max())


def body(mass: float, com: tuple[float, float, float], diag: tuple[float, float, float], off: float = 0.0) -> Body:
    a, b, c = diag
    return Body("body", mass, com, ((a, off, 0.0), (off, b, -off), (0.0, -off, c)))


def module(b: float, d: float, plane: float, twist: Twist | None, mass: float) -> StackModule:
    # the paper's module scaled by b / 0.15 (its legs, limits and home)
    scale = b / 0.15
    home = tuple(x * scale for x in (0.2844292530665578, 0.2844292530665578, 0.3753664875824692))
    limits = tuple((lo * scale, hi * scale) for lo, hi in ((0.22, 0.36), (0.22, 0.36), (0.30, 0.46)))
    return StackModule(
        b=b,
        d=d,
        plane=plane,
        limits=limits,  # type: ignore[arg-type]
        home=home,  # type: ignore[arg-type]
        platform=body(mass, (0.01, -0.02, 0.015), (0.02 * mass, 0.018 * mass, 0.03 * mass), 1e-3),
        viscous=(200.0, 150.0, 100.0),
        twist=twist,
    )


STAGE = Twist(height=0.06, limits=(-3.2, 3.2), viscous=0.5, body=body(0.5, (0.002, 0.001, 0.03), (5e-4, 4e-4, 6e-4)))
BARE = Twist(height=0.1, limits=(-3.2, 3.2), viscous=0.0)


def varied_stack(k: int) -> Stack:
    """``k`` modules of tapering size; planes 0, 90, 30, -135, 210, 45 degrees; twists with a body
    after every second module, a bare twist (the tool's) after the last when ``k`` is odd."""
    planes = (0.0, 90.0, 30.0, -135.0, 210.0, 45.0)
    modules = []
    for i in range(k):
        twist = STAGE if i % 2 == 1 else (BARE if i == k - 1 else None)
        b = 0.15 * (1.0 - 0.08 * i)
        modules.append(module(b, 0.10 * (1.0 - 0.08 * i), planes[i], twist, 2.75 - 0.3 * i))
    return Stack(
        name=f"varied {k}",
        modules=tuple(modules),
        end_effector=body(0.75, (0.01, 0.005, 0.05), (2e-3, 2.5e-3, 1e-3), 2e-4),
        tool=(0.01, -0.02, 0.03),
        gravity=(0.3, -0.5, -9.81),
    )


def symbolic_batch(stack: Stack, s: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Today's symbolic stack model (:class:`StackModel`'s CasADi functions, the interpreter),
    mapped over the samples; forward dynamics by Cholesky as :meth:`StackModel.forward_dynamics`."""
    model = StackModel(stack)
    p = stack.vector()
    n, count = stack.n_joints, len(s["q"])
    q, qd = s["q"].T, s["qd"].T
    fk = model._fk.map(count)(q, p)
    jp, jw = (np.asarray(x).T.reshape(count, n, 3).transpose(0, 2, 1) for x in model._jac.map(count)(q, p))
    M, C, _, _ = (np.asarray(x) for x in model._dynamics.map(count)(q, qd, p))
    M = M.T.reshape(count, n, n).transpose(0, 2, 1)
    C = C.T
    wrench = np.einsum("sij,si->sj", jp, s["f"]) + np.einsum("sij,si->sj", jw, s["m"])
    rhs = s["F"] + wrench - C
    L = np.linalg.cholesky(M)
    y = np.linalg.solve(L, rhs[..., None])
    fd = np.linalg.solve(np.swapaxes(L, 1, 2), y)[..., 0]
    m = stack.n_modules
    return {
        "passive": np.asarray(fk[0]).T.reshape(count, m, 4),
        "platform_position": np.asarray(fk[1]).T.reshape(count, m, 3),
        "platform_rotation": np.asarray(fk[2]).T.reshape(count, m, 3, 3),
        "tip": np.asarray(fk[3]).T,
        "rotation": np.asarray(fk[4]).T.reshape(count, 3, 3),
        "J_P": jp,
        "J_W": jw,
        "M": M,
        "C": C,
        "id": np.einsum("sij,sj->si", M, s["qdd"]) + C - wrench,
        "fd": fd,
    }


def recursive_batch(model: RecursiveModel, s: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    out = model.forward_kinematics(s["q"])
    out["J_P"], out["J_W"] = model.jacobians(s["q"])
    out["M"] = model.mass_matrix(s["q"])
    out["C"] = model.bias_forces(s["q"], s["qd"])
    out["id"] = model.inverse_dynamics(s["q"], s["qd"], s["qdd"], s["f"], s["m"])
    out["fd"] = model.forward_dynamics(s["q"], s["qd"], s["F"], s["f"], s["m"])
    return out


STACKS: dict[str, Callable[[], Stack]] = {f"varied{k}": partial(varied_stack, k) for k in range(1, 7)}
STACKS["six_modules.toml"] = partial(load_stack, EXAMPLES / "six_modules.toml")
STACKS["paper_robot.toml"] = partial(load_stack, EXAMPLES / "paper_robot.toml")


@pytest.mark.parametrize("name", sorted(STACKS))
def test_equal_to_the_symbolic_stack_model_on_random_states(name):
    stack = STACKS[name]()
    s = states(stack, STATES, seed=len(name))
    want = symbolic_batch(stack, s)
    got = recursive_batch(RecursiveModel(stack), s)
    errors = {key: relative(got[key], want[key]) for key in want}
    assert max(errors.values()) <= TOLERANCE, errors
    # the twist parts' frames: the platform's position, turned by the twist about its normal
    model = RecursiveModel(stack)
    twists = [i for i, unit in enumerate(stack.joint_units) if unit == "rad"]
    twist_bodies = [b for b in range(model.n_bodies) if b not in model.module_bodies]
    for joint, b in zip(twists, twist_bodies, strict=True):
        c, s_ = np.cos(s["q"][:, joint]), np.sin(s["q"][:, joint])
        rz = np.zeros((len(c), 3, 3))
        rz[:, 0, 0], rz[:, 0, 1], rz[:, 1, 0], rz[:, 1, 1], rz[:, 2, 2] = c, -s_, s_, c, 1.0
        assert np.allclose(got["body_rotation"][:, b], got["body_rotation"][:, b - 1] @ rz, atol=1e-14)
        assert np.array_equal(got["body_position"][:, b], got["body_position"][:, b - 1])


CACHED = ["planar_module.toml", "paper_robot.toml", "six_modules.toml"]


@pytest.mark.parametrize("name", CACHED)
def test_equal_to_the_compiled_symbolic_library(name):
    """Through the Robot API (the compiled library of the cache; skipped when it is not built)."""
    import vgtarm

    stack = load_stack(EXAMPLES / name)
    if compiled.find_compiler() is None or not compiled.library_cached(StackDefinition.of(stack)):
        pytest.skip(f"the compiled symbolic library of {name} is not in the cache (building it takes minutes)")
    robot = vgtarm.load_robot(EXAMPLES / name)
    model = RecursiveModel(stack)
    s = states(stack, STATES, seed=7)
    q, qd = s["q"], s["qd"]
    fk = robot.forward_kinematics(q)
    got = model.forward_kinematics(q)
    assert relative(got["tip"], fk.tip) <= TOLERANCE
    jp, jw = model.jacobians(q)
    assert relative(jp, robot.tip_jacobian(q)) <= TOLERANCE
    assert relative(jw, robot.angular_jacobian(q)) <= TOLERANCE
    assert relative(model.mass_matrix(q), robot.mass_matrix(q)) <= TOLERANCE
    assert relative(model.bias_forces(q, qd), robot.bias_forces(q, qd)) <= TOLERANCE
    assert (
        relative(model.inverse_dynamics(q, qd, s["qdd"], s["f"]), robot.inverse_dynamics(q, qd, s["qdd"], s["f"]))
        <= TOLERANCE
    )
    # forward dynamics: the library's own is a symbolic solve (CasADi's QR of M), which on the
    # six-module arm (cond M up to 4e6) lies 5e-10 from LAPACK's solve of the library's own M, C and
    # J_P; the articulated-body result lies within 1e-10 of LAPACK's, and its residual in the
    # library's equations is as small as the library's own solve's.
    M, C, jp = robot.mass_matrix(q), robot.bias_forces(q, qd), robot.tip_jacobian(q)
    rhs = s["F"] + np.einsum("sij,si->sj", jp, s["f"]) - C
    solved = np.linalg.solve(M, rhs[..., None])[..., 0]
    qdd = model.forward_dynamics(q, qd, s["F"], s["f"])
    assert relative(qdd, solved) <= TOLERANCE
    library_qdd = robot.forward_dynamics(q, qd, s["F"], s["f"])
    residual = relative(np.einsum("sij,sj->si", M, qdd), rhs)
    assert residual <= max(1e-12, 2 * relative(np.einsum("sij,sj->si", M, library_qdd), rhs))


# -- identities, up to the largest stack ------------------------------------------------------


def long_stack(k: int) -> Stack:
    """``k`` modules (up to the 50 of MAX_MODULES) at planes 0, 90, 37, ... with varied twists."""
    modules = []
    for i in range(k):
        twist = STAGE if i % 3 == 2 else (BARE if i == k - 1 else None)
        modules.append(module(0.15, 0.10, (0.0, 90.0, 37.0)[i % 3], twist, 1.0 + 0.1 * (i % 4)))
    return Stack(
        name=f"long {k}", modules=tuple(modules), end_effector=body(0.5, (0.0, 0.01, 0.04), (1e-3, 1e-3, 5e-4))
    )


@pytest.mark.parametrize("k", [1, 3, 10, 50])
def test_identities_of_the_recursive_algorithms(k):
    stack = long_stack(k)
    model = RecursiveModel(stack)
    n = stack.n_joints
    s = states(stack, 50 if k < 50 else 10, seed=k)
    M = model.mass_matrix(s["q"])
    assert np.array_equal(M, np.swapaxes(M, 1, 2))
    assert (np.linalg.eigvalsh(M)[:, 0] > 0.0).all()
    # inverse dynamics undoes forward dynamics (tip force and moment, gravity, friction)
    qdd = model.forward_dynamics(s["q"], s["qd"], s["F"], s["f"], s["m"])
    F = model.inverse_dynamics(s["q"], s["qd"], qdd, s["f"], s["m"])
    assert relative(F, s["F"]) <= 1e-9
    # ID is M qdd + C - J^T w, with M from composite rigid bodies and C the ID at qdd = 0
    jp, jw = model.jacobians(s["q"])
    C = model.bias_forces(s["q"], s["qd"])
    wrench = np.einsum("sij,si->sj", jp, s["f"]) + np.einsum("sij,si->sj", jw, s["m"])
    expected = np.einsum("sij,sj->si", M, s["qdd"]) + C - wrench
    got = model.inverse_dynamics(s["q"], s["qd"], s["qdd"], s["f"], s["m"])
    assert relative(got, expected) <= 1e-10
    # composite rigid bodies M = inverse of the articulated-body columns (no gravity, at rest)
    inertial = model.with_gravity((0.0, 0.0, 0.0))
    for q in s["q"][:3]:
        columns = inertial.forward_dynamics(np.repeat(q[None], n, 0), np.zeros((n, n)), np.eye(n)).T
        assert relative(columns @ model.mass_matrix(q), np.eye(n)) <= 1e-9


def test_jacobians_are_central_differences_of_the_kinematics():
    stack = varied_stack(5)
    model = RecursiveModel(stack)
    q = configurations(stack, 5, seed=3)
    h = 1e-6
    for x in q:
        jp, jw = model.jacobians(x)
        rotation = model.forward_kinematics(x)["rotation"]
        for j in range(stack.n_joints):
            e = np.zeros(stack.n_joints)
            e[j] = h
            up, down = model.forward_kinematics(x + e), model.forward_kinematics(x - e)
            assert np.allclose((up["tip"] - down["tip"]) / (2 * h), jp[:, j], atol=1e-7)
            dR = (up["rotation"] - down["rotation"]) / (2 * h)
            W = dR @ rotation.T
            omega = 0.5 * np.array([W[2, 1] - W[1, 2], W[0, 2] - W[2, 0], W[1, 0] - W[0, 1]])
            assert np.allclose(omega, jw[:, j], atol=1e-7)


def test_the_energy_balance_of_forward_dynamics():
    """The power of gravity and of the efforts: d/dt (qd' M qd / 2) = qd' (F - C) + qd'(Mdot qd / 2)...
    checked as Lagrange's identity C(q, qd) - C(q, 0) = Mdot qd - 1/2 d/dq (qd' M qd) + D qd."""
    stack = varied_stack(4)
    model = RecursiveModel(stack)
    q = configurations(stack, 3, seed=5)
    rng = np.random.default_rng(5)
    h = 1e-6
    D = stack.viscous
    for x in q:
        qd = rng.normal(size=stack.n_joints)
        Mdot = (model.mass_matrix(x + h * qd) - model.mass_matrix(x - h * qd)) / (2 * h)
        grad = np.array(
            [
                (qd @ model.mass_matrix(x + h * e) @ qd - qd @ model.mass_matrix(x - h * e) @ qd) / (2 * h)
                for e in np.eye(stack.n_joints)
            ]
        )
        lagrange = Mdot @ qd - 0.5 * grad + D * qd
        velocity_terms = model.bias_forces(x, qd) - model.bias_forces(x, np.zeros(stack.n_joints))
        assert np.allclose(velocity_terms, lagrange, rtol=1e-6, atol=1e-6 * np.abs(lagrange).max())


# -- the library: once for every arm ----------------------------------------------------------


def test_a_second_arm_compiles_nothing(monkeypatch):
    RecursiveModel(varied_stack(2))  # the library exists (built now if it did not)
    library.load_library.cache_clear()

    def refuse(*args, **kwargs):
        raise AssertionError("the recursive library was compiled again")

    monkeypatch.setattr(library, "_compile", refuse)
    model = RecursiveModel(long_stack(50))  # another arm, other module types, loaded from the cache
    assert model.n == long_stack(50).n_joints
    library.load_library.cache_clear()


def test_the_cache_key_follows_the_sources_and_the_compiler(monkeypatch, tmp_path):
    assert library.cache_key("cc") == library.cache_key("cc")
    assert library.cache_key("cc") != library.cache_key("clang")
    sources = library._sources()
    names = {p.relative_to(library._HERE.parent).as_posix() for p in sources}
    # the generated module functions come from joint.py and the model's symbolic.py (solve_module)
    assert {"recursive/joint.py", "symbolic.py", "recursive/library.py", "recursive/csrc/vgt_rec.c"} <= names
    assert "recursive/csrc/vgt_rec.h" in names and "recursive/model.py" not in names
    changed = tmp_path / "symbolic.py"
    changed.write_text((library._HERE.parent / "symbolic.py").read_text() + "\n# changed\n")
    key = library.cache_key("cc")
    monkeypatch.setattr(library, "_sources", lambda: [changed if p.name == "symbolic.py" else p for p in sources])
    assert library.cache_key("cc") != key


# -- bad input --------------------------------------------------------------------------------


def test_bad_input_is_refused_with_one_line():
    stack = varied_stack(2)
    model = RecursiveModel(stack)
    n = stack.n_joints
    q = stack.home
    with pytest.raises(InputError, match=r"q must have shape .*7.*got shape \(8,\)"):
        model.mass_matrix(np.zeros(n + 1))
    bad = q.copy()
    bad[2] = math.nan
    with pytest.raises(InputError, match=r"q must be finite; q\[0, 2\] = nan"):
        model.mass_matrix(bad)
    broken = np.array([q, q])
    broken[1, 4] = 0.05  # v2 far too short for its diagonal
    with pytest.raises(AssemblyError, match=r"q\[1\]: module 2 cannot be assembled"):
        model.forward_dynamics(broken, np.zeros((2, n)), np.zeros((2, n)))
    with pytest.raises(InputError, match="batches differ"):
        model.forward_dynamics(broken[:1], np.zeros((2, n)), np.zeros((2, n)))
    with pytest.raises(InputError, match="f_tip"):
        model.forward_dynamics(q, np.zeros(n), np.zeros(n), f_tip=[1.0, 2.0])
    with pytest.raises(InputError, match="expected a Stack"):
        RecursiveModel("six_modules.toml")


# -- the Robot on the recursive model ---------------------------------------------------------


@pytest.mark.parametrize("k", [1, 4, 6])
def test_the_parameter_vector_reads_back_into_the_same_stack(k):
    stack = varied_stack(k)
    back = stack_from_vector(stack, stack.vector())
    assert back.vector().tobytes() == stack.vector().tobytes()
    assert StackDefinition.of(back) == StackDefinition.of(stack)
    scaled = stack.scaled(mass=1.3, inertia=0.7, friction=2.0)
    assert stack_from_vector(stack, scaled.vector()).vector().tobytes() == scaled.vector().tobytes()


def test_a_robot_on_the_recursive_model_is_the_symbolic_robot():
    """Robot(stack, RecursiveBackend(stack)) against the Robot of the symbolic model (its compiled
    library when cached, else CasADi's interpreter), with the Robot's own checks, and with other
    parameters through with_parameters."""
    import vgtarm
    from vgtarm.model.compiled import InterpretedBackend, functions_of

    stack = varied_stack(3)
    definition = StackDefinition.of(stack)
    names = ["fk", "tip", "jac", "mass", "bias_forces", "fd", "id"]
    symbolic = vgtarm.Robot(stack, InterpretedBackend(functions_of(definition, names).functions))
    robot = recursive_robot(stack)
    assert robot.backend.kind == "recursive"
    s = states(stack, 40, seed=11)
    q, qd = s["q"], s["qd"]
    for other in (stack, stack.scaled(mass=1.4, friction=0.5)):
        a, b = robot.with_parameters(other), symbolic.with_parameters(other)
        assert (
            relative(a.forward_kinematics(q).platform_rotation, b.forward_kinematics(q).platform_rotation) <= TOLERANCE
        )
        assert relative(a.tip_position(q), b.tip_position(q)) <= TOLERANCE
        assert relative(a.tip_jacobian(q), b.tip_jacobian(q)) <= TOLERANCE
        assert relative(a.angular_jacobian(q), b.angular_jacobian(q)) <= TOLERANCE
        assert relative(a.mass_matrix(q), b.mass_matrix(q)) <= TOLERANCE
        assert relative(a.bias_forces(q, qd), b.bias_forces(q, qd)) <= TOLERANCE
        assert (
            relative(a.inverse_dynamics(q, qd, s["qdd"], s["f"]), b.inverse_dynamics(q, qd, s["qdd"], s["f"]))
            <= TOLERANCE
        )
        assert relative(a.forward_dynamics(q, qd, s["F"], s["f"]), b.forward_dynamics(q, qd, s["F"], s["f"])) <= 1e-9
    with pytest.raises(InputError, match="no compiled function named 'ik_pose'"):
        robot.evaluate("ik_pose", {}, 1)
    with pytest.raises(AssemblyError):
        robot.mass_matrix(np.full(stack.n_joints, 0.01))


def test_a_fifty_module_robot_needs_no_compile():
    stack = long_stack(50)
    robot = recursive_robot(stack)
    q = configurations(stack, 3, seed=2)
    qdd = robot.forward_dynamics(q, np.zeros_like(q), np.zeros_like(q))
    assert np.isfinite(qdd).all()
    assert (
        np.abs(robot.inverse_dynamics(q, np.zeros_like(q), qdd)).max()
        <= 1e-8 * np.abs(robot.bias_forces(q, np.zeros_like(q))).max()
    )


def test_a_ten_module_arm_on_the_recursive_model_equals_mujoco():
    """The recursive model against MuJoCo on the exported MJCF (the bridge's cross-check) for an arm
        whose symbolic library takes minutes to build (planes 0, 90, 37 degrees, twists with and without
    bodies): 50 random states."""
    pytest.importorskip("mujoco")
    from vgtarm.mujoco_bridge.check import cross_validate
    from vgtarm.mujoco_bridge.export import MAX_DIGITS

    # every number of the MJCF as it is (the file `export mjcf` writes rounds to 11 digits)
    rows = cross_validate(recursive_robot(long_stack(10)), n=50, seed=3, digits=MAX_DIGITS)
    worst = {row.quantity: row.worst for row in rows}
    assert worst["tip position (m)"] <= 1e-13
    assert worst["mass matrix M (relative)"] <= 1e-10
    assert worst["bias forces C, moving (relative)"] <= 1e-10
    assert worst["forward dynamics moving, efforts and tip force (relative)"] <= 1e-9


def test_a_damaged_library_is_never_opened_and_is_rebuilt(tmp_path, monkeypatch):
    """The library is checked against its metadata (size, SHA-256) before it is opened: an intact
    entry is loaded as it is, an altered file is removed and built again, and a library without
    metadata is not trusted.

    The private cache starts with a copy of the user's entry (built once for the suite); the
    altered library is rebuilt by the real compile, the untrusted one by a copy of the intact
    library (what is checked there is that it is built again, not the compiler)."""
    compiler = compiled.find_compiler()
    if compiler is None:
        pytest.skip("no C compiler")
    library.load_library.cache_clear()
    library.load_library()  # the user's cache
    key = library.cache_key(compiler)
    pristine = compiled.cache_dir() / f"vgtarm_rec_{key}.so"
    folder = tmp_path / "cache"
    folder.mkdir(mode=0o700)
    for path in (pristine, pristine.with_suffix(".json")):
        shutil.copy2(path, folder / path.name)
    so, meta = folder / pristine.name, folder / pristine.with_suffix(".json").name
    monkeypatch.setenv("VGTARM_CACHE_DIR", str(folder))
    library.load_library.cache_clear()
    built: list[str] = []
    real = library._compile

    def compile_(given: str, workdir: Path) -> Path:
        if not built:
            built.append("compiled")
            return real(given, workdir)
        built.append("copied")
        shutil.copyfile(pristine, workdir / "library.so")
        return workdir / "library.so"

    monkeypatch.setattr(library, "_compile", compile_)
    try:
        library.load_library()
        assert built == [], "an intact entry is loaded as it is"
        good = so.read_bytes()
        altered = good[:-1] + bytes([good[-1] ^ 1])  # one bit changed
        (tmp_path / "altered.so").write_bytes(altered)  # a new file: the loaded one stays mapped intact
        os.replace(tmp_path / "altered.so", so)
        library.load_library.cache_clear()
        library.load_library()
        assert built == ["compiled"]
        assert so.read_bytes() != altered
        meta.unlink()  # no metadata: built again, never opened as it is
        library.load_library.cache_clear()
        library.load_library()
        assert built == ["compiled", "copied"] and meta.is_file()
    finally:
        library.load_library.cache_clear()


def test_load_robot_chooses_the_model(monkeypatch):
    import vgtarm
    from vgtarm.errors import ConfigError

    path = EXAMPLES / "planar_module.toml"
    assert vgtarm.load_robot(path, model="recursive").backend.kind == "recursive"
    monkeypatch.setenv("VGTARM_MODEL", "recursive")
    assert vgtarm.load_robot(path).backend.kind == "recursive"
    monkeypatch.setenv("VGTARM_MODEL", "fastest")
    with pytest.raises(ConfigError, match=r"\$VGTARM_MODEL = 'fastest': expected one of symbolic, recursive"):
        vgtarm.load_robot(path)
    monkeypatch.delenv("VGTARM_MODEL")
    with pytest.raises(ConfigError, match="model = 'x'"):
        vgtarm.load_robot(path, model="x")
    with pytest.raises(ConfigError, match="the paper's robot keeps its symbolic model"):
        vgtarm.load_robot(None, model="recursive")
    fifty = long_stack(50)
    with pytest.raises(InputError, match="expected a Stack"):
        recursive_robot(load_stack(EXAMPLES / "paper_robot.toml").modules)
    assert recursive_robot(fifty).n_joints == fifty.n_joints
