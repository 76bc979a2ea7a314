"""Test fixture: DC servo motor + Stephenson press as ONE ODE, solved by scipy solve_ivp.

Not a test file. It composes the physics objects of `crankfmu.models` (the same equations the
FMUs use) with the rigid connection of the port convention:

    motor inputs   flange_w = i w,  flange_phi = i phi,  u,  w_ref
    press inputs   flange_tau = motor output flange_tau,  flange_J = motor output flange_J

State vector  x = [phi, w, <motor states>, W_motor, W_forge, W_grav]
    <motor states>  motor.state_names() (M with electrical_lag, I_speed with speed_loop)
    W_motor  work delivered by the motor shaft,  dW/dt = M_D * i w            [J]
    W_forge  work done on the workpiece,         dW/dt = F5 * S'(phi) * w     [J]
    W_grav   work done by gravity,               dW/dt = (M_C + F5 S') * w    [J]
so that  W_motor - W_forge + W_grav = Delta(1/2 J(phi) w^2)  (the kinetic energy includes the
rotor, whose inertia is in J through flange_J).

The integration is cut into segments at the crank angles where the right-hand side has a kink
(start and end of the forging window) and at every full revolution (phi = 2 pi k), by terminal
events on phi (phi increases monotonically once started). Each segment keeps its dense output,
so the trajectory can be evaluated anywhere, in particular on an equally spaced crank-angle grid.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.integrate import solve_ivp

from crankfmu.models.dc_motor.dc_motor import DcServoMotor
from crankfmu.models.stephenson_press.stephenson_press import StephensonPress

TWO_PI = 2.0 * math.pi

# The servo press of the brief (motor and press parameters; u = 220 V).
SERVO_MOTOR = dict(k_phi=1.30, R_a=0.5, L_a=5e-3, J_rotor=0.05)
SERVO_PRESS = dict(r=0.05, l=0.25, m5=50.0, m2=20.0, J1=2.0, gear_ratio=10.0, F_max=50e3,
                   forging_angle=math.radians(30.0))
SERVO_U = 220.0
PRESS_EFFECTS = ("gravity", "forging_load")


class MonolithicServoPress:
    """The composed ODE. Parameters as dicts (unknown names raise KeyError in the models),
    effects as lists of names; `u` [V] and `w_ref` [rad/s] are the motor's held inputs."""

    def __init__(self, motor_params: dict | None = None, motor_effects=(),
                 press_params: dict | None = None, press_effects=PRESS_EFFECTS,
                 u: float = SERVO_U, w_ref: float = 150.0, method: str | None = None,
                 rtol: float = 1e-10, atol: float | None = None):
        self.motor = DcServoMotor(dict(SERVO_MOTOR, **(motor_params or {})), list(motor_effects))
        self.press = StephensonPress(dict(SERVO_PRESS, **(press_params or {})),
                                     list(press_effects))
        self.i = self.press.p.gear_ratio
        self.u, self.w_ref = float(u), float(w_ref)
        self.n_motor = len(self.motor.state_names())
        self.n = 2 + self.n_motor + 3
        self.k_work = 2 + self.n_motor  # index of W_motor
        stiff = self.motor.on("electrical_lag") and self.motor.tau < 1e-3
        self.method = method or ("Radau" if stiff else "DOP853")
        self.rtol = rtol
        # atol: the work quadratures reach kJ, speeds ~ 20 rad/s, torques ~ 100 N m
        self.atol = atol if atol is not None else 1e-12
        self.n_rhs = 0

    # -- the composed right-hand side ------------------------------------------------------
    def motor_inputs(self, phi: float, w: float) -> list:
        return [self.i * w, self.i * phi, self.u, self.w_ref]  # (a list: ~1 us cheaper)

    def coupling(self, t: float, x: np.ndarray):
        """(motor inputs, motor outputs, press inputs) at state x."""
        phi, w = x[0], x[1]
        xm = x[2:2 + self.n_motor]
        um = self.motor_inputs(phi, w)
        ym = self.motor.output_values(t, xm, um)
        up = (ym[0], ym[1])  # flange_tau, flange_J
        return um, ym, up

    def rhs(self, t: float, x: np.ndarray) -> np.ndarray:
        self.n_rhs += 1
        phi, w = x[0], x[1]
        xm = x[2:2 + self.n_motor]
        um, ym, up = self.coupling(t, x)
        dx = np.empty(self.n)
        dx[0:2] = self.press.derivatives(t, x[0:2], up)
        if self.n_motor:
            dx[2:2 + self.n_motor] = self.motor.derivatives(t, xm, um)
        # M_C, F5 and S' from one call of the press's core (not one per quantity: this
        # right-hand side is most of the CPU of the tests that use it)
        M_C, F5, _, dS = self.press.crank_terms(float(phi), 0.0)[2:6]
        k = self.k_work
        dx[k] = ym[0] * self.i * w          # motor shaft power M_D * (i w)
        dx[k + 1] = F5 * dS * w             # power into the workpiece
        dx[k + 2] = (M_C + F5 * dS) * w     # power of the weights
        return dx

    def initial_state(self, phi0: float = 0.0, w0: float = 0.0) -> np.ndarray:
        x = np.zeros(self.n)
        x[0], x[1] = phi0, w0
        if self.n_motor:
            x[2:2 + self.n_motor] = self.motor.initial_state(self.motor_inputs(phi0, w0))
        return x

    # -- diagnostics on a state -----------------------------------------------------------
    def kinetic_energy(self, x: np.ndarray) -> np.ndarray:
        """1/2 J(phi) w^2 [J] for x of shape (n,) or (n, m)."""
        J_input = self.motor.p.J_rotor + self.motor.p.J_flywheel
        J = self.press.reduced_inertia(x[0], J_input)[0]
        return 0.5 * J * x[1] ** 2

    def drive_torque(self, t, x) -> float:
        """Motor air-gap torque M_D [N m] at state x (1-D)."""
        return float(self.coupling(t, x)[1][0])

    # -- integration ------------------------------------------------------------------------
    def breakpoints(self) -> np.ndarray:
        """Crank angles in [0, 2pi) where the right-hand side has a kink, plus 0."""
        pts = [0.0]
        if self.press.on("forging_load"):
            a = self.press.p.forging_angle
            pts += [(0.5 * math.pi - a) % TWO_PI, (0.5 * math.pi) % TWO_PI]
        return np.unique(np.array(pts))

    def next_breakpoint(self, phi: float) -> float:
        """Smallest breakpoint angle strictly above phi (+ a margin against re-triggering)."""
        base = math.floor(phi / TWO_PI) * TWO_PI
        for k in range(3):
            for b in self.breakpoints():
                cand = base + k * TWO_PI + b
                if cand > phi + 1e-9:
                    return cand
        raise AssertionError("unreachable")

    def simulate(self, x0: np.ndarray, t0: float, n_revolutions: int,
                 t_max_segment: float = 60.0) -> "Trajectory":
        """Integrate from (t0, x0) until phi has grown by n_revolutions full turns, ending exactly
        at phi = 2 pi k (the run starts by going to the next breakpoint)."""
        phi_end = math.floor(x0[0] / TWO_PI + 1e-12) * TWO_PI + n_revolutions * TWO_PI
        segments, t, x = [], float(t0), np.array(x0, dtype=float)
        while True:
            target = min(self.next_breakpoint(x[0]), phi_end)

            def hit(s, y, target=target):
                return y[0] - target
            hit.terminal, hit.direction = True, 1.0
            sol = solve_ivp(self.rhs, (t, t + t_max_segment), x, method=self.method,
                            rtol=self.rtol, atol=self.atol, events=hit, dense_output=True)
            if sol.status != 1:
                raise RuntimeError(f"no crank progress to phi = {target:.6f} rad: {sol.message}")
            t_new = float(sol.t_events[0][0])
            x = np.array(sol.y_events[0][0])
            x[0] = target  # on the event surface (the event locator leaves ~1e-16 rad)
            segments.append(Segment(t, t_new, sol.sol))
            t = t_new
            if target >= phi_end - 1e-12:
                return Trajectory(self, segments, x)

    def periodic_steady_state(self, n_last: int = 2, max_revolutions: int = 40,
                              tol: float = 1e-9, x0: np.ndarray | None = None) -> "SteadyState":
        """Run from rest (phi = 0, w = 0, motor in electrical equilibrium; or from x0 at t = 0)
        revolution by revolution until the state at phi = 2 pi k repeats (relative change of w
        and of the motor states below tol: the integration error at rtol 1e-10 leaves a floor of
        about 1e-10), then integrate n_last more revolutions and return them."""
        x = self.initial_state() if x0 is None else np.array(x0, dtype=float)
        t, prev = 0.0, None
        for k in range(max_revolutions):
            traj = self.simulate(x, t, 1)
            t, x = traj.segments[-1].t1, traj.x_end
            now = x[1:2 + self.n_motor].copy()
            if prev is not None and np.all(np.abs(now - prev) <= tol * np.maximum(
                    np.abs(now), 1.0)):
                break
            prev = now
        else:
            raise RuntimeError(f"no periodic steady state after {max_revolutions} revolutions")
        x_start = x.copy()
        traj = self.simulate(x, t, n_last)
        return SteadyState(self, traj, t, x_start, n_last, k + 1)


@dataclass
class Segment:
    t0: float
    t1: float
    sol: object  # scipy OdeSolution


class Trajectory:
    """Piecewise dense output of a run."""

    def __init__(self, model: MonolithicServoPress, segments: list[Segment], x_end: np.ndarray):
        self.model, self.segments, self.x_end = model, segments, x_end
        self.t_start, self.t_end = segments[0].t0, segments[-1].t1
        self._t1 = np.array([s.t1 for s in segments])

    def __call__(self, t) -> np.ndarray:
        """States at times t (array): shape (n_states, len(t))."""
        t = np.atleast_1d(np.asarray(t, dtype=float))
        out = np.empty((self.model.n, t.size))
        idx = np.minimum(np.searchsorted(self._t1, t), len(self.segments) - 1)
        for j in np.unique(idx):
            sel = idx == j
            out[:, sel] = self.segments[j].sol(t[sel])
        return out

    def t_at_phi(self, phi: np.ndarray, iterations: int = 8) -> np.ndarray:
        """Times at which the crank passes the angles phi (Newton on the dense output,
        phi' = w > 0)."""
        phi = np.asarray(phi, dtype=float)
        tt = np.linspace(self.t_start, self.t_end, 2001)
        ph = self(tt)[0]
        t = np.interp(phi, ph, tt)
        for _ in range(iterations):
            x = self(t)
            t = np.clip(t - (x[0] - phi) / x[1], self.t_start, self.t_end)
        return t


@dataclass
class SteadyState:
    """The last n revolutions of a run in periodic steady state.

    model, traj   the composed model and the trajectory of the last revolutions
    t0, x0        time and state at the start of the first of them (phi = 2 pi k0)
    n             number of revolutions in traj
    revolutions_to_converge   revolutions from rest until the state repeated
    """

    model: MonolithicServoPress
    traj: Trajectory
    t0: float
    x0: np.ndarray
    n: int
    revolutions_to_converge: int

    @property
    def phi0(self) -> float:
        return float(self.x0[0])

    @property
    def period(self) -> float:
        """Duration of the last revolution [s]."""
        t = self.traj.t_at_phi(np.array([self.traj.x_end[0] - TWO_PI, self.traj.x_end[0]]))
        return float(t[1] - t[0])

    def on_angle_grid(self, m: int = 4096, revolution: int = 0):
        """(phi - phi_start, t, states) at m equally spaced crank angles of one revolution."""
        phi_rel = TWO_PI * np.arange(m) / m
        phi = self.phi0 + revolution * TWO_PI + phi_rel
        t = self.traj.t_at_phi(phi)
        return phi_rel, t, self.traj(t)

    def on_time_grid(self, m: int = 20000, revolution: int = 0):
        """(t, states) at m equally spaced instants of one revolution."""
        ends = self.traj.t_at_phi(self.phi0 + TWO_PI * np.array([revolution, revolution + 1]))
        t = ends[0] + (ends[1] - ends[0]) * np.arange(m) / m
        return t, self.traj(t)

    def angle_mean_speed(self, m: int = 4096) -> float:
        """(1/2pi) int w dphi over one revolution [rad/s]."""
        return float(np.mean(self.on_angle_grid(m)[2][1]))

    def time_mean_speed(self) -> float:
        """2 pi / T [rad/s]."""
        return TWO_PI / self.period

    def nonuniformity(self, m: int = 20000) -> float:
        """(w_max - w_min)/w_mean over one revolution, w_mean = 2 pi/T [1]."""
        w = self.on_time_grid(m)[1][1]
        return float((w.max() - w.min()) / self.time_mean_speed())

    def speed_harmonic_in_time(self, l: int = 1, m: int = 4096) -> complex:
        """Complex amplitude of harmonic l of w(t) over one revolution, t measured from the
        instant the crank passes phi = 2 pi k: w(t) = <w> + sum Re[Wc_l exp(i l 2pi t/T)]."""
        w = self.on_time_grid(m)[1][1]
        return complex(2.0 * np.fft.rfft(w)[l] / m)

    def speed_harmonic(self, l: int = 1, m: int = 4096) -> complex:
        """Complex amplitude Wc_l of harmonic l of w as a function of the crank angle,
        w(phi) = <w> + sum Re[Wc_l exp(i l phi)]  [rad/s]."""
        w = self.on_angle_grid(m)[2][1]
        return complex(2.0 * np.fft.rfft(w)[l] / m)
