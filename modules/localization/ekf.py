"""The Extended Kalman Filter of the Darmstadt program (seed 000, §4.2, §6.2.2, §6.2.4), on numpy.

State: ``x, y`` (mm), ``ψ`` (rad, counter-clockwise from +X), and optionally

- ``glide`` — the glide factor μ (differential half-steps per degree turned), estimated online
  instead of the seed's calibration run;
- ``compass_offset`` — a slowly drifting compass bias (rad);
- ``gyro_offset`` — the heading at which the gyroscope's summed angle was zero (rad): the gyro
  measures the heading as ``ψ − offset``; its bias drift and scale error walk the offset;
- ``step_scale`` — the true length of a straight half-step relative to the nominal one, in the
  current move;
- ``step_scale_mean`` — the floor's mean of it. The floor draws each move's step length afresh
  around one mean (SPEC §5), so a new move's scale starts at this mean, not at the last move's
  scale: what one move measured is not carried into the next as if the floor repeated it.

Prediction from synchronised step increments with the seed's odometry model
``(x, y, ψ) += (cos(ψ+ω/2)·s, sin(ψ+ω/2)·s, ω)``, ``s`` the straight-line mean or the exact
chord of the arc, optionally with the floor correlator's distance over the step
(:meth:`PoseEKF.predict`). Corrections: the compass heading (``ψ + offset``), the gyroscope's
summed angle (``ψ − gyro_offset``), LOPS's distances, and wall lines seen by the
sonars — a line measured in the robot frame as ``(α_r, d_r)`` is predicted from a known wall
``(α_w, d_w)`` as ``(α_w − ψ, d_w − x·cos α_w − y·sin α_w)`` (sign-normalised so ``d ≥ 0``).

Every correction passes an innovation gate: the normalised innovation squared must stay below
the χ² quantile of ``gate_probability``; outliers (magnetic anomalies, wrong associations) are
rejected and counted. Validity flags per coordinate as in the seed: a coordinate is valid while
its standard deviation is below a bound.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from statistics import NormalDist
from typing import Any

import numpy as np

from modules.localization.sync import OdometryParams
from modules.localization.walls import KnownWall, wrap

OPTIONAL_STATES = ("glide", "compass_offset", "gyro_offset", "step_scale", "step_scale_mean")


@dataclass(frozen=True)
class EkfParams:
    """Noise and gating of the filter; every value has the unit in its name."""

    odometry: OdometryParams = field(default_factory=OdometryParams)
    estimate: tuple[str, ...] = ("glide", "compass_offset")
    # odometry noise: distance error ∝ distance, rotation error ∝ rotation (+ a little per mm)
    distance_noise_rel: float = 0.01
    rotation_noise_rel: float = 0.02
    rotation_noise_rad_per_mm: float = 0.0002
    # the floor draws its slip once per move (SPEC §5): new variance at the start of each move
    glide_per_move_rel: float = 0.06
    step_scale_per_move: float = 0.005
    # random walks of the optional states
    glide_walk_per_deg: float = 0.001
    compass_offset_walk_deg_per_s: float = 0.05
    # the gyro's summed angle: its zero point's drift per second, its scale factor's error per turn
    gyro_offset_walk_deg_per_s: float = 0.05
    gyro_scale_rel: float = 0.01
    step_scale_walk_per_m: float = 0.0005
    step_scale_mean_walk_per_move: float = 0.001  # with step_scale_mean: the floor may change
    # initial uncertainty
    initial_sigma_mm: float = 20.0
    initial_sigma_deg: float = 2.0
    initial_glide_sigma: float = 0.3
    initial_compass_offset_sigma_deg: float = 3.0
    #: unknown until the first reading: that one sets it (the measurement is linear in it)
    initial_gyro_offset_sigma_deg: float = 180.0
    initial_step_scale_sigma: float = 0.02
    #: the floor's mean step scale to start from (1.0: the nominal step; else an odometry
    #: calibration, ``tokenring calibrate``) and its σ (None: ``initial_step_scale_sigma``)
    initial_step_scale: float = 1.0
    initial_step_scale_mean_sigma: float | None = None
    # measurements
    compass_sigma_deg: float = 1.5
    gate_probability: float = 0.997
    # validity bounds (seed: X/Y/angle valid flags)
    valid_sigma_mm: float = 150.0
    valid_sigma_deg: float = 5.0


def chi2_quantile(probability: float, dof: int) -> float:
    """The χ² quantile for 1 or 2 degrees of freedom (closed forms; no scipy needed)."""
    if dof == 1:
        z = NormalDist().inv_cdf((1.0 + probability) / 2.0)
        return z * z
    if dof == 2:
        return -2.0 * math.log(1.0 - probability)
    raise ValueError("only 1 or 2 degrees of freedom are used")


@dataclass
class GateCounts:
    """Corrections accepted and rejected, per measurement kind."""

    accepted: dict[str, int] = field(default_factory=dict)
    rejected: dict[str, int] = field(default_factory=dict)

    def count(self, kind: str, accepted: bool) -> None:
        target = self.accepted if accepted else self.rejected
        target[kind] = target.get(kind, 0) + 1

    def as_dict(self) -> dict[str, dict[str, int]]:
        return {"accepted": dict(self.accepted), "rejected": dict(self.rejected)}


class PoseEKF:
    """EKF over (x, y, ψ[, glide, compass_offset, gyro_offset, step_scale, step_scale_mean])."""

    def __init__(self, params: EkfParams, pose: tuple[float, float, float]) -> None:
        unknown = set(params.estimate) - set(OPTIONAL_STATES)
        if unknown:
            raise ValueError(f"unknown states to estimate: {sorted(unknown)}")
        if "step_scale_mean" in params.estimate and "step_scale" not in params.estimate:
            raise ValueError("step_scale_mean needs step_scale")
        self.params = params
        self.names = ["x", "y", "psi", *[s for s in OPTIONAL_STATES if s in params.estimate]]
        self.index = {name: i for i, name in enumerate(self.names)}
        n = len(self.names)
        self.x = np.zeros(n)
        self.x[:3] = pose
        sigmas = [params.initial_sigma_mm, params.initial_sigma_mm, math.radians(params.initial_sigma_deg)]
        if "glide" in self.index:
            self.x[self.index["glide"]] = params.odometry.steps_per_degree
            sigmas.append(params.initial_glide_sigma)
        if "compass_offset" in self.index:
            sigmas.append(math.radians(params.initial_compass_offset_sigma_deg))
        if "gyro_offset" in self.index:
            sigmas.append(math.radians(params.initial_gyro_offset_sigma_deg))
        if "step_scale" in self.index:
            self.x[self.index["step_scale"]] = params.initial_step_scale
            sigmas.append(params.initial_step_scale_sigma)
        if "step_scale_mean" in self.index:
            self.x[self.index["step_scale_mean"]] = params.initial_step_scale
            mean_sigma = params.initial_step_scale_mean_sigma
            sigmas.append(params.initial_step_scale_sigma if mean_sigma is None else mean_sigma)
        self.P = np.diag(np.square(sigmas))
        self.gates = GateCounts()
        self.gate_1 = chi2_quantile(params.gate_probability, 1)
        self.gate_2 = chi2_quantile(params.gate_probability, 2)
        self.last_nis: float | None = None
        self.last_kind: str | None = None  # the motion of the last increment (a new one starts a move)

    # ---------------------------------------------------------------------------------------
    # state access

    @property
    def pose(self) -> tuple[float, float, float]:
        return float(self.x[0]), float(self.x[1]), float(wrap(self.x[2]))

    @property
    def glide(self) -> float:
        i = self.index.get("glide")
        return float(self.x[i]) if i is not None else self.params.odometry.steps_per_degree

    @property
    def step_scale(self) -> float:
        i = self.index.get("step_scale")
        return float(self.x[i]) if i is not None else 1.0

    @property
    def step_scale_mean(self) -> float:
        """The floor's mean step scale (the current move's scale without that state)."""
        i = self.index.get("step_scale_mean")
        return float(self.x[i]) if i is not None else self.step_scale

    @property
    def step_scale_mean_sigma(self) -> float | None:
        """The floor mean's standard deviation; None without that state."""
        i = self.index.get("step_scale_mean")
        return float(math.sqrt(max(self.P[i, i], 0.0))) if i is not None else None

    @property
    def compass_offset(self) -> float:
        i = self.index.get("compass_offset")
        return float(self.x[i]) if i is not None else 0.0

    def sigmas(self) -> tuple[float, float, float]:
        """Standard deviations of x, y (mm) and ψ (rad)."""
        d = np.sqrt(np.maximum(np.diag(self.P)[:3], 0.0))
        return float(d[0]), float(d[1]), float(d[2])

    def validity(self) -> tuple[bool, bool, bool]:
        sx, sy, spsi = self.sigmas()
        p = self.params
        return sx <= p.valid_sigma_mm, sy <= p.valid_sigma_mm, math.degrees(spsi) <= p.valid_sigma_deg

    def set_pose(self, pose: tuple[float, float, float], sigma_mm: float, sigma_deg: float) -> None:
        """Re-initialise the pose (SET_GLOBAL_POSITION, a known start); parameters are kept."""
        self.x[:3] = pose
        self.P[:3, :] = 0.0
        self.P[:, :3] = 0.0
        self.P[0, 0] = self.P[1, 1] = sigma_mm**2
        self.P[2, 2] = math.radians(sigma_deg) ** 2

    # ---------------------------------------------------------------------------------------
    # prediction

    def motion(self, dl: float, dr: float, dt_s: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The predicted state, its Jacobian A and the process noise for an increment.

        The noise is W·Q·Wᵀ for the increment's own (s, ω) noise, the random walks of the optional
        states, and — when this increment starts a new move — A·D·Aᵀ for the new draw D of the
        floor's slip (glide factor for a turn, step length for a straight move): the slip of one
        move is one error, correlated over all its increments, not independent per increment.
        With ``step_scale_mean`` a new straight move's scale restarts at the mean (A includes
        that restart).
        """
        p = self.params
        odo = p.odometry
        kind = motion_kind(dl, dr)
        starts_move = kind is not None and kind != self.last_kind
        restart = self._scale_restart() if starts_move and kind in ("straight", "arc") else None
        x = self.x if restart is None else restart @ self.x
        n = len(x)
        mu = self.glide  # a restart sets the step scale only
        k = float(x[self.index["step_scale"]]) if restart is not None else self.step_scale
        psi = float(x[2])
        nominal = (dl + dr) / 2.0 * odo.mm_per_step  # mm, nominal mean track distance
        differential = (dr - dl) / 2.0  # half-steps
        omega = math.radians(differential / mu)
        chord, dchord = _chord_factor(omega) if odo.model == "arc" else (1.0, 0.0)
        s = k * nominal * chord
        mid = psi + omega / 2.0
        c, sn = math.cos(mid), math.sin(mid)
        new = x.copy()
        new[0] += s * c
        new[1] += s * sn
        new[2] += omega

        A = np.eye(n)
        A[0, 2] = -s * sn
        A[1, 2] = s * c
        if "glide" in self.index:
            i = self.index["glide"]
            domega = -omega / mu
            ds = k * nominal * dchord * domega
            A[0, i] = ds * c - s * sn * domega / 2.0
            A[1, i] = ds * sn + s * c * domega / 2.0
            A[2, i] = domega
        if "step_scale" in self.index:
            i = self.index["step_scale"]
            A[0, i] = nominal * chord * c
            A[1, i] = nominal * chord * sn

        # input noise on (s, ω), mapped through W = ∂f/∂(s, ω)
        sigma_s = p.distance_noise_rel * abs(s)
        sigma_w = p.rotation_noise_rel * abs(omega) + p.rotation_noise_rad_per_mm * abs(s)
        W = np.zeros((n, 2))
        W[0, 0], W[1, 0] = c, sn
        W[0, 1], W[1, 1], W[2, 1] = -s * sn / 2.0, s * c / 2.0, 1.0
        Q = W @ np.diag([sigma_s**2, sigma_w**2]) @ W.T
        if "glide" in self.index:
            i = self.index["glide"]
            Q[i, i] += p.glide_walk_per_deg**2 * abs(math.degrees(omega))
        if "compass_offset" in self.index:
            i = self.index["compass_offset"]
            Q[i, i] += math.radians(p.compass_offset_walk_deg_per_s) ** 2 * max(dt_s, 0.0)
        if "gyro_offset" in self.index:
            i = self.index["gyro_offset"]
            Q[i, i] += (math.radians(p.gyro_offset_walk_deg_per_s) * max(dt_s, 0.0)) ** 2
            # the scale error is one error over a whole turn: counted as if every turn were 90°
            Q[i, i] += p.gyro_scale_rel**2 * abs(omega) * (math.pi / 2.0)
        if "step_scale" in self.index:
            i = self.index["step_scale"]
            Q[i, i] += p.step_scale_walk_per_m**2 * abs(s) / 1000.0
        if starts_move:
            D = np.zeros((n, n))
            if "glide" in self.index and kind in ("turn", "arc"):
                D[self.index["glide"], self.index["glide"]] = (p.glide_per_move_rel * mu) ** 2
            if "step_scale" in self.index and kind in ("straight", "arc"):
                D[self.index["step_scale"], self.index["step_scale"]] = p.step_scale_per_move**2
            if "step_scale_mean" in self.index and kind in ("straight", "arc"):
                i = self.index["step_scale_mean"]
                D[i, i] = p.step_scale_mean_walk_per_move**2
            Q = Q + A @ D @ A.T
        if restart is not None:
            A = A @ restart
        return new, A, Q

    def _scale_restart(self) -> np.ndarray | None:
        """The linear map that sets the move's step scale to the floor's mean (None: no mean).

        The last move's own scale drops out of the state; nothing later observes it, so this is
        its exact marginalisation, and the pose keeps what that move's scale did to it."""
        if "step_scale_mean" not in self.index:
            return None
        i, m = self.index["step_scale"], self.index["step_scale_mean"]
        T = np.eye(len(self.x))
        T[i, i] = 0.0
        T[i, m] = 1.0
        return T

    def predict(
        self, dl: float, dr: float, dt_s: float = 0.0, travel: tuple[float, float] | None = None
    ) -> bool | None:
        """Advance by ``dl``, ``dr`` half-steps of the left and right motor over ``dt_s`` seconds.

        ``travel``: the floor correlator's distance along the robot's axis over the same period
        (mm) and its σ, a correction of the step's *change* of the pose: the pose before the step
        is kept as a clone in the state for the correction, then dropped (stochastic cloning), so
        it is weighed against the odometry with every correlation the step made (the step
        scale's among them). Returns whether it passed its gate (None: no travel given)."""
        before = self.x
        new, A, Q = self.motion(dl, dr, dt_s)
        kind, previous = motion_kind(dl, dr), self.last_kind
        self.last_kind = kind
        n = len(new)
        if travel is not None:
            clone = np.zeros((n + 3, n))  # [the state after the step; x, y, ψ before it]
            clone[:n] = A
            clone[n, 0] = clone[n + 1, 1] = clone[n + 2, 2] = 1.0
            self.x = np.append(new, before[:3])
            self.P = clone @ self.P @ clone.T
            self.P[:n, :n] += Q
        else:
            self.x = new
            self.P = A @ self.P @ A.T + Q
        if kind == "straight" and previous != "straight" and "glide" in self.index:
            # the last turn's slip is fixed in the pose now: a straight move does not observe the
            # glide factor, and heading corrections on it (a bent compass) must not rewrite it —
            # after a 4° turn a 2° pull made the glide 9 and the next 90° turn 64°, gated out
            i = self.index["glide"]
            self.P[i, :i] = self.P[:i, i] = 0.0
            self.P[i, i + 1 :] = self.P[i + 1 :, i] = 0.0
        accepted = None
        if travel is not None:
            dx, dy = self.x[0] - self.x[n], self.x[1] - self.x[n + 1]
            mid = self.x[n + 2] + wrap(self.x[2] - self.x[n + 2]) / 2.0
            c, sn = math.cos(mid), math.sin(mid)
            across = 0.5 * (-dx * sn + dy * c)
            H = np.zeros((1, n + 3))
            H[0, 0], H[0, 1], H[0, n], H[0, n + 1] = c, sn, -c, -sn
            H[0, 2] = H[0, n + 2] = across
            model = np.array([dx * c + dy * sn])
            accepted = self.update(
                "correlator", np.array([travel[0]]), model, H, np.array([[travel[1] ** 2]])
            )
            self.x = self.x[:n]
            self.P = self.P[:n, :n]
        self.x[2] = wrap(self.x[2])
        return accepted

    # ---------------------------------------------------------------------------------------
    # corrections

    def update(
        self,
        kind: str,
        z: np.ndarray,
        hx: np.ndarray,
        H: np.ndarray,
        R: np.ndarray,
        angles: tuple[int, ...] = (),
    ) -> bool:
        """One gated EKF correction; ``angles`` are the rows of ``z`` to wrap. True if accepted."""
        y = np.asarray(z, dtype=float) - hx
        for row in angles:
            y[row] = wrap(y[row])
        S = H @ self.P @ H.T + R
        nis = float(y @ np.linalg.solve(S, y))
        self.last_nis = nis
        limit = self.gate_1 if len(y) == 1 else self.gate_2
        if nis > limit:
            self.gates.count(kind, False)
            return False
        K = self.P @ H.T @ np.linalg.inv(S)
        self.x = self.x + K @ y
        self.x[2] = wrap(self.x[2])
        I_KH = np.eye(len(self.x)) - K @ H
        self.P = I_KH @ self.P @ I_KH.T + K @ R @ K.T  # Joseph form: stays symmetric positive
        self.gates.count(kind, True)
        return True

    def heading_model(self) -> tuple[np.ndarray, np.ndarray]:
        """Predicted compass reading and its Jacobian."""
        H = np.zeros((1, len(self.x)))
        H[0, 2] = 1.0
        hx = float(self.x[2])
        if "compass_offset" in self.index:
            i = self.index["compass_offset"]
            H[0, i] = 1.0
            hx += float(self.x[i])
        return np.array([hx]), H

    def correct_heading(self, heading: float, sigma_rad: float | None = None) -> bool:
        """Compass correction with a heading in rad (CCW from +X)."""
        sigma = math.radians(self.params.compass_sigma_deg) if sigma_rad is None else sigma_rad
        hx, H = self.heading_model()
        return self.update("compass", np.array([heading]), hx, H, np.array([[sigma**2]]), angles=(0,))

    def correct_gyro(self, angle: float, sigma_rad: float) -> bool:
        """The gyroscope's summed angle (rad) as a heading measurement ``ψ − gyro_offset``: between
        two readings it measures the turn made, whatever the odometry's glide did."""
        i = self.index.get("gyro_offset")
        if i is None:
            return False
        H = np.zeros((1, len(self.x)))
        H[0, 2], H[0, i] = 1.0, -1.0
        hx = np.array([float(self.x[2] - self.x[i])])
        return self.update("gyro", np.array([angle]), hx, H, np.array([[sigma_rad**2]]), angles=(0,))

    def restart_gyro(self) -> None:
        """The gyro's sum started again (a new calibration): its offset is unknown once more."""
        i = self.index.get("gyro_offset")
        if i is not None:
            self.P[i, :] = self.P[:, i] = 0.0
            self.P[i, i] = math.radians(self.params.initial_gyro_offset_sigma_deg) ** 2

    def correct_range(
        self,
        receiver: tuple[float, float],
        distance: float,
        sigma_mm: float,
        moved: tuple[float, float] = (0.0, 0.0),
    ) -> bool:
        """LOPS: the distance from the robot (its transmitter at the pose's x, y) to a receiver.
        One receiver at a time, each gated: a late echo fails the gate, the others still count.
        ``moved``: how far the robot went between the measurement and now (mm, the filter's frame):
        the transmitter stood that much behind the pose."""
        dx = float(self.x[0]) - moved[0] - receiver[0]
        dy = float(self.x[1]) - moved[1] - receiver[1]
        predicted = math.hypot(dx, dy)
        if predicted < 1.0:  # on the receiver itself: no direction to correct along
            return False
        H = np.zeros((1, len(self.x)))
        H[0, 0], H[0, 1] = dx / predicted, dy / predicted
        return self.update("lops", np.array([distance]), np.array([predicted]), H, np.array([[sigma_mm**2]]))

    def correct_step_scale(self, scale: float, sigma: float) -> bool:
        """Correction with a measured step scale (a straight drive's true over nominal length);
        through the state's correlation with the pose it moves the pose by the length misjudged."""
        i = self.index.get("step_scale")
        if i is None:
            return False
        H = np.zeros((1, len(self.x)))
        H[0, i] = 1.0
        return self.update("travel", np.array([scale]), np.array([self.x[i]]), H, np.array([[sigma**2]]))

    def line_model(self, wall: KnownWall) -> tuple[np.ndarray, np.ndarray]:
        """Predicted robot-frame line (α_r, d_r) of a known wall and its Jacobian."""
        x, y, psi = float(self.x[0]), float(self.x[1]), float(self.x[2])
        ca, sa = math.cos(wall.alpha), math.sin(wall.alpha)
        signed = wall.d - x * ca - y * sa
        sign = 1.0 if signed >= 0 else -1.0
        alpha_r = wrap(wall.alpha - psi + (0.0 if sign > 0 else math.pi))
        H = np.zeros((2, len(self.x)))
        H[0, 2] = -1.0
        H[1, 0] = -sign * ca
        H[1, 1] = -sign * sa
        return np.array([alpha_r, abs(signed)]), H

    def line_nis(self, alpha_r: float, d_r: float, cov: np.ndarray, wall: KnownWall) -> float:
        """The normalised innovation squared of a measured line against a known wall."""
        hx, H = self.line_model(wall)
        y = np.array([wrap(alpha_r - hx[0]), d_r - hx[1]])
        S = H @ self.P @ H.T + cov
        return float(y @ np.linalg.solve(S, y))

    def correct_line(
        self, alpha_r: float, d_r: float, cov: np.ndarray, wall: KnownWall, kind: str = "wall"
    ) -> bool:
        """Correction with a line measured in the robot frame, associated with ``wall``."""
        hx, H = self.line_model(wall)
        return self.update(kind, np.array([alpha_r, d_r]), hx, H, cov, angles=(0,))


def motion_kind(dl: float, dr: float) -> str | None:
    """None (standing), ``straight`` (both tracks alike), ``turn`` (on the spot) or ``arc``."""
    if dl == 0 and dr == 0:
        return None
    if dl == dr:
        return "straight"
    if dl == -dr:
        return "turn"
    return "arc"


def _chord_factor(omega: float) -> tuple[float, float]:
    """``2·sin(ω/2)/ω`` (chord over arc length) and its derivative, stable near ω = 0."""
    if abs(omega) < 1e-4:
        return 1.0 - omega * omega / 24.0, -omega / 12.0
    half = omega / 2.0
    value = 2.0 * math.sin(half) / omega
    derivative = (math.cos(half) * omega - 2.0 * math.sin(half)) / (omega * omega)
    return value, derivative


def describe(ekf: PoseEKF) -> dict[str, Any]:
    """The filter's state for reports and logs (plain values)."""
    sx, sy, spsi = ekf.sigmas()
    return {
        "pose": list(ekf.pose),
        "sigma_mm": [sx, sy],
        "sigma_deg": math.degrees(spsi),
        "glide": ekf.glide,
        "compass_offset_deg": math.degrees(ekf.compass_offset),
        "step_scale": ekf.step_scale,
        "step_scale_mean": ekf.step_scale_mean,
        "gates": ekf.gates.as_dict(),
    }
