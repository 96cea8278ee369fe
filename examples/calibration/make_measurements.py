"""Write the synthetic measurement file of the calibration example (docs/calibration.md).

The reference robot "built" with every length moved by up to +-2 mm and each leg sensor reading
up to +-2 mm off (seed 1), measured at the 50 poses ``vgtarm calibrate --plan-poses 50`` chooses
(seed 0) with 0.05 mm of noise on each coordinate (seed 2). Writes, beside this script,
``measurements.csv`` (what ``vgtarm calibrate --measurements`` reads) and ``built_robot.toml`` (the
truth, to compare the fit with; its sensor offsets are in its header).

Run: ``python examples/calibration/make_measurements.py``.
"""

from __future__ import annotations

from pathlib import Path

import vgtarm
from vgtarm.calibration import kinematic as K

HERE = Path(__file__).resolve().parent


def main() -> None:
    robot = vgtarm.load_robot()
    plan = K.plan_poses(robot, 50, seed=0)
    truth = K.perturbed_values(robot, seed=1, lengths=2e-3, offsets=2e-3)
    measured = K.synthetic_measurements(robot, plan.q, truth, noise=0.05e-3, seed=2)
    (HERE / "measurements.csv").write_text(measured.to_csv(robot.joint_names))
    spec = K.calibration_parameters(robot)
    offsets = ", ".join(
        f"{n} {v:+.6g}" for n, v in zip(spec.names[spec.n_lengths :], truth[spec.n_lengths :], strict=True)
    )
    header = (
        "The 'built' robot of examples/calibration/measurements.csv (make_measurements.py).\n"
        f"Sensor zero offsets (m): {offsets}"
    )
    built = K.corrected_parameters(robot, truth, name="built (reference robot, lengths moved, seed 1)")
    (HERE / "built_robot.toml").write_text(K.robot_toml(built, header=header))


if __name__ == "__main__":
    main()
