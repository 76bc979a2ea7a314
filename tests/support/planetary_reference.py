"""Independent references for the planetary clutch drive + induction motor (tests only).

1. `reference_run`: a MONOLITHIC motor + drive ODE written independently of
   crankfmu.models.planetary_drive.planetary_drive: Newton-Euler equations of sun, ring and carrier with the
   tooth force R of the (massless) planets as an unknown, instead of the model's Lagrange form:

       J_a a_a = M_m(w_a) - M_ca - R r_a
       J_b a_b = T_b - R r_b
       J_h a_h = T_h + R (r_a + r_b)
       r_a a_a + r_b a_b - (r_a + r_b) a_h = 0           (Willis, differentiated)

   T_k is the friction torque on member k: -C_k sgn(w_k) while sliding, an unknown with the extra
   equation a_k = 0 while locked. One 6x6 linear solve per right-hand side. States (w_a, w_h)
   plus energy quadratures; w_b from Willis. Events (solve_ivp, DOP853, rtol 1e-12): sliding
   member reaches zero (then lock if |T_k| <= C_k), locked member's |T_k| reaches C_k.
   Brake laws for a command at t = 0 from the steady state (fully engaged / fully released).

2. `closed_form_*`: with the LINEAR motor law M = c0 - c1 w_a and exponential brakes, each
   phase (fixed lock/slide pattern) is linear time-invariant in the augmented state
   z = (w_b, w_h, e_b, e_h, 1), e_k = exp(-lambda_k t): z(t) = expm(A (t - t_i)) z(t_i).
   Break-free and lock instants are roots of linear functionals of expm(A t) z_i (brentq).

3. `run_model`: the model's own `advance` over communication steps h, with the motor torque fed
   through u_of_t: 'zoh' holds M(w_a(t_n)) over the step; 'iterated' feeds the linear
   interpolation between M(w_a(t_n)) and M(w_a(t_n+1)) and repeats the step (rolling back the
   states and the model's discrete state) until M(w_a(t_n+1)) is a fixed point.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.integrate import solve_ivp
from scipy.linalg import expm
from scipy.optimize import brentq

# The scene of the brief (defaults of PlanetaryClutchDrive) and the motor of the scenes (its
# rotor and flywheel are counted in J_a, so the motor's own J is 0).
DRIVE = dict(r_a=0.10, r_b=0.25, J_a=4.0, J_b=0.5, J_h=5.0, M_ca=5.0, M_cb=3.0, M_ch=40.0,
             Mp_b=1000.0, alpha_b=30.0, beta_b=40.0, Mp_h=1500.0, alpha_h=30.0, beta_h=40.0)
MOTOR = dict(P_rated=5500.0, n_rated=960.0, n_sync=1000.0, lambda_k=2.2, J_rotor=0.0,
             J_flywheel=0.0)


# -- the motor, from its nameplate (written out again, not imported) --------------------------
def motor_law(linear: bool, m=MOTOR):
    w_s = m["n_sync"] * math.pi / 30.0
    w_n = m["n_rated"] * math.pi / 30.0
    s_n = 1.0 - w_n / w_s
    M_k = m["lambda_k"] * m["P_rated"] / w_n
    s_k = s_n * (m["lambda_k"] + math.sqrt(m["lambda_k"] ** 2 - 1.0))
    if linear:
        return lambda w: 2.0 * M_k * (1.0 - w / w_s) / s_k
    return lambda w: 2.0 * M_k * (1.0 - w / w_s) * s_k / ((1.0 - w / w_s) ** 2 + s_k ** 2)


def steady_speed(torque, M_needed: float, w_lo=50.0, w_hi=None, m=MOTOR) -> float:
    w_hi = w_hi if w_hi is not None else m["n_sync"] * math.pi / 30.0
    return brentq(lambda w: torque(w) - M_needed, w_lo, w_hi, xtol=1e-14, rtol=1e-15)


# -- brake laws after a command at t = 0 -------------------------------------------------------
def brake_laws(scene: str, d=DRIVE, power=None):
    """(M_tb(t), M_th(t)) for 'engage' (b engages, h releases) or 'stop' (the reverse).
    power = dict(tc_b, tr_b, z_b, tc_h, tr_h, z_h): the power law B t^z, B = M_p/t_c^z, for
    engagement and M_p (1 - t/t_r)^z for release (both constant after t_c, t_r)."""
    if power is not None:
        def engage(Mp, tc, z):
            return lambda t: Mp * (min(t, tc) / tc) ** z

        def release(Mp, tr, z):
            return lambda t: Mp * (1.0 - min(t, tr) / tr) ** z

        if scene == "engage":
            return (engage(d["Mp_b"], power["tc_b"], power["z_b"]),
                    release(d["Mp_h"], power["tr_h"], power["z_h"]))
        return (release(d["Mp_b"], power["tr_b"], power["z_b"]),
                engage(d["Mp_h"], power["tc_h"], power["z_h"]))
    if scene == "engage":
        return (lambda t: d["Mp_b"] * (1.0 - math.exp(-d["alpha_b"] * t)),
                lambda t: d["Mp_h"] * math.exp(-d["beta_h"] * t))
    return (lambda t: d["Mp_b"] * math.exp(-d["beta_b"] * t),
            lambda t: d["Mp_h"] * (1.0 - math.exp(-d["alpha_h"] * t)))


def initial_speeds(scene: str, torque, d=DRIVE, m=MOTOR):
    """Steady state before the command: idle (engage scene) or working stroke (stop scene)."""
    p = d["r_b"] / d["r_a"]
    if scene == "engage":  # carrier held, ring backwards: M = M_ca + M_cb/p
        w_a = steady_speed(torque, d["M_ca"] + d["M_cb"] / p, m=m)
        return w_a, 0.0
    w_a = steady_speed(torque, d["M_ca"] + d["M_ch"] / (1.0 + p), m=m)  # ring held
    return w_a, w_a / (1.0 + p)


# -- 1. monolithic Newton-Euler reference ------------------------------------------------------
class NewtonEulerDrive:
    def __init__(self, scene: str, linear: bool, d=DRIVE, power=None, m=MOTOR):
        self.d, self.scene = d, scene
        self.torque = motor_law(linear, m)
        self.Mtb, self.Mth = brake_laws(scene, d, power)
        self.dir = {}

    def w_b(self, w_a, w_h):
        d = self.d
        return (-d["r_a"] * w_a + (d["r_a"] + d["r_b"]) * w_h) / d["r_b"]

    def capacities(self, t):
        return self.Mtb(t) + self.d["M_cb"], self.Mth(t) + self.d["M_ch"]

    def solve(self, t, w_a, w_h, mode):
        """Accelerations (a_a, a_b, a_h), tooth force R and friction torques (T_b, T_h)."""
        d = self.d
        ra, rb = d["r_a"], d["r_b"]
        C_b, C_h = self.capacities(t)
        A = np.zeros((6, 6))  # unknowns a_a, a_b, a_h, R, T_b, T_h
        rhs = np.zeros(6)
        A[0, [0, 3]] = d["J_a"], ra
        rhs[0] = self.torque(w_a) - d["M_ca"]
        A[1, [1, 3, 4]] = d["J_b"], rb, -1.0
        A[2, [2, 3, 5]] = d["J_h"], -(ra + rb), -1.0
        A[3, [0, 1, 2]] = ra, rb, -(ra + rb)
        for row, k, ia, it, C in ((4, "b", 1, 4, C_b), (5, "h", 2, 5, C_h)):
            if mode[k] == 0:
                A[row, ia] = 1.0  # locked: a_k = 0
            else:
                A[row, it] = 1.0  # sliding: T_k = -C_k sgn w_k
                rhs[row] = -C * mode[k]
        a_a, a_b, a_h, R, T_b, T_h = np.linalg.solve(A, rhs)
        return a_a, a_b, a_h, R, T_b, T_h

    def rhs(self, t, y, mode):
        w_a, w_h = y[0], y[1]
        w_b = self.w_b(w_a, w_h)
        a_a, _, a_h, _, _, _ = self.solve(t, w_a, w_h, mode)
        d = self.d
        sb = abs(w_b) if mode["b"] else 0.0
        sh = abs(w_h) if mode["h"] else 0.0
        return [a_a, a_h, self.Mtb(t) * sb, self.Mth(t) * sh,
                d["M_ca"] * w_a + d["M_cb"] * sb + d["M_ch"] * sh, self.torque(w_a) * w_a]

    def kinetic(self, w_a, w_h):
        d = self.d
        return 0.5 * (d["J_a"] * w_a ** 2 + d["J_b"] * self.w_b(w_a, w_h) ** 2
                      + d["J_h"] * w_h ** 2)


def reference_run(scene: str, linear: bool, t_end: float, rtol=1e-12, atol=1e-12,
                  power=None, m=MOTOR) -> dict:
    """Monolithic run from the steady state with the command at t = 0; returns the event list
    [(t, 'slip'/'lock'/'pass', member, direction)], the speeds (w_a, w_b, w_h) at each event,
    end speeds and energies (motor `m`: nameplate dict as MOTOR). With `power` the
    brakes follow the power law and the integration is split at its kinks."""
    ne = NewtonEulerDrive(scene, linear, power=power, m=m)
    kinks = sorted({power[k] for k in ("tc_b", "tr_b", "tc_h", "tr_h")}) if power else []
    w_a, w_h = initial_speeds(scene, ne.torque, ne.d, m)
    mode = {"b": -1, "h": 0} if scene == "engage" else {"b": 0, "h": 1}
    y = np.array([w_a, w_h, 0.0, 0.0, 0.0, 0.0])
    t, events_seen, speeds = 0.0, [], []
    E0 = ne.kinetic(w_a, w_h)
    for _ in range(40):
        funcs, kinds = [], []
        for k in ("b", "h"):
            if mode[k] == 0:
                for sgn in (+1, -1):  # T_k reaches -sgn*C_k: breaks free in direction sgn
                    def g(s, yy, k=k, sgn=sgn, mode=mode):
                        r = ne.solve(s, yy[0], yy[1], mode)
                        C = ne.capacities(s)[0 if k == "b" else 1]
                        return C + sgn * r[4 if k == "b" else 5]
                    g.terminal, g.direction = True, -1
                    funcs.append(g)
                    kinds.append(("slip", k, sgn))
            else:
                def g(s, yy, k=k):
                    return ne.w_b(yy[0], yy[1]) if k == "b" else yy[1]
                g.terminal, g.direction = True, -mode[k]
                funcs.append(g)
                kinds.append(("zero", k, 0))
        t_stop = min([tk for tk in kinks if tk > t] + [t_end])
        sol = solve_ivp(lambda s, yy, mode=mode: ne.rhs(s, yy, mode), (t, t_stop), y,
                        method="DOP853", rtol=rtol, atol=atol, events=funcs)
        assert sol.status >= 0, sol.message
        if sol.status == 0:
            t, y = t_stop, sol.y[:, -1]
            if t_stop == t_end:
                break
            continue
        i = next(j for j, te in enumerate(sol.t_events) if len(te))
        t, y = float(sol.t_events[i][0]), sol.y_events[i][0].copy()
        kind, k, sgn = kinds[i]
        if kind == "slip":
            mode = dict(mode, **{k: sgn})
            events_seen.append((t, "slip", k, sgn))
        else:
            if k == "h":
                y[1] = 0.0
            else:  # w_b = 0: move w_a onto the constraint (w_a = (1+p) w_h)
                y[0] = (ne.d["r_a"] + ne.d["r_b"]) * y[1] / ne.d["r_a"]
            trial = dict(mode, **{k: 0})
            T = ne.solve(t, y[0], y[1], trial)[4 if k == "b" else 5]
            C = ne.capacities(t)[0 if k == "b" else 1]
            if abs(T) <= C:
                mode = trial
                events_seen.append((t, "lock", k, 0))
            else:
                mode = dict(mode, **{k: -1 if T > 0 else 1})
                events_seen.append((t, "pass", k, mode[k]))
        speeds.append((y[0], ne.w_b(y[0], y[1]), y[1]))
    w_a, w_h = y[0], y[1]
    E_kin = ne.kinetic(w_a, w_h)
    return {"events": events_seen, "speeds_at_events": speeds, "w_a": w_a, "w_b": ne.w_b(w_a, w_h), "w_h": w_h,
            "E_brake_b": y[2], "E_brake_h": y[3], "E_resist": y[4], "W_motor": y[5],
            "dE_kin": E_kin - E0, "mode": mode}


# -- 2. closed form with the linear motor law ---------------------------------------------------
def closed_form(scene: str, t_end: float, d=DRIVE, m=MOTOR) -> dict:
    """Piecewise matrix-exponential solution, z = (w_b, w_h, e_b, e_h, 1): the phases' linear
    systems from the product (crankfmu.studies.papers.planetary_phases, written apart from the
    model and its reference), integrated here with scipy's expm and its own event search."""
    from crankfmu.studies.papers import planetary_phases

    c0 = motor_law(True, m)(0.0)
    c1 = c0 - motor_law(True, m)(1.0)
    pieces, C, _, p, mode1, held, mover = planetary_phases(d, c0, c1, scene)

    def z_at(A, z, s):
        return expm(A * s) @ z

    def grid(A, z, span, n=400):
        """z at n + 1 equally spaced instants over span (one expm, repeated products)."""
        step = expm(A * (span / n))
        out = [z]
        for _ in range(n):
            out.append(step @ out[-1])
        return np.linspace(0.0, span, n + 1), out

    def first_root(f_of_z, A, z, t0, t1):
        """First root after t0 of s -> f(z(s)): bracketed on a grid, polished by brentq on
        the exact expm."""
        ts, zs = grid(A, z, t1 - t0)
        vals = [f_of_z(zz) for zz in zs]
        for a, b, fa, fb in zip(ts[:-1], ts[1:], vals[:-1], vals[1:]):
            if fa * fb < 0.0:
                return t0 + brentq(lambda s: f_of_z(z_at(A, z, s)), a, b, xtol=1e-15,
                                   rtol=1e-15, maxiter=200)
        return None

    torque = motor_law(True, m)
    w_a0, w_h0 = initial_speeds(scene, torque, d, m)
    z0 = np.array([(-w_a0 + (1 + p) * w_h0) / p, w_h0, 1.0, 1.0, 1.0])
    # phase 1: `held` is locked until its friction torque reaches its capacity
    A1, F_b1, F_h1 = pieces(mode1)
    F1 = F_h1 if held == "h" else F_b1

    def g1(z):  # capacity minus |holding torque|: the held member breaks free at its root
        return float(C[held] @ z - abs(F1 @ z))

    t1 = first_root(g1, A1, z0, 0.0, t_end)
    z1 = z_at(A1, z0, t1)
    F_at_t1 = float(F1 @ z1)
    direction = -1 if F_at_t1 > 0 else 1
    # phase 2: both slide until `mover` stops
    mode2 = dict(mode1, **{held: direction})
    A2, _, _ = pieces(mode2)
    i_mover = 0 if mover == "b" else 1
    t2 = first_root(lambda z: float(z[i_mover]), A2, z1, t1, t_end)
    z2 = z_at(A2, z1, t2 - t1)
    z2[i_mover] = 0.0
    # phase 3: `mover` locked
    mode3 = dict(mode2, **{mover: 0})
    A3, F_b3, F_h3 = pieces(mode3)
    z3 = z_at(A3, z2, t_end - t2)
    F3 = F_b3 if mover == "b" else F_h3
    hold_margin = min(float(C[mover] @ z - abs(F3 @ z)) for z in grid(A3, z2, t_end - t2)[1])

    def w_a(z):
        return -p * z[0] + (1 + p) * z[1]

    return {"t_slip": t1, "slip_direction": direction, "t_lock": t2,
            "w_a_lock": w_a(z2), "w_h_lock": z2[1], "w_b_lock": z2[0],
            "w_a": w_a(z3), "w_b": z3[0], "w_h": z3[1], "hold_margin": hold_margin}


# -- 3. the model's own advance over communication steps ---------------------------------------
def run_model(drive, torque, command: float, t_end: float, h: float, coupling: str,
              rtol=1e-10, atol=1e-10, u_extra=None, sample=None):
    """Run `drive` (already constructed; initial_state is called here) with the motor torque
    fed through u_of_t. Returns (outputs dict at t_end, list of per-step output rows,
    iterations per step). `u_extra(t)` may return (flange_tau, flange_J) for the carrier."""
    extra = u_extra or (lambda t: (0.0, 0.0))
    names = [v.name for v in drive.outputs]

    def inputs(t, M):
        ft, fj = extra(t)
        return np.array([command, M, 0.0, ft, fj])

    # the state before the command: the input command differs from initial_period's command
    x = drive.initial_state(inputs(0.0, 0.0))
    w_a = drive.sun_speed(x)
    x = drive.initial_state(inputs(0.0, torque(w_a)))
    n = int(round(t_end / h))
    rows, iterations = [], []
    slope = 0.0
    for i in range(n):
        t = i * h
        M0 = torque(drive.sun_speed(x))
        if coupling == "zoh":
            x = drive.advance(t, x, h, lambda s, M0=M0: inputs(s, M0), rtol, atol)
            iterations.append(1)
        else:
            saved_x, saved_d = x.copy(), drive.discrete_state()
            M1 = M0 + slope * h
            for it in range(1, 31):
                drive.set_discrete_state(saved_d)
                def u_of_t(s, t=t, M0=M0, M1=M1):
                    return inputs(s, M0 + (M1 - M0) * (s - t) / h)
                x_new = drive.advance(t, saved_x.copy(), h, u_of_t, rtol, atol)
                M1_new = torque(drive.sun_speed(x_new))
                done = abs(M1_new - M1) <= 1e-11 * (1.0 + abs(M1))
                M1 = M1_new
                if done:
                    break
            iterations.append(it)
            slope = (M1 - M0) / h
            x = x_new
        row = drive.output_values((i + 1) * h, x, inputs((i + 1) * h, torque(drive.sun_speed(x))))
        rows.append(row)
        if sample is not None:
            sample(drive, (i + 1) * h, x)
    out = dict(zip(names, rows[-1]))
    out["discrete"] = drive.discrete_state()
    return out, rows, iterations
