"""Force figures of a run's summary (issue 22, item 3), checked on analytic arrays."""

from __future__ import annotations

import numpy as np

from vgtarm.model.parameters import JOINT_NAMES
from vgtarm.simulation.result import MODE_FIXED, SimulationResult, force_figures


def test_force_figures_of_analytic_arrays():
    """A sine on every leg: RMS A/sqrt(2), peak A, chatter of a sampled sine, energy of |F qd|."""
    dt, n = 1e-3, 4000  # four whole periods of 1 s
    t = np.arange(n) * dt
    amplitude = np.arange(1.0, 7.0)  # N, leg j has amplitude j + 1
    forces = np.sin(2 * np.pi * t)[:, None] * amplitude
    torque = np.full(n, 0.5)
    qd = np.zeros((n, 7))
    qd[:, 0] = 0.01  # m/s on leg 1 only
    effort = np.column_stack([forces, torque])
    out = force_figures(forces, torque, effort, qd, dt)
    np.testing.assert_allclose(out["rms_force_per_leg_n"], amplitude / np.sqrt(2), rtol=1e-3)
    np.testing.assert_allclose(out["peak_force_per_leg_n"], amplitude, rtol=1e-5)
    assert out["rms_twist_torque_nm"] == 0.5
    # change per period of a * sin(w t): 2 a sin(w dt / 2) cos(...), RMS 2 a sin(w dt/2) / sqrt(2)
    chatter = np.sqrt(np.mean(amplitude**2)) * 2 * np.sin(np.pi * dt) / np.sqrt(2)
    np.testing.assert_allclose(out["chatter_n"], chatter, rtol=1e-3)
    # integral of |sin| over 4 s is 8/pi; times amplitude 1 N and 0.01 m/s
    np.testing.assert_allclose(out["actuator_energy_j"], 0.01 * 8 / np.pi, rtol=1e-5)


def test_summary_carries_the_force_figures():
    n = 5
    zeros3, zeros7 = np.zeros((n, 3)), np.zeros((n, 7))
    effort = np.tile(np.arange(1.0, 8.0), (n, 1))
    result = SimulationResult(
        t=np.arange(n) * 1e-3,
        tip_desired=zeros3,
        tip=zeros3,
        tip_error=np.zeros(n),
        q_desired=zeros7,
        qd_desired=zeros7,
        q=zeros7,
        qd=zeros7,
        effort=effort,
        f_ext=zeros3,
        mode=np.full(n, MODE_FIXED, dtype=np.int8),
        activations=(),
        success=True,
        message="",
        wall_time_s=1.0,
        ga_time_s=0.0,
        metadata={"joint_names": list(JOINT_NAMES)},
    )
    summary = result.summary()
    assert summary["rms_force_per_leg_n"] == [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]
    assert summary["peak_force_per_leg_n"] == [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]
    assert summary["rms_twist_torque_nm"] == 7.0
    assert summary["chatter_n"] == 0.0
    assert summary["actuator_energy_j"] == 0.0
