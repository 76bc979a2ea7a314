"""Analytic results of the servo-press paper (seed stephenson_press_servo_drive, eq. 11-35).

numpy/scipy only; no FMI. Every quantity is reduced to the crank (index "c" is dropped):

    J(phi) = J0 + J~(phi)      reduced inertia, J0 its mean over a revolution [kg m^2]
    J_D    = i^2 (J_rotor + J_flywheel)   drive inertia reduced to the crank [kg m^2]
    s      = i^2 s_motor = i^2 k_phi^2/R_a   slope of the static characteristic [N m s/rad]
    D      = i mu u0 = i k_phi u0/R_a        stall moment of the drive at the crank [N m]
    tau    = L_a/R_a                          electrical time constant [s]
    theta  = -dM_C0/dphi'                     slope of the mean resistance (0 for this press)

Equation of motion (eq. 1, 5; static law or electrical lag):
    J(phi) phi'' + 1/2 J'(phi) phi'^2 = i M_D + M_C(phi),   tau (i M_D)' + i M_D = D - s phi'.

The derivations (and the points where the printed paper is wrong) are in
docs/stephenson_press_analysis.md; each function's docstring names its equation.

Conventions: a harmonic l of a periodic signal x(t) of fundamental nu is written
    x(t) = sum_l X_l cos(l nu t + alpha_l) = sum_l Re[Xc_l exp(i l nu t)], Xc_l = X_l e^{i alpha_l},
so amplitude and phase are |Xc_l| and arg Xc_l. With phi0 = omega0 t the same series is a series
in the crank angle phi0.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

ArrayFunction = Callable[[np.ndarray], np.ndarray]

DEFAULT_SAMPLES = 1 << 14  # points per revolution for means and FFTs (the forging kinks make the
#                            harmonics decay as 1/l^2: aliasing error ~ (l/N)^2, negligible here)


# ---------------------------------------------------------------------------------------------
# The reduced drive
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class ReducedDrive:
    """Press plus DC drive reduced to the crank (all SI).

    J        callable phi -> J(phi) [kg m^2], the full reduced inertia including J_D
    half_dJ  callable phi -> J'(phi)/2 [kg m^2/rad]
    M_C      callable phi -> M_C(phi) [N m], resistance moment (forging + weights)
    J_D      drive inertia at the crank, i^2 (J_rotor + J_flywheel) [kg m^2]
    D        stall moment i mu u0 [N m]
    s        reduced slope i^2 k_phi^2/R_a [N m s/rad]
    tau      electrical time constant L_a/R_a [s] (used only by the lag formulas)
    theta    slope of the mean resistance moment [N m s/rad] (0: M_C depends on phi only)
    kinks    crank angles [rad] where M_C has a kink (ends of the forging window); means of M_C
             are then integrated piecewise (Gauss-Legendre) instead of by the trapezoidal rule,
             whose error at a kink is O(h^2)
    """

    J: ArrayFunction
    half_dJ: ArrayFunction
    M_C: ArrayFunction
    J_D: float
    D: float
    s: float
    tau: float = 0.0
    theta: float = 0.0
    kinks: tuple = ()

    @classmethod
    def from_models(cls, press, motor, u0: float) -> "ReducedDrive":
        """Build from a StephensonPress and a DcServoMotor (crankfmu.models objects).

        u0 [V] is the constant armature voltage (speed loop off)."""
        i = press.p.gear_ratio
        J_input = motor.p.J_rotor + motor.p.J_flywheel
        kinks: tuple[float, ...] = ()
        if press.on("forging_load"):
            a = press.p.forging_angle
            kinks = ((0.5 * math.pi - a) % (2 * math.pi), (0.5 * math.pi) % (2 * math.pi))
        return cls(J=lambda phi: press.reduced_inertia(phi, J_input)[0],
                   half_dJ=lambda phi: press.reduced_inertia(phi, J_input)[1],
                   M_C=press.resistance_moment,
                   J_D=i * i * J_input, D=i * motor.mu * u0, s=i * i * motor.s, tau=motor.tau,
                   kinks=kinks)


def angle_average(f: ArrayFunction, kinks=(), pieces: int = 64, order: int = 20) -> float:
    """(1/2pi) int_0^2pi f(phi) dphi, piecewise Gauss-Legendre between the kink angles (each
    span cut into `pieces` parts of equal length overall, `order` nodes per part): exact to
    round-off for the piecewise smooth M_C of the press."""
    cuts = np.unique(np.concatenate([np.mod(np.asarray(kinks, dtype=float), 2 * math.pi),
                                     2 * math.pi * np.arange(pieces + 1) / pieces]))
    x, w = np.polynomial.legendre.leggauss(order)
    a, b = cuts[:-1, None], cuts[1:, None]
    nodes = 0.5 * (a + b) + 0.5 * (b - a) * x
    weights = 0.5 * (b - a) * w
    return float(np.sum(weights * f(nodes.ravel()).reshape(nodes.shape)) / (2 * math.pi))


def crank_grid(n: int = DEFAULT_SAMPLES) -> np.ndarray:
    """n equally spaced crank angles phi_k = 2 pi k/n over one revolution [rad]."""
    return 2.0 * math.pi * np.arange(n) / n


def mean_inertia(drive: ReducedDrive, n: int = DEFAULT_SAMPLES) -> float:
    """J0 = (1/2pi) int J(phi) dphi [kg m^2], the constant part of eq. (8)/(22).

    The paper's J0 = i^2 J_D + J1 + J_2O (eq. 22) leaves the mean of m5 S'^2 in J~; here J~ has
    zero mean, as the first approximation requires (the paper's choice only shifts J0 by
    m5 <S'^2>, about 1 % for the servo press)."""
    return float(np.mean(drive.J(crank_grid(n))))


# ---------------------------------------------------------------------------------------------
# Mean speed (eq. 11-14 and the energy balance)
# ---------------------------------------------------------------------------------------------
def mean_speed(drive: ReducedDrive, n: int = DEFAULT_SAMPLES) -> float:
    """Steady mean crank speed omega0 [rad/s] by the energy balance over one revolution:

        omega0 = (i mu u0 + <M_C>)/(i^2 s_motor) = (D + <M_C>)/s,

    <M_C> the mean of M_C over the crank angle [N m]. This is the finite root of the paper's
    quadratic (12)-(13) (see `mean_speed_quadratic`). With the static law it is *exact* for the
    angle mean (1/2pi) int phi' dphi of the periodic motion (integrate eq. 1 times phi' over a
    period: the kinetic energy returns, int (D - s phi') dphi + int M_C dphi = 0); the time mean
    2pi/T differs from it by var(phi')/<phi'>, second order in the non-uniformity."""
    return (drive.D + mean_resistance(drive, n)) / drive.s


def mean_resistance(drive: ReducedDrive, n: int = DEFAULT_SAMPLES) -> float:
    """<M_C> = (1/2pi) int M_C dphi [N m] (piecewise Gauss-Legendre when drive.kinks is set,
    else the n-point trapezoidal rule)."""
    if drive.kinks:
        return angle_average(drive.M_C, drive.kinks)
    return float(np.mean(drive.M_C(crank_grid(n))))


@dataclass(frozen=True)
class MeanSpeedQuadratic:
    """The paper's quadratic (12) omega^2 + p omega + d = 0 over n equally spaced positions.

    sum_dJ      sum_k J'(phi_k) [kg m^2/rad] (zero up to round-off: it degenerates (12))
    sum_abs_dJ  sum_k |J'(phi_k)|, the scale against which sum_dJ is zero
    p, d        coefficients of (12) [rad/s], [rad^2/s^2] (inf when sum_dJ is exactly 0)
    roots_printed  the two roots by the printed formula (13) (cancellation: meaningless)
    root_finite    the finite root computed stably, -2d/(p + sqrt(p^2 - 4d)),
                   which tends to (n D + sum M_C)/(n s)
    """

    n: int
    sum_dJ: float
    sum_abs_dJ: float
    p: float
    d: float
    roots_printed: tuple[float, float]
    root_finite: float


def mean_speed_quadratic(drive: ReducedDrive, n: int = 360,
                         phi: np.ndarray | None = None) -> MeanSpeedQuadratic:
    """Eq. (11)-(13): sum (11) over n crank positions phi_k (equally spaced unless `phi` given):

        n D - n s omega0 = 1/2 omega0^2 sum J'(phi_k) - sum M_C(phi_k)
        => omega0^2 + p omega0 + d = 0,  p = 2 n s/sum J',  d = -2 (n D + sum M_C)/sum J'.

    J' is the derivative of a periodic function, so its mean is zero, and the trapezoidal sum over
    equally spaced points of a smooth periodic function is its mean to spectral accuracy: sum J' = 0
    to round-off. Then p, d -> infinity and (13) degenerates: one root runs off to -infinity, the
    other tends to the energy balance omega0 = (n D + sum M_C)/(n s) (`mean_speed`). The printed
    formula (13) evaluates that root as a difference of two huge numbers and returns noise; the
    stable form -2 d/(p + sqrt(p^2 - 4 d)) returns it. Units: rad/s."""
    if phi is None:
        phi = 2.0 * math.pi * np.arange(n) / n
    phi = np.asarray(phi, dtype=float)
    n = phi.size
    dJ = 2.0 * np.asarray(drive.half_dJ(phi))
    sum_dJ, sum_abs = float(np.sum(dJ)), float(np.sum(np.abs(dJ)))
    drive_term = n * drive.D + float(np.sum(drive.M_C(phi)))
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        p = 2.0 * n * drive.s / sum_dJ if sum_dJ != 0.0 else math.inf
        d = -2.0 * drive_term / sum_dJ if sum_dJ != 0.0 else -math.copysign(math.inf, drive_term)
        disc = math.sqrt(p * p / 4.0 - d) if math.isfinite(p) else math.inf
        roots = (-p / 2.0 + disc, -p / 2.0 - disc)
    if math.isfinite(p) and math.isfinite(d):
        q = p / 2.0 + math.copysign(disc, p)
        finite = -d / q
    else:  # exactly degenerate: the linear equation n s omega0 = n D + sum M_C remains
        finite = drive_term / (n * drive.s)
    return MeanSpeedQuadratic(n, sum_dJ, sum_abs, p, d, roots, finite)


# ---------------------------------------------------------------------------------------------
# Disturbance moment and its Fourier series (eq. 18, 20)
# ---------------------------------------------------------------------------------------------
def disturbance_moment(drive: ReducedDrive, omega0: float, phi: np.ndarray,
                       n: int = DEFAULT_SAMPLES) -> np.ndarray:
    """L at crank angles phi = omega0 t [N m], eq. (18):

        L(t) = -1/2 J~'(omega0 t) omega0^2 + M~_C(omega0 t),

    J~' = J' (the derivative of the zero-mean part), M~_C = M_C - <M_C> (zero mean)."""
    mean_MC = mean_resistance(drive, n)
    phi = np.asarray(phi, dtype=float)
    return -drive.half_dJ(phi) * omega0 ** 2 + (drive.M_C(phi) - mean_MC)


@dataclass(frozen=True)
class Harmonics:
    """Fourier series x = sum_{l>=1} amp_l cos(l nu t + phase_l) of a zero-mean periodic signal.

    l      harmonic numbers 1..N
    amp    amplitudes [unit of the signal]
    phase  phases alpha_l [rad]
    nu     fundamental [rad/s] (the crank speed omega0)
    """

    l: np.ndarray
    amp: np.ndarray
    phase: np.ndarray
    nu: float

    @property
    def complex(self) -> np.ndarray:
        """Xc_l = amp_l exp(i phase_l)."""
        return self.amp * np.exp(1j * self.phase)

    def __call__(self, t) -> np.ndarray:
        """Evaluate the (truncated) series at times t [s]."""
        t = np.asarray(t, dtype=float)
        return np.real(np.exp(1j * np.multiply.outer(t, self.l * self.nu)) @ self.complex)


def fourier_harmonics(samples: np.ndarray, n_harmonics: int, nu: float) -> Harmonics:
    """Harmonics l = 1..n_harmonics of a periodic signal sampled at n equally spaced points of
    one period (FFT): Xc_l = 2 c_l, c_l = (1/n) sum_k x_k exp(-i l 2pi k/n)."""
    samples = np.asarray(samples, dtype=float)
    c = np.fft.rfft(samples) / samples.size
    if n_harmonics >= samples.size // 2:
        raise ValueError("n_harmonics must be below half the number of samples")
    Xc = 2.0 * c[1:n_harmonics + 1]
    return Harmonics(np.arange(1, n_harmonics + 1), np.abs(Xc), np.angle(Xc), nu)


def disturbance_harmonics(drive: ReducedDrive, omega0: float | None = None,
                          n_harmonics: int = 200, n: int = DEFAULT_SAMPLES) -> Harmonics:
    """Fourier series of L(t), eq. (20): L(t) = sum_l L_l cos(l nu t + alpha_l), nu = omega0.

    L_l [N m], alpha_l [rad], computed by FFT over one revolution (n samples)."""
    if omega0 is None:
        omega0 = mean_speed(drive, n)
    L = disturbance_moment(drive, omega0, crank_grid(n), n)
    return fourier_harmonics(L, n_harmonics, omega0)


# ---------------------------------------------------------------------------------------------
# Dynamic error: first approximation, with and without the electrical lag (eq. 19-20, 33-35)
# ---------------------------------------------------------------------------------------------
def speed_error_response(Omega, J0: float, s: float, theta: float = 0.0,
                         tau: float = 0.0) -> np.ndarray:
    """Complex frequency response H(i Omega) = psi'/L of the first approximation [rad/(N m s)].

    Without lag (tau = 0), eq. (19) with the resistance slope theta:
        J0 psi'' + (s + theta) psi' = L   =>   H = 1/((s + theta) + i Omega J0).
    With the electrical lag, eq. (33): J0 psi'' + theta psi' - mu = L, tau mu' + mu + s psi' = 0
    (mu the deviation of the drive moment i M_D from its mean, at the crank). For exp(i Omega t):
        mu = -s psi'/(1 + i Omega tau),
        H  = (1 + i Omega tau)/[(s + theta - tau J0 Omega^2) + i Omega (J0 + tau theta)],
    the transfer function of the third-order equation (34)
        tau J0 psi''' + (J0 + tau theta) psi'' + (s + theta) psi' = tau L' + L.
    Omega [rad/s] may be an array; J0 [kg m^2]; s, theta [N m s/rad]; tau [s]."""
    Omega = np.asarray(Omega, dtype=float)
    jw = 1j * Omega
    return (1.0 + jw * tau) / ((s + theta) * 1.0 + jw * J0 + jw * tau * (jw * J0 + theta))


def drive_moment_response(Omega, J0: float, s: float, theta: float = 0.0,
                          tau: float = 0.0) -> np.ndarray:
    """Complex response mu/L of the drive-moment deviation mu = i M_D - <i M_D> [1]:
    mu = -s/(1 + i Omega tau) psi' (eq. 33, second line; tau = 0: mu = -s psi')."""
    Omega = np.asarray(Omega, dtype=float)
    return -s / (1.0 + 1j * Omega * tau) * speed_error_response(Omega, J0, s, theta, tau)


@dataclass(frozen=True)
class DynamicError:
    """First approximation phi' = omega0 + psi'(t), phi = omega0 t + psi(t) (eq. 19-20, 33-35).

    omega0  mean crank speed [rad/s] (also the fundamental nu of L)
    J0      mean reduced inertia [kg m^2]
    s, theta, tau   as in `speed_error_response`
    L       Harmonics of the disturbance moment [N m]
    H       complex psi'/L per harmonic [rad/(N m s)]
    """

    omega0: float
    J0: float
    s: float
    theta: float
    tau: float
    L: Harmonics
    H: np.ndarray = field(repr=False)

    @property
    def speed_error(self) -> Harmonics:
        """psi'(t) as Harmonics [rad/s]: amplitude L_l |H_l|, phase alpha_l + arg H_l. Without
        lag this is eq. (20), psi' = -sum L_l sin(l nu t + alpha_l + delta_l)/sqrt(J0^2 l^2 nu^2
        + (s+theta)^2), delta_l = atan((s+theta)/(J0 l nu)) + pi (the same function)."""
        Vc = self.L.complex * self.H
        return Harmonics(self.L.l, np.abs(Vc), np.angle(Vc), self.omega0)

    @property
    def angle_error(self) -> Harmonics:
        """psi(t) (zero-mean periodic part) as Harmonics [rad]: amplitude L_l |H_l|/(l nu), eq. (20)
        (the amplitude the paper calls alpha_l, reusing the symbol of the phase of L)."""
        Vc = self.L.complex * self.H / (1j * self.L.l * self.omega0)
        return Harmonics(self.L.l, np.abs(Vc), np.angle(Vc), self.omega0)

    def psi_dot(self, t) -> np.ndarray:
        """Speed error psi'(t) [rad/s] at times t [s] (phi0 = omega0 t)."""
        return self.speed_error(t)

    def psi(self, t) -> np.ndarray:
        """Angle error psi(t) [rad] (the periodic solution with zero mean)."""
        return self.angle_error(t)

    def omega(self, t) -> np.ndarray:
        """Crank speed omega0 + psi'(t) [rad/s]."""
        return self.omega0 + self.psi_dot(t)

    def speed_on_revolution(self, n: int = 4096) -> np.ndarray:
        """psi' at the n instants t_k = k T/n of one period T = 2pi/omega0 [rad/s] (inverse FFT of
        the series, harmonics above n/2 - 1 dropped)."""
        keep = self.L.l < n // 2
        spec = np.zeros(n // 2 + 1, dtype=complex)
        spec[self.L.l[keep]] = (self.L.complex * self.H)[keep] * (n / 2.0)
        return np.fft.irfft(spec, n)

    @property
    def delta(self) -> float:
        """Non-uniformity (w_max - w_min)/w_mean [1] of the first approximation, with
        w = omega0 + psi', w_mean = omega0."""
        return nonuniformity(self)


def dynamic_error(drive: ReducedDrive, lag: bool = False, n_harmonics: int = 200,
                  n: int = DEFAULT_SAMPLES) -> DynamicError:
    """First approximation of the periodic motion (eq. 18-20 without lag, 32-35 with lag).

    Zeroth approximation phi0 = omega0 t, omega0 = `mean_speed`. Putting it into the right-hand
    side of (8) gives (18)/(32); with psi = phi1 - omega0 t and the static law (linear in phi'),
    J0 psi'' + s psi' = L(t)  (19), or with the lag the pair (33). Solved per harmonic of L by
    `speed_error_response` with J0 the mean reduced inertia, s = i^2 s_motor, theta = drive.theta,
    tau = drive.tau if lag else 0."""
    omega0 = mean_speed(drive, n)
    J0 = mean_inertia(drive, n)
    L = disturbance_harmonics(drive, omega0, n_harmonics, n)
    tau = drive.tau if lag else 0.0
    H = speed_error_response(L.l * omega0, J0, drive.s, drive.theta, tau)
    return DynamicError(omega0, J0, drive.s, drive.theta, tau, L, H)


def nonuniformity(err: DynamicError, n: int = 8192) -> float:
    """delta = (w_max - w_min)/w_mean [1] from the first approximation w = omega0 + psi'(t)
    (max and min of psi' over one period, evaluated on n points by inverse FFT)."""
    v = err.speed_on_revolution(n)
    return float((v.max() - v.min()) / err.omega0)


# ---------------------------------------------------------------------------------------------
# Transmission moment, counterweight (eq. 23-25), flywheel (eq. 26-28)
# ---------------------------------------------------------------------------------------------
def transmission_moment_ratio(Omega: float, J_D: float, J0: float, s: float,
                              theta: float = 0.0) -> float:
    """(M_pl/L_l)^2 of eq. (23)/(24) [1]: squared ratio of the amplitude of harmonic l of the
    moment transmitted by the gear, M_p = i M_D - J_D phi'' (variable part: -s psi' - J_D psi''),
    to the amplitude L_l of the disturbance:
        (M_pl/L_l)^2 = (s^2 + J_D^2 Omega^2)/((s + theta)^2 + J0^2 Omega^2),  Omega = l nu.
    J_D is the drive inertia reduced to the crank (i^2 J_rotor; the paper writes J_D), J0 the
    total constant inertia [kg m^2]; s, theta [N m s/rad]; Omega [rad/s]."""
    return (s * s + (J_D * Omega) ** 2) / ((s + theta) ** 2 + (J0 * Omega) ** 2)


def counterweight_mass(J_D: float, J1: float, r: float) -> float:
    """Eq. (25): m2 = -(J_D + J1)/r^2 [kg], J_D = i^2 J_rotor (drive inertia at the crank)
    [kg m^2], J1 [kg m^2], r [m].

    This is where d/dJ_2O of (24) vanishes, J_2O = m2 r^2 = -J_O1 (J_O1 = J_D + J1), i.e. the
    constant inertia J_O1 + J_2O is zero. It is a *maximum* of (24), not a minimum: (24) has its
    denominator (s + theta)^2 + (J_O1 + J_2O)^2 Omega^2 smallest there, and (24) decreases
    monotonically for J_2O > -J_O1 (`counterweight_stationary_point`). The mass is negative
    (impossible), and a real counterweight (a positive mass opposite the pin) still adds
    + m r^2 to J_2O. The paper's "minimum" and its reading of the sign as a counterweight are
    wrong: for m2 >= 0, a heavier base link always lowers (24)."""
    return -(J_D + J1) / r ** 2


@dataclass(frozen=True)
class StationaryPoint:
    """Kind of the stationary point of (24) in J_2O.

    J_2O     location [kg m^2]   (= -J_O1)
    m2       the corresponding mass J_2O/r^2 [kg]
    value    (24) there [1]
    d1, d2   first and second derivative of (24) with respect to J_2O there
    kind     "maximum" or "minimum"
    """

    J_2O: float
    m2: float
    value: float
    d1: float
    d2: float
    kind: str


def counterweight_stationary_point(Omega: float, J_D: float, J1: float, r: float, s: float,
                                   theta: float = 0.0) -> StationaryPoint:
    """Classify the stationary point of (24) f(x) = (s^2 + J_D^2 W^2)/((s+theta)^2 + (J_O1+x)^2 W^2)
    (x = J_2O, W = Omega = l nu, J_O1 = J_D + J1) analytically:
        f'(x)  = -2 W^2 (J_O1 + x) N/Q^2,   zero only at x = -J_O1,
        f''(-J_O1) = -2 W^2 N/(s + theta)^4 < 0   => maximum.
    N = s^2 + J_D^2 W^2, Q = (s+theta)^2 + (J_O1+x)^2 W^2."""
    J_O1 = J_D + J1
    x = -J_O1
    N = s * s + (J_D * Omega) ** 2
    Q = (s + theta) ** 2
    d1 = -2.0 * Omega ** 2 * (J_O1 + x) * N / Q ** 2
    d2 = -2.0 * Omega ** 2 * N / Q ** 2
    return StationaryPoint(x, x / r ** 2, N / Q, d1, d2, "maximum" if d2 < 0 else "minimum")


def flywheel_inertia(Omega: float, J_D: float, J_M0: float, s: float,
                     theta: float = 0.0) -> float:
    """Eq. (27): flywheel inertia J_Mx on the motor shaft, reduced to the crank [kg m^2], that
    minimises the transmission-moment ratio (26)
        R(J_Mx) = (s^2 + (J_D + J_Mx)^2 W^2)/((s + theta)^2 + (J_D + J_M0 + J_Mx)^2 W^2),
    W = Omega = l nu [rad/s] (the paper's omega^2 = l^2 nu^2), J_D the drive inertia at the crank,
    J_M0 the constant inertia of everything else (J1 + J_2O + mean of the mechanism's variable
    part) [kg m^2], s, theta [N m s/rad].

    Derivation (y = J_D + J_Mx, the whole inertia on the motor side, m = J_M0):
    dR/dy = 0  <=>  m W^2 y^2 + (m^2 W^2 + 2 s theta + theta^2) y - m s^2 = 0, whose roots have
    product -s^2/W^2 < 0; dR/dy < 0 between them and > 0 beyond the positive one, so the
    positive root is the minimum (the negative one a maximum, unphysical):
        J_Mx = -J_D + [-(2 s theta + theta^2 + m^2 W^2) + sqrt((2 s theta + theta^2 + m^2 W^2)^2
               + 4 W^2 s^2 m^2)]/(2 W^2 m),
    which is the printed (27). What the paper gets wrong or leaves ambiguous: (a) it writes
    J0* = J_M0 + J_Mx, omitting J_D; with J0* = J_D + J_M0 + J_Mx (the only reading under which
    (27) is the minimiser of (26), derived above) the formula holds; (b) "omega" in (27)-(28) is
    l nu, not a speed, and the harmonic l must be chosen (l = 1, the dominant one, here); (c) the
    result may be negative: then the rotor alone exceeds the optimum and no flywheel is best;
    (d) (26) is the ratio of the transmitted moment to the disturbance, not the speed error: the
    non-uniformity falls monotonically with any flywheel, while (26) has an optimum because the
    flywheel's own inertia torque passes through the gear."""
    m, W2 = J_M0, Omega * Omega
    b = 2.0 * s * theta + theta * theta + m * m * W2
    # stable positive root of m W2 y^2 + b y - m s^2 = 0: y = 2 m s^2/(b + sqrt(b^2 + 4 W2 s^2 m^2))
    y = 2.0 * m * s * s / (b + math.sqrt(b * b + 4.0 * W2 * s * s * m * m))
    return y - J_D


def flywheel_inertia_theta0(Omega: float, J_D: float, J_M0: float, s: float) -> float:
    """Eq. (28), theta = 0: J_Mx = -J_D - J_M0/2 + sqrt(J_M0^2/4 + s^2/W^2) [kg m^2],
    W = Omega = l nu [rad/s]; same symbols as `flywheel_inertia`."""
    return -J_D - 0.5 * J_M0 + math.sqrt(0.25 * J_M0 ** 2 + (s / Omega) ** 2)


def flywheel_ratio(J_Mx: float, Omega: float, J_D: float, J_M0: float, s: float,
                   theta: float = 0.0) -> float:
    """(26) [1]: (s^2 + (J_D + J_Mx)^2 W^2)/((s + theta)^2 + (J_D + J_M0 + J_Mx)^2 W^2)."""
    return transmission_moment_ratio(Omega, J_D + J_Mx, J_D + J_M0 + J_Mx, s, theta)


def solve_for_voltage(drive_at_unit_voltage: ReducedDrive, omega0: float,
                      n: int = DEFAULT_SAMPLES) -> float:
    """Problem 3 of the paper: the voltage u0 [V] that gives the mean speed omega0 [rad/s].
    `drive_at_unit_voltage` is the drive built with u0 = 1 V (so its D is i mu):
        u0 = (s omega0 - <M_C>)/(i mu)."""
    mean_MC = mean_resistance(drive_at_unit_voltage, n)
    return (drive_at_unit_voltage.s * omega0 - mean_MC) / drive_at_unit_voltage.D


def mean_speed_second_order(err: DynamicError) -> tuple[float, float]:
    """Second-order estimates of the two mean speeds of the periodic motion [rad/s]:
    (time mean 2pi/T, angle mean (1/2pi) int phi' dphi), from the first approximation.

    Energy over a period, eq. (1) times phi' (kinetic energy returns):
        <i M_D phi'>_t + <M_C>_phi <phi'>_t = 0,   <i M_D>_t = D - s <phi'>_t
    =>  <phi'>_t = omega0 + cov(i M_D, phi')/(s <phi'>_t),
    and with mu_l = -s psi'_l/(1 + i l nu tau) (eq. 33), cov = -s sum |psi'_l|^2/(2(1 + l^2 nu^2
    tau^2)). The angle mean is <phi'^2>_t/<phi'>_t = <phi'>_t + var(psi')/omega0:
        time mean  = omega0 - sum_l |psi'_l|^2/(2 omega0 (1 + (l nu tau)^2)),
        angle mean = omega0 + sum_l |psi'_l|^2 (l nu tau)^2/(2 omega0 (1 + (l nu tau)^2)).
    Without lag the angle mean is omega0 exactly (see `mean_speed`)."""
    V2 = err.speed_error.amp ** 2
    x2 = (err.L.l * err.omega0 * err.tau) ** 2
    w0 = err.omega0
    return (w0 - float(np.sum(V2 / (1.0 + x2))) / (2.0 * w0),
            w0 + float(np.sum(V2 * x2 / (1.0 + x2))) / (2.0 * w0))


@dataclass(frozen=True)
class PeriodicApproximation:
    """Approximation k of the method of successive approximations (eq. 9-10).

    k       approximation number (1 = the first approximation of eq. 18-20 / 32-35)
    Omega   its mean crank speed (time mean) [rad/s]
    theta   n equally spaced values of Omega t over one period [rad]
    psi     the angle error at theta: phi = theta + psi [rad]
    w       the crank speed phi' at theta [rad/s]
    change  max |psi_k - psi_{k-1}| (eq. 10) [rad]
    """

    k: int
    Omega: float
    theta: np.ndarray
    psi: np.ndarray
    w: np.ndarray
    change: float

    @property
    def phi(self) -> np.ndarray:
        return self.theta + self.psi

    @property
    def delta(self) -> float:
        """(w_max - w_min)/w_mean, w_mean = Omega [1]."""
        return float((self.w.max() - self.w.min()) / self.Omega)

    def speed_on_angle_grid(self, m: int = 4096) -> np.ndarray:
        """phi' at m equally spaced crank angles 2 pi j/m [rad/s] (periodic cubic spline through
        the samples (phi_k, w_k))."""
        from scipy.interpolate import CubicSpline
        phi = np.mod(self.phi, 2 * math.pi)
        order = np.argsort(phi)
        p, w = phi[order], self.w[order]
        p = np.append(p, p[0] + 2 * math.pi)
        w = np.append(w, w[0])
        return CubicSpline(p, w, bc_type="periodic")(2 * math.pi * np.arange(m) / m)

    def speed_harmonic(self, l: int = 1, m: int = 4096) -> complex:
        """Complex amplitude of harmonic l of phi' as a function of the crank angle [rad/s]."""
        return complex(2.0 * np.fft.rfft(self.speed_on_angle_grid(m))[l] / m)


def successive_approximations(drive: ReducedDrive, lag: bool = False, iterations: int = 6,
                              n: int = 8192) -> list[PeriodicApproximation]:
    """The paper's iteration (9), carried to any order, with the mean speed updated (eq. 9-10).

    Write the motion as phi = theta + psi(theta), theta = Omega t, psi 2pi-periodic. Given the
    approximation k-1, evaluate the right-hand side of (8)/(29)
        R(theta) = -J~(phi) phi'' - 1/2 J'(phi) phi'^2 + M_C(phi),
        phi' = Omega (1 + dpsi/dtheta),  phi'' = Omega^2 d2psi/dtheta2,
    and solve the linear left-hand side J0 phi'' - (drive moment deviation) = D + R exactly:
    the mean gives Omega_k = (D + <R>_t)/s (the constant part of the drive law), each harmonic
    R_l gives psi'_l = H(l Omega_k) R_l (`speed_error_response`, with or without lag). Starting
    from phi_0 = omega0 t, approximation 1 is the first approximation (`dynamic_error`); a fixed
    point is the exact periodic motion of eq. (1) with the static law or the lag (5). Each step
    gains a factor of the order of the relative disturbance (here a few per cent).
    n samples per period (harmonics up to n/2 - 1)."""
    J0 = mean_inertia(drive)
    omega = mean_speed(drive)
    tau = drive.tau if lag else 0.0
    theta = crank_grid(n)
    l = np.arange(1, n // 2)
    psi_c = np.zeros(l.size, dtype=complex)  # harmonics of psi(theta)
    out = []
    psi_prev = np.zeros(n)
    for k in range(1, iterations + 1):
        spec = np.zeros(n // 2 + 1, dtype=complex)
        spec[l] = psi_c * (n / 2.0)
        psi = np.fft.irfft(spec, n)
        spec[l] = 1j * l * psi_c * (n / 2.0)
        dpsi = np.fft.irfft(spec, n)
        spec[l] = -(l ** 2) * psi_c * (n / 2.0)
        ddpsi = np.fft.irfft(spec, n)
        phi = theta + psi
        w = omega * (1.0 + dpsi)
        acc = omega ** 2 * ddpsi
        R = -(drive.J(phi) - J0) * acc - drive.half_dJ(phi) * w ** 2 + drive.M_C(phi)
        c = np.fft.rfft(R) / n
        omega_new = (drive.D + float(c[0].real)) / drive.s
        V = speed_error_response(l * omega_new, J0, drive.s, drive.theta, tau) * 2.0 * c[l]
        # psi(theta) has the coefficients of psi(t) = sum Re[Psi_l exp(i l Omega t)]
        psi_c = V / (1j * l * omega_new)
        spec[l] = psi_c * (n / 2.0)
        psi_new = np.fft.irfft(spec, n)
        spec[l] = V * (n / 2.0)
        w_new = omega_new + np.fft.irfft(spec, n)
        out.append(PeriodicApproximation(k, omega_new, theta, psi_new, w_new,
                                         float(np.max(np.abs(psi_new - psi_prev)))))
        psi_prev, omega = psi_new, omega_new
    return out


__all__ = [
    "ReducedDrive", "crank_grid", "mean_inertia", "mean_speed", "MeanSpeedQuadratic",
    "mean_speed_quadratic", "disturbance_moment", "Harmonics", "fourier_harmonics",
    "disturbance_harmonics", "speed_error_response", "drive_moment_response", "DynamicError",
    "dynamic_error", "nonuniformity", "transmission_moment_ratio", "counterweight_mass",
    "StationaryPoint", "counterweight_stationary_point", "flywheel_inertia",
    "flywheel_inertia_theta0", "flywheel_ratio", "solve_for_voltage", "angle_average",
    "mean_resistance", "mean_speed_second_order", "PeriodicApproximation",
    "successive_approximations",
]
