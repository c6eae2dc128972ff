"""The EKF: cross-check against filterpy, Jacobians, gating, wall corrections, validity flags."""

from __future__ import annotations

import math

import numpy as np
import pytest
from filterpy import kalman as filterpy_kalman

from modules.localization.ekf import EkfParams, PoseEKF, chi2_quantile
from modules.localization.sync import OdometryParams
from modules.localization.walls import KnownWall, wrap


def reference_motion(
    state: np.ndarray, dl: float, dr: float, names: list[str], odo: OdometryParams, new_move: bool = False
) -> np.ndarray:
    """The seed's odometry model written out independently of modules.localization.ekf; a new straight
    or arc move with a mean step scale in the state starts from that mean."""
    values = dict(zip(names, state, strict=True))
    state = state.copy()
    if new_move and dl != -dr and "step_scale_mean" in values:
        values["step_scale"] = values["step_scale_mean"]
        state[names.index("step_scale")] = values["step_scale_mean"]
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


@pytest.mark.parametrize(
    ("model", "mean"), [("arc", False), ("straight", False), ("arc", True), ("straight", True)]
)
def test_cross_check_against_filterpy(model: str, mean: bool) -> None:
    odo = OdometryParams(model=model)
    states = ("glide", "compass_offset", "step_scale", *(("step_scale_mean",) if mean else ()))
    params = EkfParams(odometry=odo, estimate=states)
    ours = PoseEKF(params, (100.0, 200.0, 0.3))
    theirs = filterpy_kalman.ExtendedKalmanFilter(dim_x=len(ours.x), dim_z=1)
    theirs.x = ours.x.copy()
    theirs.P = ours.P.copy()
    wall = KnownWall.segment(-5000, 1500, 5000, 1500)
    rng = np.random.default_rng(4)
    last_kind = None
    for step in range(60):
        shape = step % 4  # straight, arc, turn, arc again: every kind of move, and moves that start
        dl = int(rng.integers(-200, 400))
        dr = {0: dl, 1: int(rng.integers(-200, 400)), 2: -dl, 3: int(rng.integers(-200, 400))}[shape]
        kind = "straight" if dl == dr else "turn" if dl == -dr else "arc"
        new_move, last_kind = kind != last_kind, kind
        _, _, Q = ours.motion(dl, dr, 0.1)
        ours.predict(dl, dr, 0.1)

        def f(x, dl=dl, dr=dr, new_move=new_move):
            return reference_motion(x, dl, dr, ours.names, odo, new_move)

        theirs.F = numeric_jacobian(f, theirs.x)
        theirs.Q = Q
        theirs.x = f(theirs.x)
        theirs.x[2] = wrap(theirs.x[2])  # both keep the heading in [-π, π)
        theirs.P = theirs.F @ theirs.P @ theirs.F.T + theirs.Q
        if kind == "straight" and new_move:  # a straight move does not observe the last turn's glide
            g = ours.names.index("glide")
            diagonal = theirs.P[g, g]
            theirs.P[g, :] = theirs.P[:, g] = 0.0
            theirs.P[g, g] = diagonal
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


def test_the_mean_step_scale_is_the_posterior_of_every_move_measured() -> None:
    """Each move's scale is the floor's mean plus its own draw: measured moves inform the mean as
    independent draws around it, the closed-form Gaussian posterior, and a new move starts there."""
    draw_sd, noise_sd, prior_sd = 0.005, 0.002, 0.02
    params = EkfParams(
        estimate=("glide", "step_scale", "step_scale_mean"),
        step_scale_per_move=draw_sd,
        step_scale_mean_walk_per_move=0.0,
        step_scale_walk_per_m=0.0,
        initial_step_scale_sigma=prior_sd,
    )
    ekf = PoseEKF(params, (0.0, 0.0, 0.0))
    rng = np.random.default_rng(7)
    readings = []
    for _ in range(25):
        ekf.predict(200, 200)  # a straight move: its scale restarts at the mean
        k = ekf.names.index("step_scale")
        assert ekf.step_scale == pytest.approx(ekf.step_scale_mean)
        reading = 1.012 + rng.normal(0.0, draw_sd) + rng.normal(0.0, noise_sd)
        readings.append(reading)
        assert ekf.correct_step_scale(reading, noise_sd)
        ekf.predict(300, 300)
        ekf.predict(-100, 100)  # a turn ends the move
    precision = 1 / prior_sd**2 + len(readings) / (draw_sd**2 + noise_sd**2)
    expected = (1.0 / prior_sd**2 + sum(readings) / (draw_sd**2 + noise_sd**2)) / precision
    m = ekf.names.index("step_scale_mean")
    assert ekf.step_scale_mean == pytest.approx(expected, abs=1e-9)
    assert ekf.P[m, m] == pytest.approx(1 / precision, rel=1e-6)
    ekf.predict(200, 200)
    assert ekf.P[k, k] == pytest.approx(1 / precision + draw_sd**2, rel=1e-6)


def test_a_mean_step_scale_needs_the_move_s_scale() -> None:
    with pytest.raises(ValueError, match="step_scale_mean needs step_scale"):
        PoseEKF(EkfParams(estimate=("step_scale_mean",)), (0.0, 0.0, 0.0))
