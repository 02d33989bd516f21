# SPDX-License-Identifier: Apache-2.0
"""Nonlinear time-domain simulation of the spinning screw with the nut's friction (issue 13).

The modal equations of (27) with the friction force kept nonlinear (`friction_force`):

    qdd + (C + G) qd + ([omega^2] - Omega^2 I) q = Q(q, qd)

M = I (mass-normalised modes), C = diag(2 xi omega) (A.1), G the gyroscopic coupling (A.2),
Q the friction of the nut over the contact helix at the actual contact velocity. Steady
sliding is the static equilibrium q* of ([omega^2] - Omega^2 I) q* = Q(q*, 0) (the screw
twisted and bent by the steady friction; Newton from q = 0); the run starts there plus a
seeded random perturbation of every modal coordinate and rate (each mode's contribution to
the contact velocity of the same size), so the simulation itself shows which mode grows. The
state integrated is the deviation from q*.

Integrator: scipy's LSODA (Adams while the problem is not stiff, BDF with the analytic
Jacobian when it turns stiff; Radau IIA or DOP853 selectable). The system is stiff: the highest
mode kept (about 29 kHz with the 18 default modes), friction damping ~ mu |F_z| Phi^2 / |Vc|
that grows as the speed falls, and the regularisation's slope ~ mu |F_z| Phi^2 / v_eps near
zero sliding. The step follows the accuracy of what moves but never exceeds 1/8 of the period
of the highest mode kept: an implicit method that steps over an oscillation it does not
resolve damps it (Radau) or sustains it (LSODA) numerically; both were seen at 0.2 rad/s with
a large perturbation without the cap, and with it the two agree (DOP853, explicit, went
erratic there).

Stick: the kinematics (3)-(11) have no axial vibration, so the axial sliding component
R Omega tan(beta) of Vc never changes and |Vc| >= R |Omega| tan(beta) (8.7e-3 m/s at
20 rad/s, 8.7e-5 m/s at 0.2 rad/s with Table 1). The contact never sticks completely; the
regularisation (v_eps 1e-5 m/s by default) changes the force by more than 1e-6 only where
|Vc| < 7.3 v_eps, so only below |Omega| = 7.3 v_eps / (R tan(beta)) (0.17 rad/s with Table 1).

`modes` keeps the K lowest-frequency modes of the basis (the contact force and every matrix
restricted to them).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace

import numpy as np
from scipy.integrate import solve_ivp

from ..physics.assembly import gyroscopic_unit
from ..physics.contact import contact_angles
from ..physics.display import exact
from ..physics.metadata import check, setting
from ..physics.modes import KIND_T, KIND_X, KIND_Y, ModalBasis, modal_basis
from ..physics.parameters import ParameterError, ScrewParameters
from ..squeak_model import check_operating_point
from .friction_force import HelixFriction

METHODS = ("LSODA", "Radau", "DOP853")
ATOL_PER_RTOL = 100  # absolute tolerance of each state: 100 rtol times its start size
MIN_SAMPLES, MAX_SAMPLES = 256, 2_000_000  # stored samples of a run
STEPS_PER_PERIOD = 8  # largest step: this fraction of the period of the highest mode kept
# Plausible |speed| of a simulation: from a turn in about 70 days (below it the steady sliding
# and its perturbation underflow the integrator) to the first critical speed (the model's).
MIN_SPEED_RAD_S = 1e-6


@dataclass(frozen=True)
class TransientSettings:
    """Settings of one simulation (validated on construction; `ParameterError` names the
    field).

    Attributes
    ----------
    duration_s : float
        Simulated time [s].
    sample_rate_hz : int
        Rate of the stored samples [Hz].
    modes : int
        Keep the K lowest-frequency modes (0: all of the basis).
    regularisation_m_s : float
        Width v_eps of the tanh regularisation of the friction direction [m/s].
    perturbation : float
        Initial perturbation: standard deviation of each mode's contribution to the contact
        velocity, as a fraction of the steady sliding speed (dimensionless).
    seed : int
        Seed of the perturbation.
    points_per_turn : int
        Gauss-Legendre points per thread turn of the contact integral.
    rtol : float
        Relative tolerance of the integrator (dimensionless).
    method : str
        `scipy.integrate.solve_ivp` method: LSODA (default: switches between Adams and BDF
        with the analytic Jacobian as the problem turns stiff), Radau or DOP853.
    """

    duration_s: float = setting(0.2, "s", "simulated time", 0.0, 10.0, lo_open=True)
    sample_rate_hz: int = setting(96000, "Hz", "rate of the stored samples", 1000, 1000000)
    modes: int = setting(0, "1", "keep the K lowest-frequency modes (0: all)", 0, 1000)
    regularisation_m_s: float = setting(
        1e-5,
        "m/s",
        "width v_eps of the tanh regularisation of the friction direction near zero sliding speed",
        0.0,
        1.0,
        lo_open=True,
    )
    perturbation: float = setting(
        1e-6,
        "1",
        "initial perturbation of every mode, as a fraction of the steady sliding speed",
        0.0,
        10.0,
        lo_open=True,
    )
    seed: int = setting(0, "1", "seed of the initial perturbation", 0, 2**31 - 1)
    points_per_turn: int = setting(
        16, "1", "Gauss-Legendre points per thread turn of the contact integral", 4, 64
    )
    rtol: float = setting(1e-8, "1", "relative tolerance of the integrator", 1e-12, 1e-2)
    method: str = setting("LSODA", "", "scipy solve_ivp method", choices=METHODS)

    def __post_init__(self) -> None:
        check(self, ParameterError)
        samples = self.duration_s * self.sample_rate_hz
        if not MIN_SAMPLES <= samples <= MAX_SAMPLES:
            raise ParameterError(
                f"duration_s * sample_rate_hz = {samples:.6g} samples: between {MIN_SAMPLES} "
                f"and {MAX_SAMPLES} are allowed (at most a few hundred MB of modal coordinates)"
            )


@dataclass(frozen=True)
class TransientResult:
    """One simulated run, sampled at `TransientSettings.sample_rate_hz`.

    Attributes
    ----------
    speed_rad_s : float
        Screw speed Omega [rad/s].
    load_n : float
        Axial load F_z [N].
    labels : tuple of str
        Labels of the modes kept.
    omega_rad_s : numpy.ndarray
        Their natural frequencies [rad/s].
    time_s : numpy.ndarray
        Sample times [s], (T,).
    q : numpy.ndarray
        Modal coordinates, deviation from steady sliding, (T, N).
    qdot : numpy.ndarray
        Their rates, (T, N).
    q_static : numpy.ndarray
        Steady sliding q* (the static deflection under the steady friction), (N,).
    lateral_m : numpy.ndarray
        Lateral displacement (x, y) at the nut centre relative to steady sliding [m], (T, 2).
    torsion_rad : numpy.ndarray
        Torsion angle at the nut centre relative to steady sliding [rad], (T,).
    surface_velocity_m_s : numpy.ndarray
        Contact velocity minus its steady value at the nut centre, (radial, tangential) in the
        frame of the contact point [m/s], (T, 2).
    sliding_speed_m_s : numpy.ndarray
        |Vc| at the nut centre [m/s], (T,); the steady value is `steady_sliding_m_s`.
    steady_sliding_m_s : float
        R |Omega| / cos(beta) [m/s].
    jacobian_eigenvalues : numpy.ndarray
        Eigenvalues of the linearisation at q* (the exact linear system of the run) [1/s].
    evaluations : int
        Right-hand-side evaluations of the integrator (its work).
    """

    speed_rad_s: float
    load_n: float
    labels: tuple[str, ...]
    omega_rad_s: np.ndarray
    time_s: np.ndarray
    q: np.ndarray
    qdot: np.ndarray
    q_static: np.ndarray
    lateral_m: np.ndarray
    torsion_rad: np.ndarray
    surface_velocity_m_s: np.ndarray
    sliding_speed_m_s: np.ndarray
    steady_sliding_m_s: float
    jacobian_eigenvalues: np.ndarray
    evaluations: int


def kept_basis(basis: ModalBasis, modes: int) -> tuple[ModalBasis, np.ndarray]:
    """The `modes` lowest-frequency modes of `basis` in basis order (all when 0), and their
    indices in `basis`."""
    keep = (
        np.arange(basis.n)
        if modes == 0 or modes >= basis.n
        else np.sort(np.argsort(basis.omega_rad_s, kind="stable")[:modes])
    )
    if len(keep) == basis.n:
        return basis, keep
    return replace(
        basis,
        labels=tuple(basis.labels[i] for i in keep),
        **{f.name: getattr(basis, f.name)[keep] for f in fields(basis) if f.name != "labels"},
    ), keep


class ModalEquations:
    """The nonlinear first-order system of the module docstring about steady sliding.

    Parameters
    ----------
    params : ScrewParameters
        Screw, nut and friction.
    speed_rad_s : float
        Screw speed Omega [rad/s].
    load_n : float
        Axial load F_z [N].
    settings : TransientSettings
        Modes kept, regularisation and quadrature.
    """

    def __init__(
        self,
        params: ScrewParameters,
        speed_rad_s: float,
        load_n: float,
        settings: TransientSettings,
    ):
        self.basis, self.keep = kept_basis(modal_basis(params), settings.modes)
        self.friction = HelixFriction(
            params,
            self.basis,
            speed_rad_s,
            load_n,
            settings.regularisation_m_s,
            settings.points_per_turn,
        )
        om, n = self.basis.omega_rad_s, self.basis.n
        self.n = n
        self.stiffness = np.diag(om**2 - speed_rad_s**2)
        self.damping = np.diag(2 * params.modal_damping * om) + speed_rad_s * gyroscopic_unit(
            self.basis
        )
        self.q_static = self._static_deflection()
        self.q_force_static = self.friction.force(self.q_static, np.zeros(n))

    def _static_deflection(self) -> np.ndarray:
        """q* with K q* = Q(q*, 0), by Newton from 0 (the friction's dependence on q is weak:
        a few iterations reach round-off)."""
        q, zero = np.zeros(self.n), np.zeros(self.n)
        for _ in range(50):
            force, jq, _ = self.friction.force(q, zero, jacobian=True)
            try:
                step = np.linalg.solve(self.stiffness - jq, force - self.stiffness @ q)
            except np.linalg.LinAlgError:
                raise ParameterError(
                    "no steady sliding: the static stiffness is singular (a critical speed)"
                ) from None
            q = q + step
            if np.abs(step).max() <= 1e-13 * max(np.abs(q).max(), 1e-300):
                return q
        raise ParameterError(
            "no steady sliding: the static deflection under the steady friction did not converge"
        )

    def rhs(self, _t: float, y: np.ndarray) -> np.ndarray:
        """d/dt (dq, dqdot) of the deviation dq = q - q* from steady sliding.

        Parameters
        ----------
        _t : float
            Time [s] (the equations are autonomous; the integrator passes it).
        y : ndarray
            State (dq, dqdot), shape (2N,).

        Returns
        -------
        ndarray
            Its time derivative, shape (2N,).
        """
        n = self.n
        dq, dqdot = y[:n], y[n:]
        force = self.friction.force(self.q_static + dq, dqdot) - self.q_force_static
        return np.concatenate((dqdot, force - self.stiffness @ dq - self.damping @ dqdot))

    def jacobian(self, _t: float, y: np.ndarray) -> np.ndarray:
        """The state matrix of the linearisation at the state y.

        Parameters
        ----------
        _t : float
            Time [s] (unused, as in `rhs`).
        y : ndarray
            State (dq, dqdot), shape (2N,).

        Returns
        -------
        ndarray
            d rhs / dy, shape (2N, 2N).
        """
        n = self.n
        _, jq, jd = self.friction.force(self.q_static + y[:n], y[n:], jacobian=True)
        out = np.zeros((2 * n, 2 * n))
        out[:n, n:] = np.eye(n)
        out[n:, :n] = jq - self.stiffness
        out[n:, n:] = jd - self.damping
        return out

    def modal_velocity_scale(self) -> np.ndarray:
        """Peak contact-point velocity per unit modal rate of each mode.

        Returns
        -------
        ndarray
            (N,) [m/s per unit qdot]: the amplitude of the shape, times R for torsion.
        """
        b = self.basis
        return b.amplitude * np.where(b.kind == KIND_T, self.friction.params.radius_m, 1.0)


def _nut_centre(eq: ModalEquations, q: np.ndarray, qdot: np.ndarray) -> dict[str, np.ndarray]:
    """Deflections and contact velocity at the middle of the nut, per sample."""
    p, b = eq.friction.params, eq.basis
    alpha_o, alpha = contact_angles(p)
    theta = alpha_o + alpha / 2
    phi = b.shapes(np.array([p.lead_per_rad_m * theta]))[:, 0]
    per_kind = [np.where(b.kind == k, phi, 0.0) for k in (KIND_X, KIND_Y, KIND_T)]
    s, c, r, om = math.sin(theta), math.cos(theta), p.radius_m, eq.friction.speed
    (x, y, z), (xd, yd, zd) = ([qq @ k for k in per_kind] for qq in (q, qdot))
    radial = om * (s * x - c * y - r * z) + c * xd + s * yd  # (3)
    tangential = om * (c * x + s * y) - s * xd + c * yd + r * zd
    xs, ys, zs = (eq.q_static @ k for k in per_kind)
    steady = eq.friction.v0 + np.array(
        [om * (s * xs - c * ys - r * zs), om * (c * xs + s * ys), 0.0]
    )
    vc = np.stack((steady[0] + radial, steady[1] + tangential, np.full_like(radial, steady[2])))
    return {
        "lateral": np.stack((x, y), 1),
        "torsion": z,
        "surface": np.stack((radial, tangential), 1),
        "sliding": np.sqrt((vc * vc).sum(0)),
    }


def simulate(
    params: ScrewParameters,
    speed_rad_s: float,
    load_n: float,
    settings: TransientSettings | None = None,
) -> TransientResult:
    """Integrate the nonlinear modal equations from steady sliding plus a perturbation.

    Parameters
    ----------
    params : ScrewParameters
        Screw, nut and friction (any formulation: the force is the nonlinear one).
    speed_rad_s : float
        Screw speed Omega [rad/s]: MIN_SPEED_RAD_S <= |Omega| < the first critical speed.
    load_n : float
        Axial load F_z [N].
    settings : TransientSettings, optional
        Duration, sampling, modes, regularisation, perturbation; defaults when None.

    Returns
    -------
    TransientResult
        The sampled run.

    Raises
    ------
    OperatingPointError
        Speed or load not a finite number, or the load implausibly large.
    ParameterError
        |speed| below MIN_SPEED_RAD_S or at or above the first critical speed, no
        steady sliding, or the integrator failed.
    """
    settings = settings or TransientSettings()
    speed_rad_s, load_n = check_operating_point(speed_rad_s, load_n)
    if speed_rad_s == 0:
        raise ParameterError("speed = 0: there is no steady sliding to start from")
    if abs(speed_rad_s) < MIN_SPEED_RAD_S:  # else LSODA's "Unexpected istate" (underflow)
        raise ParameterError(
            f"|speed| = {exact(abs(speed_rad_s))} rad/s is below "
            f"{MIN_SPEED_RAD_S:g} rad/s: no steady sliding to simulate"
        )
    critical = float(modal_basis(params).omega_rad_s.min())  # SqueakModel's, the full basis
    if abs(speed_rad_s) >= critical:  # else an overflow or a static divergence
        raise ParameterError(
            f"|speed| = {exact(abs(speed_rad_s))} rad/s is at or above the "
            f"first critical speed {critical:.4g} rad/s: the model holds "
            f"below it"
        )
    eq = ModalEquations(params, speed_rad_s, load_n, settings)
    n, om = eq.n, eq.basis.omega_rad_s
    sliding = params.radius_m * abs(speed_rad_s) / math.cos(params.helix_angle_rad)
    scale = settings.perturbation * sliding / eq.modal_velocity_scale()
    # drawn for every mode of the basis, so a mode starts the same whichever modes are kept
    draw = np.random.default_rng(settings.seed).standard_normal((2, params.n_modes))
    y0 = np.concatenate((draw[0, eq.keep] * scale / om, draw[1, eq.keep] * scale))
    count = int(round(settings.duration_s * settings.sample_rate_hz)) + 1
    t = np.arange(count) / settings.sample_rate_hz
    atol = np.concatenate((scale / om, scale)) * (ATOL_PER_RTOL * settings.rtol)
    max_step = 2 * math.pi / (STEPS_PER_PERIOD * om.max())
    jac = {} if settings.method == "DOP853" else {"jac": eq.jacobian}
    sol = solve_ivp(
        eq.rhs,
        (0.0, t[-1]),
        y0,
        method=settings.method,
        t_eval=t,
        rtol=settings.rtol,
        atol=atol,
        max_step=max_step,
        **jac,
    )
    if sol.status != 0:
        raise ParameterError(f"the integrator failed: {sol.message}")
    q, qdot = sol.y[:n].T, sol.y[n:].T
    at_nut = _nut_centre(eq, q, qdot)
    return TransientResult(
        speed_rad_s=float(speed_rad_s),
        load_n=float(load_n),
        labels=eq.basis.labels,
        omega_rad_s=om,
        time_s=sol.t,
        q=q,
        qdot=qdot,
        q_static=eq.q_static,
        lateral_m=at_nut["lateral"],
        torsion_rad=at_nut["torsion"],
        surface_velocity_m_s=at_nut["surface"],
        sliding_speed_m_s=at_nut["sliding"],
        steady_sliding_m_s=sliding,
        jacobian_eigenvalues=np.linalg.eigvals(eq.jacobian(0.0, np.zeros(2 * n))),
        evaluations=int(sol.nfev),
    )
