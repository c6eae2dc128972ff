"""The EKF: cross-check against filterpy, Jacobians, gating, wall corrections, validity flags."""

from __future__ import annotations

import math

import numpy as np
import pytest
from filterpy import kalman as filterpy_kalman

from modules.common.ekf import EkfParams, PoseEKF, chi2_quantile
from modules.common.sync import OdometryParams
from modules.common.walls import KnownWall, wrap


def reference_motion(
    state: np.ndarray, dl: float, dr: float, names: list[str], odo: OdometryParams
) -> np.ndarray:
    """The seed's odometry model written out independently of modules.common.ekf."""
    values = dict(zip(names, state, strict=True))
    mu = values.get("glide", odo.steps_per_degree)
    k = values.get("step_scale", 1.0)
    omega = math.radians((dr - dl) / 2 / mu)
    s = k * (dl + dr) / 2 * odo.mm_per_step
    if odo.model == "arc" and omega != 0:
        s *= math.sin(omega / 2) / (omega / 2)
    out = state.copy()
    out[0] += s * math.cos(values["psi"] + omega / 2)
    out[1] += s * math.sin(values["psi"] + omega / 2)
    out[2] += omega
    return out


def numeric_jacobian(f, x: np.ndarray, eps: float = 1e-6) -> np.ndarray:
    columns = []
    for i in range(len(x)):
        step = np.zeros(len(x))
        step[i] = eps * max(1.0, abs(x[i]))
        columns.append((f(x + step) - f(x - step)) / (2 * step[i]))
    return np.array(columns).T


@pytest.mark.parametrize("model", ["arc", "straight"])
def test_cross_check_against_filterpy(model: str) -> None:
    odo = OdometryParams(model=model)
    params = EkfParams(odometry=odo, estimate=("glide", "compass_offset", "step_scale"))
    ours = PoseEKF(params, (100.0, 200.0, 0.3))
    theirs = filterpy_kalman.ExtendedKalmanFilter(dim_x=len(ours.x), dim_z=1)
    theirs.x = ours.x.copy()
    theirs.P = ours.P.copy()
    wall = KnownWall.segment(-5000, 1500, 5000, 1500)
    rng = np.random.default_rng(4)
    for step in range(60):
        dl, dr = (rng.integers(-200, 400), rng.integers(-200, 400))
        _, _, Q = ours.motion(dl, dr, 0.1)
        ours.predict(dl, dr, 0.1)

        def f(x, dl=dl, dr=dr):
            return reference_motion(x, dl, dr, ours.names, odo)

        theirs.F = numeric_jacobian(f, theirs.x)
        theirs.Q = Q
        theirs.x = f(theirs.x)
        theirs.x[2] = wrap(theirs.x[2])  # both keep the heading in [-π, π)
        theirs.P = theirs.F @ theirs.P @ theirs.F.T + theirs.Q
        np.testing.assert_allclose(ours.x, theirs.x, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(ours.P, theirs.P, rtol=1e-5, atol=1e-9)

        heading = ours.x[2] + ours.compass_offset + rng.normal(0, 0.01)
        _, H = ours.heading_model()
        if ours.correct_heading(heading, 0.02):
            theirs.update(
                np.array([heading]),
                lambda x, H=H: H,
                lambda x, H=H: H @ x,
                R=np.array([[0.02**2]]),
                residual=lambda a, b: np.array([wrap(a[0] - b[0])]),
            )
            theirs.x[2] = wrap(theirs.x[2])
        if step % 5 == 0:
            z, _ = ours.line_model(wall)
            z = z + np.array([0.01, 15.0])
            cov = np.diag([0.02**2, 20.0**2])
            x_before = theirs.x.copy()

            def hx_line(x):
                probe = PoseEKF(params, (0, 0, 0))
                probe.x = x
                return probe.line_model(wall)[0]

            H_line = numeric_jacobian(hx_line, x_before)
            if ours.correct_line(float(z[0]), float(z[1]), cov, wall):
                theirs.dim_z = 2
                theirs.update(
                    z,
                    lambda x, H=H_line: H,
                    hx_line,
                    R=cov,
                    residual=lambda a, b: np.array([wrap(a[0] - b[0]), a[1] - b[1]]),
                )
                theirs.x[2] = wrap(theirs.x[2])
                theirs.dim_z = 1
        np.testing.assert_allclose(ours.x, theirs.x, rtol=1e-6, atol=1e-6)
        np.testing.assert_allclose(ours.P, theirs.P, rtol=1e-4, atol=1e-7)
    assert ours.gates.accepted.get("compass", 0) > 50


def test_gate_rejects_an_injected_compass_outlier_and_counts_it() -> None:
    ekf = PoseEKF(EkfParams(estimate=()), (0.0, 0.0, 0.0))
    for _ in range(5):
        assert ekf.correct_heading(math.radians(0.5))
    before = ekf.x.copy(), ekf.P.copy()
    assert not ekf.correct_heading(math.radians(30.0))  # a magnetic anomaly
    assert ekf.gates.rejected == {"compass": 1}
    assert ekf.gates.accepted == {"compass": 5}
    np.testing.assert_array_equal(ekf.x, before[0])
    np.testing.assert_array_equal(ekf.P, before[1])
    assert ekf.last_nis > chi2_quantile(0.997, 1)


def test_wall_line_corrects_the_coordinate_normal_to_the_wall_only() -> None:
    ekf = PoseEKF(EkfParams(estimate=(), initial_sigma_mm=100.0), (1000.0, 550.0, 0.0))
    wall = KnownWall.segment(0, 1500, 3000, 1500)  # y = 1500
    # truth y = 500: the wall is 1000 mm to the left, its normal at +90 degrees in the robot frame
    cov = np.diag([math.radians(1.0) ** 2, 5.0**2])
    assert ekf.correct_line(math.pi / 2, 1000.0, cov, wall)
    assert ekf.x[1] == pytest.approx(500.0, abs=3.0)
    assert ekf.x[0] == pytest.approx(1000.0, abs=1e-6)
    sx, sy, _ = ekf.sigmas()
    assert sy < 6.0 < 90.0 < sx
    # a wall on the other side of the robot: the normal flips, the algebra must too
    other = KnownWall.segment(0, -1000, 3000, -1000)
    ekf2 = PoseEKF(EkfParams(estimate=(), initial_sigma_mm=100.0), (1000.0, 550.0, 0.0))
    assert ekf2.correct_line(-math.pi / 2, 1500.0, cov, other)
    assert ekf2.x[1] == pytest.approx(500.0, abs=3.0)


def test_wrong_association_is_gated() -> None:
    ekf = PoseEKF(EkfParams(estimate=(), initial_sigma_mm=10.0), (1000.0, 500.0, 0.0))
    wall = KnownWall.segment(0, 1500, 3000, 1500)
    cov = np.diag([math.radians(1.0) ** 2, 5.0**2])
    assert not ekf.correct_line(math.pi / 2, 700.0, cov, wall)  # 300 mm off: not this wall
    assert ekf.gates.rejected == {"wall": 1}


def test_validity_flags_follow_the_covariance() -> None:
    ekf = PoseEKF(EkfParams(estimate=(), valid_sigma_mm=100.0, valid_sigma_deg=5.0), (0.0, 0.0, 0.0))
    assert ekf.validity() == (True, True, True)
    ekf.P[0, 0] = 200.0**2
    ekf.P[2, 2] = math.radians(10.0) ** 2
    assert ekf.validity() == (False, True, False)


def test_glide_factor_is_learned_from_compass_during_turns() -> None:
    true_mu = 7.0  # the floor makes turns need more steps per degree than the nominal 6.5
    ekf = PoseEKF(EkfParams(estimate=("glide",), rotation_noise_rel=0.02), (0.0, 0.0, 0.0))
    rng = np.random.default_rng(1)
    truth = 0.0
    for _ in range(8):  # eight 90-degree turns on the spot, 10 increments each
        for _ in range(10):
            diff = 90 * true_mu / 10
            ekf.predict(-diff, diff, 0.1)
            truth += math.radians(diff / true_mu)
            ekf.correct_heading(wrap(truth + rng.normal(0, math.radians(1.0))), math.radians(1.0))
    assert ekf.glide == pytest.approx(true_mu, abs=0.1)
    assert abs(math.degrees(wrap(ekf.x[2] - truth))) < 1.0


def test_unknown_state_name_is_refused() -> None:
    with pytest.raises(ValueError, match="unknown states"):
        PoseEKF(EkfParams(estimate=("wheel_radius",)), (0, 0, 0))
