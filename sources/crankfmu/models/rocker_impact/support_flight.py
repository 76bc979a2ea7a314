"""Free flight of the rocker on its elastic (linear) support, the support in closed form.

Out of contact, in psi = theta + (m r/J_t) u0 the rocker's equations separate (README.md,
"Free flight"):

    J_t psi'' = torque                                      (the rocker about the pivot)
    u0'' + 2 alpha u0' + k^2 u0 = G,   k^2 = c0 J_t/(m J_C),  2 alpha = d0 J_t/(m J_C),
                                       G = (J_t F_axis - m r torque)/(m J_C)

torque and F_axis: the rocker's loads apart from contact and support (RockerImpact: the drive
torque; the hammer: the rod). The support is a stiff oscillator (MO-100: k ~ 1.6e4 rad/s) that an
explicit method crosses in steps of ~0.2 ms at best and follows in far smaller ones while it
rings. Here it is exact over a segment (at most the step): G is a cubic in time plus its linear
dependence on (u0, u0') (the rod's stiffness and damping at the support, frozen over the
segment), and cf.DampedOscillator gives u0 in closed form. psi and the model's further states
(crank, energies) are integrated by Dormand-Prince with u0 from that closed form.

The cubic is G's on the segment's own trajectory: its values at both ends and its integral and
first moment over the segment, which the integrator forms as it integrates the slow states
(G less its frozen part rides along as the rate of an extra state: dopri.moments); the second
moment tells how far G is from a cubic. So the slow equations first see u0 from a guess (the
previous segment's cubic, extrapolated); the segment is repeated while the u0 they saw differs
from the fitted one's by more than the slow states' tolerance allows, or while the cubic or the
frozen coefficients miss G by more than u0's tolerance allows (then on half the length).

The ringing also shakes the slow equations (the rod's pull depends on u0): that part, linear in
the ringing's (u0, u0') with the rates' derivatives frozen over the segment, is integrated in
closed form too (the slow states are integrated less it, `true_state` adds it back). What is
left (the derivatives' change over the segment times the ringing) is followed with steps of at
most RIPPLE_STEP/omega while it could move a state by more than its tolerance.
"""
from __future__ import annotations

import math

from ...runtime import closed_form as cf
from ...runtime import dopri
from ...runtime.model import TOLERANCE_FACTOR

MAX_PASSES = 6        # tries of a segment (refits, halvings) before the full equations take over
RIPPLE_STEP = 0.5 * math.pi  # rad of the support's ringing per step while the rates ring
FROZEN_ENOUGH = 0.01  # of u0's tolerance: ringing this weak, the frozen terms need no update
NEGLIGIBLE_RINGING = 0.1  # of u0's tolerance: a ringing this weak is left out (each segment
# starts one of ~1e-2 of it: the cubics of neighbouring segments differ in their slope)
# The cubic p on sigma = s/H in [0, 1] with p(0), p(1), the integral and the first moment of G:
# p = g0 + b sigma + c sigma^2 + d sigma^3, (b, c, d) = MOMENT_FIT (g1 - g0, m0 - g0, m1 - g0/2)
# (the inverse of [[1, 1, 1], [1/2, 1/3, 1/4], [1/3, 1/4, 1/5]]). For G = sigma^4 it misses by
# sigma (sigma - 1)(5 sigma^2 - 5 sigma + 1)/5, at most 1/80, and its second moment by 1/2100:
# MOMENT_ERROR = 2100/80 turns the second moment's miss into the largest miss.
MOMENT_FIT = ((3.0, 36.0, -60.0), (-12.0, -96.0, 180.0), (10.0, 60.0, -120.0))
MOMENT_ERROR = 26.25


class SupportFlight:
    """One free-flight segment of a RockerImpact (or subclass) with the linear elastic support
    from (t, x), inertia J_t about the pivot; `run(t_end)`. The integrated states z: psi,
    Omega = psi', the model's states after the rocker's (the tail), and the integral of G less
    its frozen part (last)."""

    def __init__(self, model, t, x, J_t, u_of_t, rtol, atol):
        p = model.p
        self.model, self.t, self.x, self.J_t, self.u_of_t, self.rtol = \
            model, t, x, J_t, u_of_t, rtol
        self.mr, self.d0 = model._mr, model._support_damping
        self.det = p.m * J_t - self.mr * self.mr   # m J_C
        self.mu = self.mr / J_t
        self.k2 = model._c0 * J_t / self.det
        self.two_alpha = self.d0 * J_t / self.det
        self.atol_u = TOLERANCE_FACTOR * atol[0]   # u0's, as the integrator would hold it
        self.atol = atol[2:4] + atol[8:]  # psi and Omega as theta and omega; the tail
        self.atol_z = [TOLERANCE_FACTOR * a for a in self.atol]
        self.steps_u = (1e-4 * model._length, 1e-4 * max(p.V0, 1.0))  # differences
        self.z0 = [x[2] + self.mu * x[0], x[3] + self.mu * x[1]] + x[8:] + [0.0]
        self.f_u = self.f_v = ()  # the rates' derivatives by u0, u0' frozen over the segment
        self.G_u = self.G_v = 0.0
        self.last = (None, 0.0)   # (time, G) of the last call of the slow equations

    # -- the loads ---------------------------------------------------------------------------
    def loads(self, s, z, u0, v0):
        """(G, [Omega', tail rates]) at time s, slow states z (psi, Omega, tail), support
        (u0, v0)."""
        mu, J_t = self.mu, self.J_t
        torque, F_axis, _, tail = self.model._load(s, u0, v0, z[0] - mu * u0, z[1] - mu * v0,
                                                   z[2:], self.u_of_t(s), 0.0)
        return (J_t * F_axis - self.mr * torque) / self.det, [torque / J_t] + tail

    def linearised(self, s, z, u0, v0, previous=None):
        """(R, G_u, G_v, f_u, f_v): G's and the rates' derivatives by u0 and u0' (differences)
        and R = G - G_u u0 - G_v u0'. With `previous` (its derivatives, kept while ringing
        weaker than FROZEN_ENOUGH of u0's tolerance makes them irrelevant) only R, from the
        last call of the slow equations if that was at s."""
        if previous is not None:
            _, G_u, G_v, f_u, f_v = previous
            G = self.last[1] if self.last[0] == s else self.loads(s, z, u0, v0)[0]
            return G - G_u * u0 - G_v * v0, G_u, G_v, f_u, f_v
        G, f = self.loads(s, z, u0, v0)
        du, dv = self.steps_u
        G_pu, f_pu = self.loads(s, z, u0 + du, v0)
        G_pv, f_pv = self.loads(s, z, u0, v0 + dv)
        G_u, G_v = (G_pu - G) / du, (G_pv - G) / dv
        return (G - G_u * u0 - G_v * v0, G_u, G_v, [(b - a) / du for a, b in zip(f, f_pu)],
                [(b - a) / dv for a, b in zip(f, f_pv)])

    def true_state(self, osc, s, z):
        """(psi, Omega and tail, u0, u0', the ringing's u0, u0') at s (from the segment's start)
        for the integrated z (less the ringing's part: psi by the ringing integrated twice,
        Omega and the tail once, through the frozen derivatives)."""
        u0, v0 = osc.forced(s)
        if not osc.rings:
            return z[:-1], u0, v0, 0.0, 0.0
        u_r, v_r = osc.ringing(s)
        once, twice = osc.ringing_integrals(s, u_r, v_r)
        f_u, f_v, moved = self.f_u, self.f_v, u_r - osc.q0  # moved: u_r' integrated
        true = [z[0] + f_u[0] * twice + f_v[0] * (once - osc.q0 * s)]
        true += [y + a * once + b * moved for y, a, b in zip(z[1:-1], f_u, f_v)]
        return true, u0 + u_r, v0 + v_r, u_r, v_r

    # -- the segment ---------------------------------------------------------------------------
    def run(self, t_end):
        """(t, x, stopped) at the segment's end (t_end, or earlier: stopped where contact may
        begin, or a shorter segment), or the time up to which the full equations must
        integrate instead."""
        model, t, x = self.model, self.t, self.x
        u0, v0 = x[0], x[1]
        carried = model._carried
        if carried is not None and abs(carried[0] - t) <= 1e-12 * max(1.0, abs(t)):
            _, guess, start, resolve = carried
        else:
            start, resolve = self.linearised(t, self.z0, u0, v0), False
            guess = [start[0]]
        _, self.G_u, self.G_v, self.f_u, self.f_v = start
        alpha, k2 = 0.5 * (self.two_alpha - self.G_v), self.k2 - self.G_u
        if not k2 > alpha * alpha or (self.d0 > 0.0 and alpha <= 0.0):
            return t_end
        self.alpha, self.k2_eff = alpha, k2
        negligible = NEGLIGIBLE_RINGING * self.atol_u
        # the integral of G: a tolerance that moves u0 by u0's over the step (quasi-statically)
        atol = self.atol + [k2 * self.atol_u / TOLERANCE_FACTOR * (t_end - t)]
        h_start, t_stop, t_near = model._h_next, t_end, None
        for _ in range(MAX_PASSES):
            osc = cf.DampedOscillator(alpha, k2, u0, v0, guess, negligible)
            near = self.near_contact(osc)
            if near(t, self.z0) >= 0.0:
                return self.separated(osc, near(t, self.z0), t_end)
            model._h_next, dense = h_start, []
            sol = model.integrate(self.u_of_t, t, self.z0, t_stop, self.rtol, atol,
                                  [] if t_near else [near], self.rates(osc), dense,
                                  RIPPLE_STEP / osc.omega if resolve else math.inf)
            if sol.status == 1:  # where contact may begin: integrated up to there on its own,
                t_stop = t_near = sol.t  # for the moments (the integrator's stages to there)
                continue
            H = sol.t - t
            z_end, u_end, v_end, _, _ = self.true_state(osc, H, sol.x)
            ringing = osc.ringing_bound(0.0)
            end = self.linearised(sol.t, z_end, u_end, v_end, previous=(
                start if ringing * max(abs(self.G_u), abs(self.G_v) * osc.omega)
                < FROZEN_ENOUGH * k2 * self.atol_u else None))
            shaken = self.shaken(osc, ringing, end)
            if shaken and not resolve:
                resolve = True   # the ripple left must be followed by the steps
                continue
            fit, fit_error = self.forcing(start[0], end, u_end, v_end, H, dense)
            drift = ringing * H * (abs(end[1] - self.G_u) / osc.omega + abs(end[2] - self.G_v))
            if fit_error > k2 * self.atol_u or 0.25 * drift > self.atol_u:
                t_stop, guess = t + 0.5 * H, fit   # the cubic or the frozen terms too coarse
                continue
            if not self.saw_within_tolerance(guess, fit, H):
                guess = fit
                continue
            break
        else:
            model._h_next = h_start
            return t_end
        return self.finish(sol, z_end, cf.DampedOscillator(alpha, k2, u0, v0, fit, negligible),
                           H, fit, end, shaken, sol.t == t_near)

    def rates(self, osc):
        """The slow equations less the ringing's part, with u0 from osc, and G less its frozen
        part as the last rate. The last call's time and G are kept in self.last: the
        integrator's last call is at the end state (first same as last)."""
        t, mu, J_t, mr, det, load = self.t, self.mu, self.J_t, self.mr, self.det, \
            self.model._load
        true_state, f_u, f_v, forced = self.true_state, self.f_u, self.f_v, osc.forced
        G_u, G_v = self.G_u, self.G_v

        def rates(s, z, u):
            if osc.rings:
                zt, u0, v0, u_r, v_r = true_state(osc, s - t, z)
            else:  # the common case, spelled out (a hot path)
                (u0, v0), zt = forced(s - t), z
            torque, F_axis, _, tail = load(s, u0, v0, zt[0] - mu * u0, zt[1] - mu * v0,
                                           zt[2:len(f_u) + 1], u, 0.0)
            G = (J_t * F_axis - mr * torque) / det
            self.last = (s, G)
            R = G - G_u * u0 - G_v * v0
            if not osc.rings:
                return [z[1], torque / J_t] + tail + [R]
            return [z[1]] + [f - a * u_r - b * v_r
                             for f, a, b in zip([torque / J_t] + tail, f_u, f_v)] + [R]
        return rates

    def near_contact(self, osc):
        """A terminal event >= delta = (1 - S mu) u0 + S psi - w_tool - gap everywhere (the
        ringing by its bound, and a margin): contact may begin only after its zero."""
        model, t = self.model, self.t
        S, w_tool, gap = model.p.S, self.x[4], model._gap
        lever = 1.0 - S * self.mu
        margin = 1e-6 * model._length

        def near(s, z):
            if not osc.rings:
                return lever * osc.forced(s - t)[0] + margin + S * z[0] - w_tool - gap
            psi = self.true_state(osc, s - t, z)[0][0]
            return (lever * osc.forced(s - t)[0] + abs(lever) * osc.ringing_bound(s - t)
                    + margin + S * psi - w_tool - gap)
        near.terminal, near.direction = True, 1.0
        return near

    def separated(self, osc, distance, t_end) -> float:
        """When the strike point will be `distance` farther from the tool (twice that at its
        present speed, at least a quarter period of the ringing), or t_end if it approaches."""
        S = self.model.p.S
        speed = -(S * self.z0[1] + (1.0 - S * self.mu) * osc.forced(0.0)[1])
        if speed <= 0.0:
            return t_end
        return min(t_end, self.t + max(2.0 * distance / speed, 0.5 * math.pi / osc.omega))

    def shaken(self, osc, ringing, end) -> bool:
        """Could the ripple the frozen derivatives leave (their change over the segment times
        the ringing) move a state by more than its tolerance (psi by Omega's ripple over omega
        twice, the others by their rate's over omega)?"""
        if ringing == 0.0 or end[3] is self.f_u:  # no ringing, or derivatives kept
            return False
        w, atol_z = osc.omega, self.atol_z
        ripple = [ringing * (abs(a1 - a0) + abs(b1 - b0) * w) / w
                  for a0, a1, b0, b1 in zip(self.f_u, end[3], self.f_v, end[4])]
        return ripple[0] / w > atol_z[0] or any(r > a for r, a in zip(ripple, atol_z[1:]))

    def forcing(self, R_start, end, u_end, v_end, H, dense):
        """(the cubic in s with R at both ends and R's integral and first moment over the
        segment, an estimate of its largest miss from the second moment): R = G - G_u u0 -
        G_v u0' with this segment's frozen terms, also at the end."""
        g0 = R_start
        g1 = end[0] + (end[1] - self.G_u) * u_end + (end[2] - self.G_v) * v_end
        m0, m1, m2 = dopri.moments(dense, self.t, -1, 3)
        rhs = (g1 - g0, m0 / H - g0, m1 / (H * H) - 0.5 * g0)
        b, c, d = (sum(a * y for a, y in zip(row, rhs)) for row in MOMENT_FIT)
        miss = m2 / (H * H * H) - (g0 / 3.0 + b / 4.0 + c / 5.0 + d / 6.0)
        return [g0, b / H, c / (H * H), d / (H * H * H)], MOMENT_ERROR * abs(miss)

    def saw_within_tolerance(self, guess, fit, H) -> bool:
        """Did the slow equations see u0 close enough to the fitted forcing's? They saw the
        response to the guess, which misses the fit by at most e (at the quarter points): a
        difference of at most 2 e/k^2 in u0 (its quasi-static part, and the ringing it starts),
        omega times that in u0'. The rates' errors from it over the segment: Omega's and the
        tail's by H, psi's by H^2/2."""
        difference = cf.poly_add(fit, guess, scales=(1.0, -1.0))
        e = max(abs(cf.poly_value(difference, s)) for s in (0.0, 0.25 * H, 0.5 * H, 0.75 * H, H))
        du = 2.0 * e / self.k2_eff
        dv = du * math.sqrt(self.k2_eff)
        atol_z, f_u, f_v = self.atol_z, self.f_u, self.f_v
        if 0.5 * (abs(f_u[0]) * du + abs(f_v[0]) * dv) * H * H > atol_z[0]:
            return False
        for a, b, tol in zip(f_u, f_v, atol_z[1:]):
            if (abs(a) * du + abs(b) * dv) * H > tol:
                return False
        return True

    def finish(self, sol, z_end, osc, H, fit, end, shaken, stopped):
        """The state at the segment's end; the fit, the end's linearisation and whether the
        ripple needed following carried to the next segment."""
        model, x, mu = self.model, self.x, self.mu
        u1, v1 = osc.state(H)
        x1 = [u1, v1, z_end[0] - mu * u1, z_end[1] - mu * v1] + x[4:8] + z_end[2:]
        if self.d0 > 0.0:  # the support damper's loss d0 u0'^2, integrated exactly
            loss = osc.damping_loss(H, (u1, v1)) / (2.0 * osc.alpha)  # per d0
            x1[model._damper_state] += self.d0 * loss
        model._carried = (sol.t, cf.poly_shift(fit, H), end, shaken)
        return sol.t, x1, stopped
