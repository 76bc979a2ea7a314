"""The papers' figures, each analytic curve beside the simulation it approximates
(`crankfmu analyze press|impact|planetary --out DIR --plot`; docs/papers.md lists them all).

seed 000 (Stephenson servo press, crankfmu.studies.press_analysis):
    press_dynamic_error.png   psi' and psi over the crank angle: first approximation (eq. 19-20,
                              and 33-35 with the motor lag) against the periodic steady state of
                              motor + press integrated as one ODE (the FMUs' equations)
    press_base_link.png       J_2O(phi) and J(phi) with a base-link offset a != 0 (eq. 21-22,
                              Fig. 3): the printed (21), the model, and the kinetic energy of the
                              bodies from finite differences of their positions
    press_flywheel.png        eq. (26) in both conventions for J_M0 against the flywheel with (28)
                              marked and the simulated gear moment beside it; delta from the
                              first approximation against the simulated delta; the difference of
                              the two conventions' (28) against the slider mass
    press_base_link_mass.png  Fig. 4, the base link's mass (crankfmu.studies.base_link)
seed 004 (rocker impact, crankfmu.studies.rocker_analysis):
    impact_forces.png         P(t), T(t): first approximation (6), (12), second approximation
                              (14)-(18), against the RockerImpact run of the scene
    impact_stiffness.png      Figs. 2-3: the same for the three bearing constants k_n
seed 001 (planetary clutch drive, crankfmu.models.planetary_drive.planetary_drive):
    planetary.png             speeds over the four periods and the brake energies, the
                              engagement time against alpha_b, the ring brake torque needed for a
                              given engagement time: the closed form of the linear motor law
                              (piecewise matrix exponentials) against the FMU runs of the scene
    (stopping from crank angles: crankfmu.studies.planetary_stopping; seed 002's mobility
    tables: crankfmu.studies.structure.mobility)

Here only the figures and the short simulations behind them; the equations are the physics
modules' (nothing in physics/ imports this module).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..outputs import write_table
from ..system.scene import SceneError
from .progress import progress, progress_over  # noqa: F401 - progress: the analyses' notes

TWO_PI = 2.0 * math.pi
A_FIGURE = 0.08  # m: base-link offset drawn in press_base_link.png (triangle height, ~ l/3)


# =============================================================================================
# seed 000: the press's bodies from their positions (independent of crank_terms)
# =============================================================================================
def press_body_positions(press, phi: float) -> dict:
    """Positions of the press's bodies at crank angle phi [rad], from the assembly constraints
    alone (not from the model's psi, S formulas): link 2 is an equilateral triangle of height
    a = press.p.a with the crank pin A at its apex and the rods' hinges B1, B2 at A + R(theta)
    (-+b, a), b = a/sqrt(3) (b = r/sqrt(3) when a = 0: any spacing, the rods are parallel); the
    slider's hinges are at (-+b, S) on the vertical through O. Unknowns theta (link 2's rotation)
    and S, solved from |B_k - P_k| = l by Newton from theta = 0. Returns A, S2 (centre of mass,
    2a/3 below A along the height), theta, S, the rods' centres C1, C2 and angles psi1, psi2."""
    from scipy.optimize import fsolve

    p = press.p
    r, l, a = p.r, p.l, p.a
    b = abs(a) / math.sqrt(3.0) if a != 0.0 else p.r / math.sqrt(3.0)
    A = np.array([r * math.cos(phi), r * math.sin(phi)])

    def hinges(theta, S):
        R = np.array([[math.cos(theta), -math.sin(theta)], [math.sin(theta), math.cos(theta)]])
        B = [A + R @ np.array([sgn * b, a]) for sgn in (-1.0, 1.0)]
        P = [np.array([sgn * b, S]) for sgn in (-1.0, 1.0)]
        return R, B, P

    def residual(z):
        _, B, P = hinges(*z)
        return [float(np.dot(Bk - Pk, Bk - Pk) - l * l) for Bk, Pk in zip(B, P)]

    S_guess = A[1] + a + math.sqrt(max(l * l - A[0] ** 2, 0.0))
    z, _, ok, msg = fsolve(residual, [0.0, S_guess], xtol=1e-15, full_output=True)
    if ok != 1 and max(abs(x) for x in residual(z)) > 1e-20:
        raise RuntimeError(f"press assembly at phi = {phi}: {msg}")
    theta, S = z
    R, B, P = hinges(theta, S)
    C = [(Bk + Pk) / 2.0 for Bk, Pk in zip(B, P)]
    psi = [math.atan2(Pk[1] - Bk[1], Pk[0] - Bk[0]) for Bk, Pk in zip(B, P)]
    return {"A": A, "S2": A + R @ np.array([0.0, 2.0 * a / 3.0]), "theta": theta, "S": S,
            "C": C, "psi": psi}


def simulated(scene, **settings) -> np.ndarray:
    """The scene co-simulated with its master (settings as crankfmu.system.load.prepare_scene
    takes them): fmpy's structured array, "time" then "comp.var"."""
    from ..cosim.results import structured
    from ..cosim.runner import RunOptions, run_scene
    from ..system.load import prepare_scene
    result = run_scene(prepare_scene(scene, **settings), RunOptions(progress=False))
    return structured(result.recorder.names, result.recorder.rows)


def press_kinetic_inertia(press, phi, J_input: float = 0.0, h: float = 1e-5):
    """(J(phi), J_2O(phi)) [kg m^2] as 2 T/phi'^2: the kinetic energy T of every body at unit
    crank speed, the velocities by central differences (step h [rad]) of the positions of
    `press_body_positions`. Bodies: input shaft (i^2 J_input) and crank J1; link 2 (mass m2 at
    S2, plus its rotation with the polar moment m2 s^2/12 of a uniform triangle of side s =
    2a/sqrt(3)); the rods (effect rod_inertia: m_rod at C_k, m_rod l^2/12 about C_k); slider m5."""
    p = press.p
    rods = press.on("rod_inertia")
    side = 2.0 * abs(p.a) / math.sqrt(3.0)

    def one(angle):
        lo, hi = press_body_positions(press, angle - h), press_body_positions(press, angle + h)

        def d(key, k=None):
            x1, x0 = (hi[key], lo[key]) if k is None else (hi[key][k], lo[key][k])
            return (np.asarray(x1) - np.asarray(x0)) / (2.0 * h)
        J_2O = p.m2 * float(np.dot(d("S2"), d("S2"))) + p.m2 * side ** 2 / 12.0 * d("theta") ** 2
        J = p.gear_ratio ** 2 * J_input + p.J1 + J_2O + p.m5 * d("S") ** 2
        if rods:
            for k in (0, 1):
                J += p.m_rod * float(np.dot(d("C", k), d("C", k)))
                J += p.m_rod * p.l ** 2 / 12.0 * d("psi", k) ** 2
        return float(J), float(J_2O)
    out = np.array([one(float(x)) for x in np.atleast_1d(phi)])
    return out[:, 0], out[:, 1]


def base_link_inertia_printed(phi, m2: float, r: float, a: float):
    """The printed eq. (21): J_2O = m2 (r^2 + 4a^2/9 - (4/3) a r sin phi) [kg m^2]. It is
    |A' + (2a/3) e_x|^2 m2: the centre's constant offset 2a/3 counted as a velocity. For the
    translating link 2 the offset has no derivative and J_2O = m2 r^2 (model card)."""
    phi = np.asarray(phi, dtype=float)
    return m2 * (r * r + 4.0 * a * a / 9.0 - 4.0 / 3.0 * a * r * np.sin(phi))


# =============================================================================================
# seed 000: the periodic steady state of motor + press (one ODE, the FMUs' equations)
# =============================================================================================
@dataclass
class PressRevolution:
    """One revolution of the periodic steady state, sampled on an equally spaced crank-angle
    grid theta_k = 2 pi k/n (phi = 2 pi K + theta_k).

    theta   crank angle within the revolution [rad]
    t       time since phi = 2 pi K [s]
    w       crank speed phi' [rad/s]
    period  duration of the revolution [s]"""

    theta: np.ndarray
    t: np.ndarray
    w: np.ndarray
    period: float

    @property
    def psi(self) -> np.ndarray:
        """Angle error theta - Omega t, Omega = 2 pi/period, mean removed [rad]."""
        x = self.theta - TWO_PI / self.period * self.t
        return x - x.mean()

    @property
    def delta(self) -> float:
        """(w_max - w_min)/w_mean [1], w_mean = 2 pi/period (the time mean)."""
        return float((self.w.max() - self.w.min()) * self.period / TWO_PI)


@dataclass(frozen=True)
class CrankMass:
    """A point mass fixed on the crank opposite the crank pin: a counterweight.

    mass [kg] at radius [m] from the crank axis, g [m/s^2]. The crank pin is at r (cos phi,
    sin phi) with y downwards (the press model: the slider's S grows towards BDC, the base
    link's weight moment is +m2 g r cos phi); the counterweight is at -radius (cos phi, sin phi),
    so its weight moment at the crank is -mass g radius cos phi and its inertia mass radius^2."""

    mass: float
    radius: float
    g: float

    @property
    def inertia(self) -> float:
        """mass radius^2 [kg m^2], constant: a point on a rigid crank."""
        return self.mass * self.radius ** 2

    def moment(self, phi):
        """Weight moment at the crank [N m] at crank angle phi [rad] (scalar or array)."""
        return -self.mass * self.g * self.radius * np.cos(phi)


def press_steady_revolution(press, motor, u0: float, revolutions: int = 2,
                            n: int = 720, rtol: float = 1e-10,
                            crank_mass: CrankMass | None = None) -> PressRevolution:
    """Motor (DcServoMotor) and press (StephensonPress) rigidly coupled (the port convention:
    flange_w = i phi', flange_J into J) integrated as one ODE (DOP853), started at the analytic
    mean speed with the motor in equilibrium; the last of `revolutions` revolutions on n crank
    angles. The slow mode J0/s ~ 0.02 s falls by e^-18 in a revolution (0.37 s): 2 to 12
    revolutions agree with an rtol 1e-12 solution to 7.8e-9 of its speed, 2 and 3 with each
    other to 3.7e-11 of it (the servo press scene) and in the base-link sweep's delta to
    1.1e-8 relative (`crankfmu analyze press` prints the same tables); 3 revolutions cost 1.3 x
    the CPU of 2. The integration restarts at the forging window's edges
    (_across_forging_edges).
    A `crank_mass` enters through the same port as the motor: its inertia / i^2 added to
    flange_J, its weight moment / i to flange_tau (the press reduces them back to the crank)."""
    from scipy.integrate import solve_ivp
    from scipy.optimize import brentq

    from . import press_analysis as pa

    i = press.p.gear_ratio
    n_m = len(motor.state_names())
    J_extra = crank_mass.inertia / i ** 2 if crank_mass else 0.0

    def motor_u(phi, w):
        return [i * w, i * phi, u0, 0.0]

    def rhs(t, x):
        phi, w = x[0], x[1]
        x_m, u_m = x[2:], motor_u(phi, w)   # the motor's states and inputs, made once
        y = motor.output_values(t, x_m, u_m)
        tau_extra = crank_mass.moment(phi) / i if crank_mass else 0.0
        dx = [*press.derivatives(t, (phi, w), [y[0] + tau_extra, y[1] + J_extra, 0.0, 0.0])]
        if n_m:
            dx += motor.derivatives(t, x_m, u_m)
        return dx
    w0 = pa.mean_speed(pa.ReducedDrive.from_models(press, motor, u0))
    x0 = [0.0, w0] + list(motor.initial_state(motor_u(0.0, w0)))
    t_end = (revolutions + 0.5) * TWO_PI / w0
    solution = _across_forging_edges(
        lambda t, x: solve_ivp(rhs, (t, t_end), x, method="DOP853", rtol=rtol, atol=1e-10,
                               dense_output=True, events=_edges(press, x) or None),
        x0, t_end)
    K = revolutions - 1

    def t_at(phi):
        return brentq(lambda t: solution(t)[0] - phi, 0.0, t_end, xtol=1e-14, rtol=1e-15)
    t0, t1 = t_at(TWO_PI * K), t_at(TWO_PI * (K + 1))
    theta = TWO_PI * np.arange(n) / n
    # phi(t) is monotonic: invert it on a fine grid, then polish each time by Newton (w = phi')
    t_fine = np.linspace(t0, t1, 20 * n)
    t = np.interp(theta + TWO_PI * K, solution(t_fine)[0], t_fine)
    for _ in range(3):
        x = solution(t)
        t = t - (x[0] - (theta + TWO_PI * K)) / x[1]
    return PressRevolution(theta, t - t0, solution(t)[1], t1 - t0)


def _edges(press, x) -> list:
    """The press's forging-window edges around the crank angle x[0] (terminal events: where
    the load has a kink; none without the forging load), as its FMU locates them."""
    if press.on("driven_crank"):  # no crank states of its own: a driver's edges, not these
        return []
    press.restart_state = (x[0], x[1])
    return press.event_functions(None)


def _across_forging_edges(integrate, x0, t_end: float):
    """One dense solution from integrate(t, x) (a solve_ivp to t_end with dense output and
    terminal events) restarted at each event: the solver steps across no kink of the load.
    Stepping across them, where the steps fell moved the steady revolution by up to 1e-6 of
    its speed (its last revolution of 6 or 12 against 2, 3, 4, 5 or 8)."""
    from scipy.integrate import OdeSolution

    t, x, pieces = 0.0, list(x0), []
    while True:
        sol = integrate(t, x)
        if not sol.success:
            raise RuntimeError(f"press simulation failed: {sol.message}")
        pieces.append(sol.sol)
        if sol.status == 0 or sol.t[-1] >= t_end:  # an edge at the very end: done too
            break
        t, x = float(sol.t[-1]), list(sol.y[:, -1])
    ts = np.concatenate([pieces[0].ts] + [p.ts[1:] for p in pieces[1:]])
    return OdeSolution(ts, [i for p in pieces for i in p.interpolants])


# =============================================================================================
# seed 000 figures
# =============================================================================================
def press_models(scene, motor: str = "motor", press: str = "press"):
    """(StephensonPress, DcServoMotor without its lag, the same with it, u0 [V]) of a servo press
    scene (the scene's parameters and effects; speed_loop removed: the analysis is for u = u0)."""
    from ..models.dc_motor.dc_motor import DcServoMotor
    from ..models.stephenson_press.stephenson_press import StephensonPress

    p, m = _component(scene, press, "StephensonPress"), _component(scene, motor, "DcServoMotor")
    u0 = float(scene.inputs[f"{motor}.u"].values[0]) if f"{motor}.u" in scene.inputs else 220.0
    effects = [e for e in m.effects if e not in ("speed_loop", "electrical_lag")]
    return (StephensonPress(p.parameters, p.effects), DcServoMotor(m.parameters, effects),
            DcServoMotor(m.parameters, effects + ["electrical_lag"]), u0)


def dynamic_error_data(press, motor_static, motor_lag, u0: float) -> dict:
    """First approximation and simulation, static law and lag: psi'(theta), psi(theta)."""
    from . import press_analysis as pa

    out = {}
    for name, motor in (("static", motor_static), ("lag", motor_lag)):
        drive = pa.ReducedDrive.from_models(press, motor, u0)
        err = pa.dynamic_error(drive, lag=(name == "lag"))
        rev = press_steady_revolution(press, motor, u0)
        t_nom = rev.theta / err.omega0  # the angle reading: forces at the true angle
        out[name] = {"theta": rev.theta, "omega0": err.omega0, "rev": rev,
                     "psi_dot_1": err.psi_dot(t_nom), "psi_1": err.psi(t_nom),
                     "psi_dot_sim": rev.w - err.omega0, "psi_sim": rev.psi,
                     "delta_1": err.delta, "delta_sim": rev.delta}
    return out


def figure_dynamic_error(data: dict):
    from ..cosim.results import axis_label, new_figure, style_axes

    fig = new_figure(figsize=(9, 7))
    ax = fig.subplots(2, 1, sharex=True)
    for a in ax:
        style_axes(a)
    for name, d in data.items():
        deg = np.degrees(d["theta"])
        ax[0].plot(deg, d["psi_dot_sim"], lw=1.4, label=f"simulation, {name} law "
                   f"(delta {100 * d['delta_sim']:.2f} %)")
        ax[0].plot(deg, d["psi_dot_1"], lw=1.0, ls="--", label=f"first approximation, {name} "
                   f"(delta {100 * d['delta_1']:.2f} %)")
        ax[1].plot(deg, d["psi_sim"], lw=1.4, label=f"simulation, {name} law")
        ax[1].plot(deg, d["psi_1"], lw=1.0, ls="--", label=f"first approximation, {name}")
    ax[0].set_ylabel(axis_label("speed error psi' = phi' - omega0", "rad/s"))
    ax[1].set_ylabel(axis_label("angle error psi", "rad"))
    ax[1].set_xlabel(axis_label("crank angle phi", "deg"))
    for a in ax:
        a.legend(fontsize=7, loc="best")
    ax[0].set_title("Seed 000, eq. (19)-(20) and (33)-(35): dynamic errors of the servo press, "
                    "without and with the motor lag", fontsize=9)
    fig.tight_layout()
    return fig


def base_link_data(press, a: float = A_FIGURE, n: int = 73) -> dict:
    """J_2O and J over a revolution at offset a: printed (21), model, finite differences."""
    from ..models.stephenson_press.stephenson_press import StephensonPress

    shifted = StephensonPress({**vars(press.p), "a": a}, sorted(press.enabled))
    phi = np.linspace(0.0, TWO_PI, n)
    J_fd, J2O_fd = press_kinetic_inertia(shifted, phi)
    p = shifted.p
    return {"phi": phi, "a": a, "J_model": shifted.reduced_inertia(phi, 0.0)[0],
            "J_fd": J_fd, "J2O_fd": J2O_fd, "J2O_model": np.full_like(phi, p.m2 * p.r ** 2),
            "J2O_printed": base_link_inertia_printed(phi, p.m2, p.r, a),
            "J2O_printed_a0": base_link_inertia_printed(phi, p.m2, p.r, 0.0),
            "J_printed": shifted.reduced_inertia(phi, 0.0)[0] - p.m2 * p.r ** 2
            + base_link_inertia_printed(phi, p.m2, p.r, a)}


def figure_base_link(d: dict):
    from ..cosim.results import axis_label, new_figure, style_axes

    fig = new_figure(figsize=(9, 7))
    ax = fig.subplots(2, 1, sharex=True)
    for x in ax:
        style_axes(x)
    deg = np.degrees(d["phi"])
    a_mm = 1e3 * d["a"]
    ax[0].plot(deg, d["J2O_printed"], lw=1.2, ls="--", label=f"printed (21), a = {a_mm:.0f} mm")
    ax[0].plot(deg, d["J2O_printed_a0"], lw=1.0, ls=":", label="printed (21), a = 0")
    ax[0].plot(deg, d["J2O_model"], lw=1.4, label=f"model: m2 r^2 (link 2 translates), "
               f"a = {a_mm:.0f} mm")
    ax[0].plot(deg, d["J2O_fd"], "o", ms=3, label="kinetic energy of link 2 from its positions "
               "(finite differences)")
    ax[1].plot(deg, d["J_printed"], lw=1.2, ls="--", label="J with the printed (21)")
    ax[1].plot(deg, d["J_model"], lw=1.4, label="model J(phi) (crank_terms)")
    ax[1].plot(deg, d["J_fd"], "o", ms=3, label="kinetic energy of all bodies from positions")
    ax[0].set_ylabel(axis_label("J_2O", "kg.m2"))
    ax[1].set_ylabel(axis_label("J(phi), drive excluded", "kg.m2"))
    ax[1].set_xlabel(axis_label("crank angle phi", "deg"))
    for x in ax:
        x.legend(fontsize=7, loc="best")
    ax[0].set_title(f"Seed 000, eq. (21)-(22), Fig. 3: base-link inertia with offset "
                    f"a = {a_mm:.0f} mm", fontsize=9)
    fig.tight_layout()
    return fig


def gear_moment_ratio(rev: PressRevolution, drive) -> float:
    """|M_p1|/L_1 [1] of a simulated revolution with the static law: the first harmonic (over
    the crank angle) of the moment through the gear, M_p = i M_D - J_D phi'' with
    i M_D = D - s phi', phi'' = phi' dphi'/dphi (spectral derivative on the equally spaced
    angles), over the first harmonic L_1 of the disturbance. The time-domain counterpart of
    sqrt(23)/(26) (tests/test_press_physics.py computes it independently from its own
    steady state; tests/test_papers_claims.py compares it with both readings of (26))."""
    from . import press_analysis as pa

    n = rev.theta.size
    spec = np.fft.rfft(rev.w)
    dw = np.fft.irfft(1j * np.arange(spec.size) * spec, n)
    Mp = drive.D - drive.s * rev.w - drive.J_D * rev.w * dw
    L1 = pa.disturbance_harmonics(drive, n_harmonics=1).amp[0]
    return float(abs(2.0 * np.fft.rfft(Mp)[1] / n) / L1)


def flywheel_data(press, motor_static, u0: float, factors=(0.0, 0.5, 1.0, 2.0, 3.0)) -> dict:
    """Eq. (26)-(28) (l = 1, theta = 0) in both conventions for J_M0 (flywheel.eq28_conventions)
    and delta: first approximation and simulation at the flywheels factor * J_Mx (J_Mx of (28)
    on the motor shaft, the product's convention), with the simulated gear-moment ratio
    (`gear_moment_ratio`) beside sqrt(26); J_Mx of both conventions against the slider mass."""
    from . import press_analysis as pa
    from .flywheel import eq28_against, eq28_conventions
    from ..models.dc_motor.dc_motor import DcServoMotor

    conv = eq28_conventions(press, motor_static, u0)
    i2 = press.p.gear_ratio ** 2
    J_Mx = conv["mean"]["J_Mx_motor"]
    grid = np.linspace(0.0, 4.0 * J_Mx, 81)
    ratio = {c: np.array([math.sqrt(pa.flywheel_ratio(j * i2, conv["omega0"], conv["J_D"],
                                                      conv[c]["J_M0"], conv["s"]))
                          for j in grid]) for c in ("paper", "mean")}
    J_f = np.array(factors) * J_Mx
    d1, dsim, rsim = [], [], []
    for j in J_f:
        motor = DcServoMotor({**vars(motor_static.p), "J_flywheel": float(j)},
                             sorted(motor_static.enabled))
        drive = pa.ReducedDrive.from_models(press, motor, u0)
        rev = press_steady_revolution(press, motor, u0)
        d1.append(pa.dynamic_error(drive).delta)
        dsim.append(rev.delta)
        rsim.append(gear_moment_ratio(rev, drive))
    return {"grid": grid, "ratio": ratio["mean"], "ratio_paper": ratio["paper"], "J_Mx": J_Mx,
            "J_Mx_paper": conv["paper"]["J_Mx_motor"], "conventions": conv, "J_f": J_f,
            "delta_1": np.array(d1), "delta_sim": np.array(dsim), "ratio_sim": np.array(rsim),
            "against": eq28_against(press, motor_static, u0)}


def figure_flywheel(d: dict):
    from ..cosim.results import PALETTE, axis_label, new_figure, style_axes

    fig = new_figure(figsize=(9, 9.5))
    gs = fig.add_gridspec(3, 1, height_ratios=(1.0, 1.0, 1.0))
    ax = [fig.add_subplot(gs[0])]
    ax += [fig.add_subplot(gs[1], sharex=ax[0]), fig.add_subplot(gs[2])]
    for x in ax:
        style_axes(x)
    c = d["conventions"]
    ax[0].plot(d["grid"], d["ratio"], lw=1.4, color=PALETTE[0],
               label="sqrt of (26), J_M0 = mean of J - J_D (product)")
    ax[0].plot(d["grid"], d["ratio_paper"], lw=1.0, ls="--", color=PALETTE[1],
               label="sqrt of (26), J_M0 = J1 + J_2O (paper)")
    ax[0].plot(d["J_f"], d["ratio_sim"], "o", ms=5, color=PALETTE[2],
               label="simulation: first harmonic of i M_D - J_D phi'' over L_1")
    for key, colour, name in (("J_Mx", PALETTE[0], "product"), ("J_Mx_paper", PALETTE[1],
                                                                "paper")):
        for x in ax[:2]:
            x.axvline(d[key], color=colour, lw=0.8, ls=":")
    ax[0].plot([], [], color="0.3", lw=0.8, ls=":", label=f"(28): J_Mx = {d['J_Mx']:.5f} "
               f"(product), {d['J_Mx_paper']:.5f} kg.m2 (paper): {100 * c['relative']:+.2f} %")
    ax[1].plot(d["J_f"], 100 * d["delta_sim"], "o-", ms=5, label="simulation (static law)")
    ax[1].plot(d["J_f"], 100 * d["delta_1"], "s--", ms=4, label="first approximation (20)")
    ax[0].set_ylabel(axis_label("ratio (26), square root", None))
    ax[1].set_ylabel(axis_label("non-uniformity delta", "%"))
    ax[1].set_xlabel(axis_label("flywheel J_flywheel on the motor shaft", "kg.m2"))
    k = d["against"]
    ax[2].plot(k["values"], 100 * k["relative"], lw=1.4, color=PALETTE[0],
               label="J_Mx(product)/J_Mx(paper) - 1")
    scene_rel = float(np.interp(k["scene"], k["values"], k["relative"]))
    ax[2].plot([k["scene"]], [100 * scene_rel], "o", ms=6, color=PALETTE[3],
               label=f"the scene's {k['parameter']} = {k['scene']:g} kg: {100 * scene_rel:+.2f} %")
    ax[2].set_xlabel(axis_label(f"slider mass {k['parameter']}", "kg"))
    ax[2].set_ylabel(axis_label("difference of J_Mx (28)", "%"))
    ax[2].legend(fontsize=7, loc="lower left")
    ax[0].legend(fontsize=7, loc="upper center")
    ax[1].legend(fontsize=7, loc="best")
    ax[0].set_title("Seed 000, eq. (26)-(28): the flywheel effect (the ratio (26) has its "
                    "minimum at (28); delta falls monotonically)", fontsize=9)
    ax[2].set_title("(28) in both conventions for J_M0 (the product adds m5 <S'^2> to the "
                    "paper's J1 + J_2O), against the slider mass", fontsize=9)
    fig.tight_layout()
    return fig


# the files press_figures writes, each with its drawing from press_models' (press, motor
# without its lag, motor with it, u0) (`crankfmu analyze press` checks the names first)
PRESS_FIGURES = {
    "press_dynamic_error.png": lambda press, m_static, m_lag, u0: figure_dynamic_error(
        dynamic_error_data(press, m_static, m_lag, u0)),
    "press_base_link.png": lambda press, m_static, m_lag, u0: figure_base_link(
        base_link_data(press)),
    "press_flywheel.png": lambda press, m_static, m_lag, u0: figure_flywheel(
        flywheel_data(press, m_static, u0))}


def press_figures(scene, out_dir: Path) -> list[Path]:
    models = press_models(scene)
    progress("analyze press: the figures of the dynamic errors, the base-link offset, the "
             "flywheel")
    figures = {name: draw(*models) for name, draw in progress_over(
        PRESS_FIGURES.items(), "analyze press", "figure")}
    return save_figures(figures, out_dir)


# =============================================================================================
# seed 004: P(t), T(t) with the second approximation
# =============================================================================================
def impact_data(scene, k_n: float | None = None) -> dict:
    """Run the scene (RockerImpact with the linearised stiffnesses it records; the bearing
    constant k_n [N(2/3)/m] replaced if given) and evaluate the first and second
    approximations and the exact linear solution at the stiffnesses used."""
    from ..system.load import load_scene
    from . import rocker_analysis as ra

    sc = load_scene(scene)
    comp = next((c.name for c in sc.components.values() if c.fmu == "RockerImpact"), None)
    if comp is None:
        comp = _component(sc, "impact", "RockerImpact").name  # raises: no such component
    for var in ("P", "T", "c_contact_used", "c_support_used"):
        if f"{comp}.{var}" not in sc.record:
            raise SceneError(sc.path, "record.variables", f"the figure needs {comp}.{var}")
    if k_n is not None:
        sc.components[comp].parameters["k_n"] = float(k_n)
    v = simulated(sc)
    c, c0 = float(v[f"{comp}.c_contact_used"][0]), float(v[f"{comp}.c_support_used"][0])
    params = sc.components[comp].parameters
    data = ra.RockerData(**{k: float(params[k]) for k in ("J", "m", "r", "S", "R_c", "d", "E",
                                                          "rho", "nu", "V0", "k_n")
                            if k in params})
    second = ra.second_approximation(data, c, c0)
    exact = ra.exact_linear(data, c, c0)
    t = v["time"]
    in_contact = t <= exact.tau
    y, z = _on_times(second.flow, t), _on_times(exact.flow, t)
    return {"t": t, "P_sim": v[f"{comp}.P"], "T_sim": v[f"{comp}.T"], "tau": exact.tau,
            "in_contact": in_contact, "P1": y[:, 0], "T1": y[:, 2],
            "P2": y[:, 0] + y[:, 4], "T2": y[:, 2] + y[:, 6],
            "P_exact": z[:, 2], "T_exact": z[:, 0], "c": c, "c0": c0,
            "mu": ra.validity(data, c, c0)["mu"], "effects": sc.components[comp].effects,
            "k_n": data.k_n, "S": data.S, "S_percussion": data.S_percussion,
            "first": second.first}


def figure_impact(d: dict):
    """Top: P(t), T(t) over the contact (simulation, first and second approximation). Bottom:
    the corrections dP, dT of (14)-(18) against what the simulation says the first approximation
    misses (simulation - first approximation): at this scale the approximations part."""
    from ..cosim.results import axis_label, new_figure, style_axes

    fig = new_figure(figsize=(11, 7))
    ax = fig.subplots(2, 2, sharex=True)
    k = d["in_contact"]
    t_ms = 1e3 * d["t"][k]
    for col, key, name, eq in ((0, "P", "contact force P", "(6)"),
                               (1, "T", "bearing load T", "(12)")):
        top, low = ax[0, col], ax[1, col]
        style_axes(top)
        style_axes(low)
        sim, first, second = (d[f"{key}_sim"][k] / 1e3, d[f"{key}1"][k] / 1e3,
                              d[f"{key}2"][k] / 1e3)
        top.plot(t_ms, sim, lw=2.4, alpha=0.5, label="simulation (RockerImpact FMU)")
        top.plot(t_ms, first, lw=1.0, ls=":", label=f"first approximation {eq}")
        top.plot(t_ms, second, lw=1.0, ls="--", label="second approximation (14)-(18)")
        low.plot(t_ms, sim - first, lw=2.4, alpha=0.5, label="simulation - first approximation")
        low.plot(t_ms, second - first, lw=1.0, ls="--", label=f"correction d{key} of (14)-(18)")
        top.set_ylabel(axis_label(name, "kN"))
        low.set_ylabel(axis_label(f"correction to {key}", "kN"))
        low.set_xlabel(axis_label("time from first contact", "ms"))
        top.legend(fontsize=7, loc="best")
        low.legend(fontsize=7, loc="best")
    fig.suptitle("Seed 004, Fig. 2-3: MO-100 impact over the contact, P(t) and T(t) with the "
                 f"second-approximation corrections\n(linearised c = {d['c']:.3g}, "
                 f"c0 = {d['c0']:.3g} N/m; coupling mu = {d['mu']:.2g})", fontsize=9)
    fig.tight_layout()
    return fig


def _on_times(flow, t: np.ndarray) -> np.ndarray:
    """The states of a LinearFlow at the recorded times: on an equally spaced record one matrix
    exponential for the step, then products (flow.grid, round-off ~ n eps); else one per time."""
    steps = np.diff(t)
    if t.size > 2 and np.allclose(steps, steps[0], rtol=1e-9, atol=0.0):
        return flow.grid(float(t[0]), float(t[-1]), t.size - 1)[1]
    return flow(t)


def impact_stiffness_data(scene, k_n_values=(40e6, 80e6, 160e6)) -> list[dict]:
    """`impact_data` for each bearing constant k_n [N(2/3)/m] (the paper's Figs. 2-3 compare
    three), with the opposite lobe of T (rocker_analysis.opposite_lobe) of the first
    approximation over its contact [0, tau1] and of the simulation over the simulated contact."""
    from . import rocker_analysis as ra

    out = []
    progress(f"analyze impact: the figures, {len(k_n_values) + 1} impacts")
    for kn in k_n_values:
        d = impact_data(scene, kn)
        d["lobe_1"] = ra.opposite_lobe(d["first"].T(np.linspace(0.0, d["first"].tau, 2001)))
        d["lobe_sim"] = ra.opposite_lobe(d["T_sim"][d["in_contact"]])
        out.append(d)
    return out


def figure_impact_stiffness(runs: list[dict]):
    """Seed 004, Figs. 2-3 for several k_n: (a) the first approximation P1 (6) and T1 (12) with
    the simulation; (b) the second-approximation corrections dP, dT of (14)-(18) with what the
    simulation says the first approximation misses. Curves numbered as in the paper (1, 2, 3
    in the order of k_n)."""
    from ..cosim.results import PALETTE, axis_label, new_figure, style_axes

    fig = new_figure(figsize=(11, 8))
    ax = fig.subplots(2, 2, sharex=True)
    for x in ax.ravel():
        style_axes(x)
    for n, (d, colour) in enumerate(zip(runs, PALETTE), start=1):
        k = d["in_contact"]
        t_ms = 1e3 * d["t"][k]
        name = f"{n}: k_n = {d['k_n'] / 1e6:g}e6"
        for col, key in ((0, "P"), (1, "T")):
            sim, first = d[f"{key}_sim"][k] / 1e3, d[f"{key}1"][k] / 1e3
            second = d[f"{key}2"][k] / 1e3
            extra = f", opposite lobe {100 * d['lobe_sim']:.0f} %" if key == "T" else ""
            ax[0, col].plot(t_ms, sim, lw=2.6, alpha=0.35, color=colour,
                            label=f"{name}: simulation{extra}")
            ax[0, col].plot(t_ms, first, lw=1.0, ls="--", color=colour,
                            label=f"{name}: first approximation")
            ax[1, col].plot(t_ms, sim - first, lw=2.6, alpha=0.35, color=colour,
                            label=f"{name}: simulation - first approximation")
            ax[1, col].plot(t_ms, second - first, lw=1.0, ls="--", color=colour,
                            label=f"{name}: correction d{key} (14)-(18)")
    S = runs[0]["S"] / runs[0]["S_percussion"]
    titles = (("(Fig. 2a) contact force P: first approximation (6)", "contact force P", "kN"),
              ("(Fig. 3a) support reaction T: first approximation (12)", "support reaction T",
               "kN"),
              ("(Fig. 2b) correction dP of the second approximation", "dP", "kN"),
              ("(Fig. 3b) correction dT of the second approximation", "dT", "kN"))
    for x, (title, name, unit) in zip(ax.ravel(), titles):
        x.set_title(title, fontsize=9)
        x.set_ylabel(axis_label(name, unit))
        x.legend(fontsize=6, loc="best")
    for x in ax[1]:
        x.set_xlabel(axis_label("time from first contact", "ms"))
    fig.suptitle(f"Seed 004, Figs. 2-3: MO-100 impact for {len(runs)} bearing constants k_n "
                 f"[N(2/3)/m] (S = {S:.2f} J/(m r)), approximations against the RockerImpact "
                 f"FMU", fontsize=10)
    fig.tight_layout()
    return fig


def impact_figures(scene, out_dir: Path, k_n_values=(40e6, 80e6, 160e6)) -> list[Path]:
    return save_figures({"impact_forces.png": figure_impact(impact_data(scene)),
                  "impact_stiffness.png": figure_impact_stiffness(
                      impact_stiffness_data(scene, k_n_values))}, out_dir)


# =============================================================================================
def _component(scene, name: str, fmu: str):
    """The scene's component `name`, which must be a `fmu`; else a SceneError (exit 2) saying
    what the figure needs."""
    comp = scene.components.get(name)
    if comp is None or comp.fmu != fmu:
        found = f"a {comp.fmu}" if comp is not None else "none"
        raise SceneError(scene.path, f"components.{name}",
                         f"the analysis needs a component {name!r} of FMU {fmu} (found {found})")
    return comp


def save_figures(figures: dict, out_dir: Path) -> list[Path]:
    """Each figure as the PNG `out_dir`/name (cosim.results.save_figure: a regular file,
    written whole, never replacing anything else)."""
    from ..cosim.results import save_figure

    return [save_figure(fig, Path(out_dir) / name, dpi=100) for name, fig in figures.items()]


# =============================================================================================
# seed 001: planetary clutch drive, linear motor law in closed form
# =============================================================================================
def linear_motor_law(motor) -> tuple[float, float]:
    """(c0, c1) of M = c0 - c1 w_a [N m, N m s/rad] of an InductionMotor with effect linear_law
    (read from the model's own output at w = 0 and w = 1 rad/s)."""
    def M(w):
        return float(motor.output_values(0.0, [], [w, 0.0])[0])
    return M(0.0), M(0.0) - M(1.0)


def planetary_phases(d: dict, c0: float, c1: float, scene: str):
    """The linear phases of an engagement ('engage': ring brake b engages by
    M_p (1 - e^(-alpha_b t)), carrier brake h releases by M_p e^(-beta_h t)) or a stop ('stop':
    the reverse) with the linear motor law M = c0 - c1 w_a, in z = (w_b, w_h, e_b, e_h, 1), e_k
    the brakes' exponentials. Returns (pieces, C, Mt, p, first mode, held member, mover):
    pieces(mode) -> (A, F_b, F_h), dz/dt = A z in that lock/slide pattern (mode[k] = 0 locked,
    +-1 sliding), the friction torques as linear functionals of z; C[k] @ z is member k's
    capacity, Mt[k] @ z its brake torque. Units SI; d holds the drive's parameters."""
    p = d["r_b"] / d["r_a"]
    Ja, Jb, Jh = d["J_a"], d["J_b"], d["J_h"]
    m11, m12, m22 = Ja * p * p + Jb, -Ja * p * (1 + p), Ja * (1 + p) ** 2 + Jh
    if scene == "engage":
        lam = (d["alpha_b"], d["beta_h"])
        Mt = {"b": np.array([0, 0, -d["Mp_b"], 0, d["Mp_b"]]),
              "h": np.array([0, 0, 0, d["Mp_h"], 0])}
        mode1, held, mover = {"b": -1, "h": 0}, "h", "b"
    else:
        lam = (d["beta_b"], d["alpha_h"])
        Mt = {"b": np.array([0, 0, d["Mp_b"], 0, 0]),
              "h": np.array([0, 0, 0, -d["Mp_h"], d["Mp_h"]])}
        mode1, held, mover = {"b": 0, "h": 1}, "b", "h"
    unit = np.array([0, 0, 0, 0, 1.0])
    C = {"b": Mt["b"] + d["M_cb"] * unit, "h": Mt["h"] + d["M_ch"] * unit}
    M_A = np.array([c1 * p, -c1 * (1 + p), 0, 0, c0 - d["M_ca"]])  # motor - M_ca, linear in z
    Q_b, Q_h = -p * M_A, (1 + p) * M_A

    def pieces(mode):
        A = np.zeros((5, 5))
        A[2, 2], A[3, 3] = -lam[0], -lam[1]
        if mode["b"] and mode["h"]:
            F_b, F_h = -mode["b"] * C["b"], -mode["h"] * C["h"]
            acc = np.linalg.solve(np.array([[m11, m12], [m12, m22]]),
                                  np.vstack([Q_b + F_b, Q_h + F_h]))
            A[0], A[1] = acc[0], acc[1]
        elif mode["h"]:
            F_h = -mode["h"] * C["h"]
            A[1] = (Q_h + F_h) / m22
            F_b = m12 * A[1] - Q_b
        else:
            F_b = -mode["b"] * C["b"]
            A[0] = (Q_b + F_b) / m11
            F_h = m12 * A[0] - Q_h
        return A, F_b, F_h

    return pieces, C, Mt, p, mode1, held, mover


def planetary_closed_form(d: dict, c0: float, c1: float, scene: str, w_a0: float, w_h0: float,
                          t_end: float, n: int = 400, lock_only: bool = False) -> dict:
    """Engagement or stop (planetary_phases) from the speeds w_a0, w_h0 (the held member at
    rest): each phase is linear time-invariant, z(t) = expm(A t) z(t_i); break-free and lock are
    roots of linear functionals of z (brentq on the exact expm). The speeds on a grid and the
    brake energies (trapezoidal rule on the grid, n intervals per phase: relative error ~1e-6)."""
    from scipy.optimize import brentq

    from ..runtime.matrix_exponential import expm
    pieces, C, Mt, p, mode1, held, mover = planetary_phases(d, c0, c1, scene)

    def grid(A, z, span):
        step = expm(A * (span / n))
        out = [z]
        for _ in range(n):
            out.append(step @ out[-1])
        return np.linspace(0.0, span, n + 1), np.array(out)

    def first_root(f, A, z, span):
        ts, zs = grid(A, z, span)
        vals = [f(zz) for zz in zs]
        for a, b, fa, fb in zip(ts[:-1], ts[1:], vals[:-1], vals[1:]):
            if fa * fb < 0.0:
                return brentq(lambda s: f(expm(A * s) @ z), a, b, xtol=1e-15, rtol=1e-15,
                              maxiter=200)
        raise ValueError(f"planetary closed form ({scene}): no event within {t_end} s")

    z0 = np.array([(-w_a0 + (1 + p) * w_h0) / p, w_h0, 1.0, 1.0, 1.0])
    A1, F_b1, F_h1 = pieces(mode1)
    F1 = F_h1 if held == "h" else F_b1
    t1 = first_root(lambda z: float(C[held] @ z - abs(F1 @ z)), A1, z0, t_end)
    z1 = expm(A1 * t1) @ z0
    mode2 = dict(mode1, **{held: -1 if float(F1 @ z1) > 0 else 1})
    A2, _, _ = pieces(mode2)
    i_mover = 0 if mover == "b" else 1
    t2 = t1 + first_root(lambda z: float(z[i_mover]), A2, z1, t_end - t1)
    if lock_only:
        return {"t_slip": t1, "t_lock": t2}
    z2 = expm(A2 * (t2 - t1)) @ z1
    z2[i_mover] = 0.0
    A3, _, _ = pieces(dict(mode2, **{mover: 0}))
    t_pieces, z_pieces = [], []
    for A, za, ta, tb in ((A1, z0, 0.0, t1), (A2, z1, t1, t2), (A3, z2, t2, t_end)):
        ts, zs = grid(A, za, tb - ta)
        t_pieces.append(ts + ta)
        z_pieces.append(zs)
    t, z = np.concatenate(t_pieces), np.concatenate(z_pieces)
    w_b, w_h = z[:, 0], z[:, 1]
    out = {"t_slip": t1, "t_lock": t2, "t": t, "w_b": w_b, "w_h": w_h,
           "w_a": -p * w_b + (1 + p) * w_h}
    for k, w in (("b", w_b), ("h", w_h)):   # brake power M_t |w| (zero while locked)
        power = (z @ Mt[k]) * np.abs(w)
        out[f"E_brake_{k}"] = np.concatenate(
            [[0.0], np.cumsum(0.5 * (power[1:] + power[:-1]) * np.diff(t))])
    return out


PLANETARY_ALPHAS = (15.0, 60.0)            # 1/s: simulated engagement rates besides the scene's
SWEEP_STEP = 5e-4   # s: communication step of those runs (the FMU locates the lock itself; the
                    # motor torque held over a step costs O(h): ~5e-5 of the lock time)
PLANETARY_TARGETS = (0.2, 0.3)             # s: simulated engagement times (markers)
T_COMMAND_ON, T_COMMAND_OFF, T_STOP = 0.05, 0.55, 1.0   # s: the four-period run


def planetary_setup(scene_path):
    """(scene with the motor's linear law and the idle start speed of that law, drive parameters,
    c0, c1, idle w_a). The linear law makes the simulation and the closed form the same
    equations, so they can be compared to the co-simulation's accuracy."""
    from ..models.induction_motor.induction_motor import InductionMotor
    from ..models.planetary_drive.planetary_drive import PlanetaryClutchDrive, steady_state
    from ..system.load import load_scene

    scene = load_scene(scene_path)
    motor_c = _component(scene, "motor", "InductionMotor")
    _component(scene, "drive", "PlanetaryClutchDrive")
    for var in ("w_a", "w_b", "w_h", "E_brake_b", "E_brake_h", "period", "t_lock_b", "t_lock_h"):
        if f"drive.{var}" not in scene.record:
            raise SceneError(scene.path, "record.variables", f"the figure needs drive.{var}")
    if "linear_law" not in motor_c.effects:
        motor_c.effects.append("linear_law")
    motor = InductionMotor(motor_c.parameters, motor_c.effects)
    d = dict(scene.components["drive"].parameters)
    w_idle = steady_state(PlanetaryClutchDrive(d), motor, 1)["w_a"]
    scene.components["drive"].parameters["w_a_start"] = w_idle
    d["w_a_start"] = w_idle
    return scene, d, *linear_motor_law(motor), w_idle


def planetary_engagement_time(d: dict, c0: float, c1: float, w_idle: float,
                              t_end: float = 2.0) -> float:
    """Closed-form engagement time (the ring locks) [s] from idle; inf if it does not lock."""
    try:
        return planetary_closed_form(d, c0, c1, "engage", w_idle, 0.0, t_end, n=100,
                                     lock_only=True)["t_lock"]
    except ValueError:
        return math.inf


def brake_torque_for_engagement_time(d: dict, c0: float, c1: float, w_idle: float,
                                     target: float) -> float:
    """The ring brake's design torque Mp_b [N m] whose closed-form engagement time is `target`
    [s] (the paper: "with the engagement time limited, the brake torques needed follow"):
    brentq on Mp_b, the engagement time falling as Mp_b grows."""
    from scipy.optimize import brentq

    def f(Mp):
        return min(planetary_engagement_time({**d, "Mp_b": Mp}, c0, c1, w_idle), 10.0) - target
    return brentq(f, 50.0, 1e5, xtol=1e-4, rtol=1e-9)


def planetary_data(scene_path) -> dict:
    """The four-period run and the closed forms beside it; engagement time against alpha_b and
    the brake torque for a given engagement time, closed form and simulated."""
    from ..system.load import prepare_scene
    from ..system.scene import InputSignal

    scene, d, c0, c1, w_idle = planetary_setup(scene_path)
    progress("analyze planetary: the four periods, engagement times, brake torques (~10 s)")
    four = prepare_scene(scene, stop_time=T_STOP)
    four.inputs["drive.command"] = InputSignal("drive.command", [0.0, T_COMMAND_ON,
                                               T_COMMAND_OFF], [0.0, 1.0, 0.0], "step")
    v = simulated(four)
    t = v["time"]
    k_off = int(np.argmin(np.abs(t - T_COMMAND_OFF)))
    engage = planetary_closed_form(d, c0, c1, "engage", w_idle, 0.0, T_COMMAND_OFF - T_COMMAND_ON)
    stop = planetary_closed_form(d, c0, c1, "stop", float(v["drive.w_a"][k_off]),
                                 float(v["drive.w_h"][k_off]), T_STOP - T_COMMAND_OFF)
    alphas = np.linspace(10.0, 80.0, 36)
    sims = {d["alpha_b"]: float(v["drive.t_lock_b"][-1]) - T_COMMAND_ON}  # the four-period run
    for a in PLANETARY_ALPHAS:
        t_cf = planetary_engagement_time({**d, "alpha_b": a}, c0, c1, w_idle)
        r = simulated(scene, stop_time=t_cf + 0.01, step=SWEEP_STEP,
                         parameters={"drive.alpha_b": a})
        sims[a] = float(r["drive.t_lock_b"][-1])
    targets = np.linspace(0.15, 0.45, 13)
    Mp_check = [brake_torque_for_engagement_time(d, c0, c1, w_idle, x) for x in PLANETARY_TARGETS]
    t_check = []
    for Mp, x in zip(Mp_check, PLANETARY_TARGETS):
        r = simulated(scene, stop_time=x + 0.01, step=SWEEP_STEP,
                         parameters={"drive.Mp_b": Mp})
        t_check.append(float(r["drive.t_lock_b"][-1]))
    return {"sim": {k: v[k] for k in ("time", "drive.w_a", "drive.w_b", "drive.w_h",
                                      "drive.E_brake_b", "drive.E_brake_h", "drive.period",
                                      "drive.t_lock_b", "drive.t_lock_h")},
            "engage": engage, "stop": stop, "alpha_grid": alphas,
            "t_lock_grid": np.array([planetary_engagement_time({**d, "alpha_b": a}, c0, c1,
                                                               w_idle) for a in alphas]),
            "alpha_sim": np.array(sorted(sims)), "t_lock_sim": np.array([sims[a] for a in
                                                                          sorted(sims)]),
            "t_lock_cf_sim": np.array([planetary_engagement_time({**d, "alpha_b": a}, c0, c1,
                                                                 w_idle) for a in sorted(sims)]),
            "targets": targets, "Mp_needed": np.array(
                [brake_torque_for_engagement_time(d, c0, c1, w_idle, x) for x in targets]),
            "Mp_check": np.array(Mp_check), "t_check": np.array(t_check),
            "alpha_b": d["alpha_b"], "Mp_b": d["Mp_b"]}


def figure_planetary(d: dict):
    from ..cosim.results import axis_label, new_figure, style_axes

    fig = new_figure(figsize=(11, 8))
    gs = fig.add_gridspec(2, 2)
    ax_w, ax_e = fig.add_subplot(gs[0, 0]), fig.add_subplot(gs[1, 0])
    ax_a, ax_m = fig.add_subplot(gs[0, 1]), fig.add_subplot(gs[1, 1])
    for x in (ax_w, ax_e, ax_a, ax_m):
        style_axes(x)
    s = d["sim"]
    for key, name in (("w_a", "sun a (motor)"), ("w_b", "ring b"), ("w_h", "carrier h")):
        ax_w.plot(s["time"], s[f"drive.{key}"], lw=2.2, alpha=0.5, label=f"{name}, simulation")
    for part, t0 in (("engage", T_COMMAND_ON), ("stop", T_COMMAND_OFF)):
        c = d[part]
        for key in ("w_a", "w_b", "w_h"):
            ax_w.plot(c["t"] + t0, c[key], "k--", lw=0.8,
                      label="closed form (linear motor law)" if (part, key) == ("engage", "w_a")
                      else "_")
    E_end = d["engage"]["E_brake_b"][-1], d["engage"]["E_brake_h"][-1]
    for j, (k, name) in enumerate((("b", "ring brake b"), ("h", "carrier brake h"))):
        ax_e.plot(s["time"], s[f"drive.E_brake_{k}"] / 1e3, lw=2.2, alpha=0.5,
                  label=f"{name}, simulation")
        ax_e.plot(d["engage"]["t"] + T_COMMAND_ON, d["engage"][f"E_brake_{k}"] / 1e3, "k--",
                  lw=0.8, label="closed form" if j == 0 else "_")
        ax_e.plot(d["stop"]["t"] + T_COMMAND_OFF, (d["stop"][f"E_brake_{k}"] + E_end[j]) / 1e3,
                  "k--", lw=0.8, label="_")
    for x in (ax_w, ax_e):
        for edge, text in ((T_COMMAND_ON, "engage"), (T_COMMAND_OFF, "stop")):
            x.axvline(edge, color="grey", lw=0.6, ls=":")
        x.set_xlabel(axis_label("time", "s"))
    ax_w.set_ylabel(axis_label("angular velocity", "rad/s"))
    ax_e.set_ylabel(axis_label("brake energy (cumulative)", "kJ"))
    ax_w.set_title("Periods 1-4: idle, engagement, stroke, stopping, idle", fontsize=9)
    ax_a.plot(d["alpha_grid"], d["t_lock_grid"], lw=1.4, label="closed form")
    ax_a.plot(d["alpha_sim"], d["t_lock_sim"], "o", ms=6, label="simulation (ring locks)")
    ax_a.set_xlabel(axis_label("ring brake engagement rate alpha_b", "1/s"))
    ax_a.set_ylabel(axis_label("engagement time", "s"))
    ax_a.set_title(f"Engagement time against alpha_b (Mp_b = {d['Mp_b']:.0f} N.m)", fontsize=9)
    ax_m.plot(d["targets"], d["Mp_needed"], lw=1.4, label="closed form, inverted")
    ax_m.plot(d["t_check"], d["Mp_check"], "o", ms=6, label="simulation at that Mp_b")
    ax_m.set_xlabel(axis_label("required engagement time", "s"))
    ax_m.set_ylabel(axis_label("ring brake torque Mp_b needed", "N.m"))
    ax_m.set_title(f"Brake torque for a given engagement time (alpha_b = {d['alpha_b']:.0f} 1/s)",
                   fontsize=9)
    for x in (ax_w, ax_e, ax_a, ax_m):
        x.legend(fontsize=7, loc="best")
    fig.suptitle("Seed 001: planetary clutch drive, the four periods (eq. 7-10), brake laws "
                 "(4)-(5); induction motor, linear law (3)", fontsize=10)
    fig.tight_layout()
    return fig


def format_planetary(d: dict) -> str:
    """The figure's checks as text: lock times of the four-period run, closed form against
    simulation; engagement time against alpha_b; the brake torque for a given time."""
    s = d["sim"]
    lock_b = float(s["drive.t_lock_b"][-1]) - T_COMMAND_ON
    lock_h = float(s["drive.t_lock_h"][-1]) - T_COMMAND_OFF
    lines = ["Seed 001: linear motor law, closed form (piecewise expm) against the FMU runs",
             f"{'':>28}{'closed form [s]':>16}{'simulation [s]':>16}",
             f"{'engagement (ring locks)':>28}{d['engage']['t_lock']:>16.7f}{lock_b:>16.7f}",
             f"{'stop (carrier locks)':>28}{d['stop']['t_lock']:>16.7f}{lock_h:>16.7f}",
             f"{'alpha_b [1/s]':>28}{'engagement [s]':>16}{'simulation [s]':>16}"]
    for a, cf, sim in zip(d["alpha_sim"], d["t_lock_cf_sim"], d["t_lock_sim"]):
        lines.append(f"{a:>28g}{cf:>16.7f}{sim:>16.7f}")
    lines.append(f"{'wanted engagement [s]':>28}{'Mp_b [N.m]':>16}{'simulation [s]':>16}")
    for x, Mp, sim in zip(PLANETARY_TARGETS, d["Mp_check"], d["t_check"]):
        lines.append(f"{x:>28g}{Mp:>16.2f}{sim:>16.7f}")
    return "\n".join(lines)


def write_planetary_csv(d: dict, path: Path) -> Path:
    """Engagement time against alpha_b (closed form) and the brake torque for a given time."""
    return write_table(path, ["alpha_b [1/s]", "engagement time [s]"],
                       [*zip(d["alpha_grid"], d["t_lock_grid"]), [],
                        ["engagement time [s]", "Mp_b needed [N.m]"],
                        *zip(d["targets"], d["Mp_needed"])])
