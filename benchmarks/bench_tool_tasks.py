"""Tool-task benchmark: the 5-D tool-axis and entry-point IK of case 1's tip path against IPOPT per sample.

The hardest case the tool tasks meet: case 1's whole path at 1 ms (6,284 samples) with the drill's
axis tilted by 10 degrees from the vertical (held), and the same path with the axis through an
entry point 0.2 m below the path's centre (an axis that turns with every sample). Baseline, in the
same run: IPOPT per sample on the same task and cost, written symbolically from the forward
kinematics (``solver="ipopt"``, each sample started from the previous one), too slow for the whole
path: timed on ``BLOCKS`` blocks of ``BLOCK`` samples spread along it, each started from the fast
solution of the sample before it, and scaled. Both include the exact rates and the verification.

Then the redundancy the axis task keeps, against the workaround a user had before it: the full
pose with the spin about the axis held at the axis solution's first value. On the paper robot with
its default tool the tool's axis is the twist's, so the spin is the twist joint alone and both give
the same joints; the comparison is made with a drill mounted at :data:`MOUNT` to the twist axis
(the paper robot's file with ``tool_axis`` and ``tool_edge`` turned about F3's ``y``), on case 1
and case 2 with the drill tilted about the base x and y axes. Reported: whether each solves, and
the smallest and the median (over samples) margin of the legs to their stroke limits (mm).

Then Robotics Toolbox's ``IK_LM`` (masked pose, :mod:`benchmarks.rtb_anchor`) on 50 vertical-axis
points against one batched call of vgtarm's axis task over the same points, when
``roboticstoolbox-python`` is installed (the ``bench`` extra).
"""

from __future__ import annotations

import numpy as np

import vgtarm
from vgtarm import paths
from vgtarm.ik import inverse_kinematics

from .common import Row, best_time, print_table

#: The angle of the drill mounted on the end-effector, from the twist axis (rad).
MOUNT = np.radians(30.0)
#: Tilts of the drill from the vertical in the margin comparison (deg), about the base axis named.
TILTS = ((0.0, "x"), (10.0, "x"), (20.0, "x"), (10.0, "y"), (20.0, "y"))

BLOCKS = 4
BLOCK = 100
#: The drill's tilt from the vertical (rad), about the base x axis.
TILT = np.radians(10.0)
#: How far below case 1's centre the entry point is (m).
ENTRY_DEPTH = 0.2


def axis_of_case() -> np.ndarray:
    """The tilted drill axis of the benchmark."""
    return np.array([0.0, -np.sin(TILT), np.cos(TILT)])


def entry_of_case(path: paths.TipPath) -> np.ndarray:
    """The entry point of the benchmark: :data:`ENTRY_DEPTH` below the path's centre."""
    return np.asarray(path.position.mean(axis=0) - np.array([0.0, 0.0, ENTRY_DEPTH]))


class _Solved:
    """What :func:`_ipopt_on_blocks` reads of a solve: its wall time and its per-sample cost."""

    def __init__(self, seconds: float, phi: np.ndarray) -> None:
        self.wall_time_s = seconds
        self.samples = type("Samples", (), {"phi": phi})()


def _ipopt_cone(robot: vgtarm.Robot, block: paths.TipPath, task: dict[str, object], q0: np.ndarray) -> _Solved:
    """IPOPT per sample on ``min Phi`` subject to the tip, ``d . a(q) >= cos(beta)`` (written from the
    FK), the joint limits and the assembly margin, each sample started from the previous one."""
    import time

    import casadi as ca

    from vgtarm.ik.problem import DEFAULT_MARGIN, IKProblem

    problem = IKProblem.from_parameters(robot.parameters)
    q = ca.SX.sym("q", robot.n_joints)
    fk = robot.definition.kinematics(q, ca.DM(robot.parameter_vector))
    point = ca.SX.sym("x", 3)
    d = np.asarray(task["axis"], dtype=float)
    along = ca.DM(d).T @ (fk.C03 @ ca.DM(robot.tool_rotation[:, 2]))
    G, h = robot.margin_form()
    g = ca.vertcat(fk.tip - point, along, ca.DM(G) @ q + ca.DM(h))
    cost = 0.5 * ca.sum1(ca.DM(problem.weight) * (q - ca.DM(problem.centre)) ** 2)
    settings = {"print_time": False, "ipopt.print_level": 0, "ipopt.sb": "yes", "ipopt.tol": 1e-12}
    settings["ipopt.bound_relax_factor"] = 0.0
    solver = ca.nlpsol("cone", "ipopt", {"x": q, "p": point, "f": cost, "g": g}, settings)
    bound = float(np.cos(float(task["cone"])))  # type: ignore[arg-type]
    lbg = np.concatenate([np.zeros(3), [bound], np.full(G.shape[0], DEFAULT_MARGIN)])
    ubg = np.concatenate([np.zeros(3), [1.0], np.full(G.shape[0], np.inf)])
    low, high = robot.joint_limits()
    started, phi, x = time.perf_counter(), [], q0
    for point_i in block.position:
        result = solver(x0=x, p=point_i, lbx=low, ubx=high, lbg=lbg, ubg=ubg)
        x = np.asarray(result["x"]).ravel()
        phi.append(float(result["f"]))
    return _Solved(time.perf_counter() - started, np.array(phi))


def _ipopt_on_blocks(robot: vgtarm.Robot, path: paths.TipPath, fast: object, **task: object) -> tuple[float, float]:
    """IPOPT's seconds per sample on the blocks, and the worst ``|Phi_fast - Phi_ipopt|`` there."""
    n = len(path)
    q = fast.q  # type: ignore[attr-defined]
    phi = fast.samples.phi  # type: ignore[attr-defined]
    seconds, worst, count = 0.0, 0.0, 0
    for s in np.linspace(1, n - BLOCK - 1, BLOCKS).astype(int):
        pieces = (path.t, path.position, path.velocity, path.acceleration, path.jerk)
        block = paths.TipPath("block", *(None if a is None else a[s : s + BLOCK] for a in pieces))
        sliced = {k: (v[s : s + BLOCK] if isinstance(v, np.ndarray) and v.ndim == 2 else v) for k, v in task.items()}
        if "cone" in sliced:  # IPOPT on the inequality itself: its rows written from the FK
            ref: object = _ipopt_cone(robot, block, task, q[s - 1])
        else:
            ref = inverse_kinematics(robot, block, solver="ipopt", initial_guess=q[s - 1], **sliced)
        seconds += ref.wall_time_s  # type: ignore[attr-defined]
        count += BLOCK
        worst = max(worst, float(np.abs(ref.samples.phi - phi[s : s + BLOCK]).max()))  # type: ignore[attr-defined]
    return seconds / count, worst


def run() -> list[Row]:
    robot = vgtarm.load_robot()
    path = paths.case1(dt=1e-3)
    n = len(path)
    rows, notes = [], []
    for label, task in (
        ("axis tilted 10 deg", {"axis": axis_of_case()}),
        ("axis through an entry point", {"entry_point": entry_of_case(path)}),
        ("axis tilted 10 deg, effort criterion", {"axis": axis_of_case(), "criterion": "effort", "tool_force": 20.0}),
        ("axis within 5 deg of the vertical", {"axis": np.array([0.0, 0.0, 1.0]), "cone": np.radians(5.0)}),
    ):
        fast = inverse_kinematics(robot, path, **task)
        seconds = best_time(lambda task=task: inverse_kinematics(robot, path, **task), repeat=5, min_time=0.3)
        per_sample, worst = _ipopt_on_blocks(robot, path, fast, **task)
        rows.append(
            Row(
                f"IK case 1 at 1 ms, {label}, fast solver + exact rates",
                seconds,
                "sample",
                n,
                f"IPOPT from the FK per sample (timed on {BLOCKS * BLOCK} samples, scaled)",
                per_sample * n,
                "whole path <= 150 ms, >= 100x",
            )
        )
        notes.append(
            f"{label}: {fast.message}; worst axis error {fast.samples.orientation_error.max():.2e} rad, worst tip "
            f"residual {fast.samples.residual.max():.2e} m; worst |Phi_fast - Phi_ipopt| on the blocks {worst:.2e}"
        )
    print_table(f"Tool tasks (case 1, {n:,} samples)", rows)
    for note in notes:
        print(note)
    margins()
    _robotics_toolbox()
    return rows


def mounted_drill() -> vgtarm.Robot:
    """The paper robot (``examples/paper_robot.toml``) with a drill mounted at :data:`MOUNT` from the twist axis."""
    import tomllib
    from pathlib import Path

    from vgtarm.model.robot import robot_from_dict

    source = Path(__file__).resolve().parents[1] / "examples" / "paper_robot.toml"
    data = tomllib.loads(source.read_text())
    s, c = float(np.sin(MOUNT)), float(np.cos(MOUNT))
    data["end_effector"].update(tool_axis=[s, 0.0, c], tool_edge=[c, 0.0, -s])
    return robot_from_dict(data, source="paper_robot.toml with a mounted drill")


def _leg_margins(robot: vgtarm.Robot, q: np.ndarray) -> tuple[float, float]:
    """The smallest and the median (over samples) margin of the legs to their limits (mm)."""
    low, high = robot.joint_limits()
    legs = np.array([unit == "m" for unit in robot.joint_units])
    margin = np.minimum(q - low, high - q)[:, legs].min(axis=1)
    return 1e3 * float(margin.min()), 1e3 * float(np.median(margin))


def margins() -> None:
    """The axis task against the full pose with the spin held, on the mounted drill (module docstring)."""
    robot = mounted_drill()
    mount = f"drill mounted {np.degrees(MOUNT):g} deg from the twist"
    print(f"\nAxis task against the full pose with the spin held ({mount})\n")
    print("| path | drill tilt | axis task: solved, leg margin min / median (mm) | full pose, spin held | Phi max |")
    print("| --- | --- | --- | --- | --- |")
    for name, path in (("case 1", paths.case1()), ("case 2", paths.case2())):
        for degrees, about in TILTS:
            t = np.radians(degrees)
            d = np.array([0.0, -np.sin(t), np.cos(t)]) if about == "x" else np.array([np.sin(t), 0.0, np.cos(t)])
            axis = inverse_kinematics(robot, path, axis=d, check=False)
            if not axis.success:
                print(f"| {name} | {degrees:g} deg about {about} | {axis.status}: {axis.message[:90]} | - | - |")
                continue
            held = robot.tool_frame(axis.q[0])[1] @ robot.tool_rotation.T  # C03 of the first sample
            pose = inverse_kinematics(robot, path, pose=held, check=False)
            low, mid = _leg_margins(robot, axis.q)
            other = f"{pose.status}: {pose.message[:60]}"
            phi = f"{axis.samples.phi.max():.4f} / -"
            if pose.success:
                low_p, mid_p = _leg_margins(robot, pose.q)
                other = f"solved, {low_p:.2f} / {mid_p:.2f}"
                phi = f"{axis.samples.phi.max():.4f} / {pose.samples.phi.max():.4f}"
            print(f"| {name} | {degrees:g} deg about {about} | solved, {low:.2f} / {mid:.2f} | {other} | {phi} |")


def _robotics_toolbox() -> None:
    """Robotics Toolbox's masked-pose LM on vertical-axis points, when it is installed."""
    try:
        from . import rtb_anchor
    except ImportError as missing:  # the bench extra is not installed
        print(f"Robotics Toolbox: not installed ({missing}); pip install 'vgtarm[bench]'")
        return
    rtb_anchor.run()


if __name__ == "__main__":
    run()
