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

The cubic comes from the segment's own trajectory (G at five times), so the slow equations first
see u0 from a guess (the previous segment's cubic, extrapolated); the segment is repeated while
the u0 they saw differs from the fitted one's by more than the slow states' tolerance allows, or
while the cubic or the frozen coefficients miss G by more than u0's tolerance allows (then on
half the length).

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


class SupportFlight:
    """One free-flight segment of a RockerImpact (or subclass) with the linear elastic support
    from (t, x), inertia J_t about the pivot; `run(t_end)`. The slow states z: psi, Omega =
    psi' and the model's states after the rocker's (the tail)."""

    def __init__(self, model, t, x, J_t, u_of_t, rtol, atol):
        p = model.p
        self.model, self.t, self.x, self.J_t, self.u_of_t, self.rtol = \
            model, t, x, J_t, u_of_t, rtol
        self.mr, self.d0 = model._mr, model._support_damping
        self.det = p.m * J_t - self.mr * self.mr   # m J_C
        self.mu = self.mr / J_t
        self.k2 = model._c0 * J_t / self.det
        self.two_alpha = self.d0 * J_t / self.det
        self.atol = atol[2:4] + atol[8:]           # psi, Omega as theta, omega; the tail
        self.atol_z = [TOLERANCE_FACTOR * a for a in self.atol]
        self.atol_u = TOLERANCE_FACTOR * atol[0]   # u0's, as the integrator would hold it
        self.steps_u = (1e-4 * model._length, 1e-4 * max(p.V0, 1.0))  # differences
        self.z0 = [x[2] + self.mu * x[0], x[3] + self.mu * x[1]] + x[8:]
        self.last = (None, 0.0)  # (time, G) of the last call of the slow equations
        self.f_u = self.f_v = ()  # the rates' derivatives by u0, u0' frozen over the segment

    # -- the loads ---------------------------------------------------------------------------
    def loads(self, s, z, u0, v0):
        """(G, [Omega', tail rates]) at time s, slow states z, support (u0, v0)."""
        mu, J_t = self.mu, self.J_t
        torque, F_axis, _, tail = self.model._load(s, u0, v0, z[0] - mu * u0, z[1] - mu * v0,
                                                   z[2:], self.u_of_t(s), 0.0)
        return (J_t * F_axis - self.mr * torque) / self.det, [torque / J_t] + tail

    def forcing_at(self, s, z, u0, v0) -> float:
        """G alone."""
        mu = self.mu
        torque, F_axis = self.model._pull(s, u0, v0, z[0] - mu * u0, z[1] - mu * v0, z[2:],
                                          self.u_of_t(s))
        return (self.J_t * F_axis - self.mr * torque) / self.det

    def linearised(self, s, z, u0, v0, previous=None):
        """(R, G_u, G_v, f_u, f_v): G's and the rates' derivatives by u0 and u0' (differences)
        and R = G - G_u u0 - G_v u0'. With `previous` (its derivatives, kept while ringing
        weaker than FROZEN_ENOUGH of u0's tolerance makes them irrelevant) only G, which the
        last call of `rates` may have evaluated there."""
        if previous is not None:
            _, G_u, G_v, f_u, f_v = previous
            G = self.last[1] if self.last[0] == s else self.forcing_at(s, z, u0, v0)
            return G - G_u * u0 - G_v * v0, G_u, G_v, f_u, f_v
        G, f = self.loads(s, z, u0, v0)
        du, dv = self.steps_u
        G_pu, f_pu = self.loads(s, z, u0 + du, v0)
        G_pv, f_pv = self.loads(s, z, u0, v0 + dv)
        G_u, G_v = (G_pu - G) / du, (G_pv - G) / dv
        return (G - G_u * u0 - G_v * v0, G_u, G_v, [(b - a) / du for a, b in zip(f, f_pu)],
                [(b - a) / dv for a, b in zip(f, f_pv)])

    def true_state(self, osc, s, z):
        """(z, u0, u0', the ringing's u0, u0') at s (from the segment's start) for the
        integrated slow states z (less the ringing's part: psi by the ringing integrated
        twice, Omega and the tail once, through the frozen derivatives)."""
        u0, v0 = osc.forced(s)
        if not osc.rings:
            return z, u0, v0, 0.0, 0.0
        u_r, v_r = osc.ringing(s)
        once, twice = osc.ringing_integrals(s, u_r, v_r)
        f_u, f_v, moved = self.f_u, self.f_v, u_r - osc.q0  # moved: u_r' integrated
        true = [z[0] + f_u[0] * twice + f_v[0] * (once - osc.q0 * s)]
        true += [y + a * once + b * moved for y, a, b in zip(z[1:], f_u, f_v)]
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
        _, G_u, G_v, self.f_u, self.f_v = start
        alpha, k2 = 0.5 * (self.two_alpha - G_v), self.k2 - G_u
        if not k2 > alpha * alpha or (self.d0 > 0.0 and alpha <= 0.0):
            return t_end
        self.alpha, self.k2_eff = alpha, k2
        negligible = NEGLIGIBLE_RINGING * self.atol_u
        h_start, t_stop = model._h_next, t_end
        for _ in range(MAX_PASSES):
            osc = cf.DampedOscillator(alpha, k2, u0, v0, guess, negligible)
            near = self.near_contact(osc)
            if near(t, self.z0) >= 0.0:
                return self.separated(osc, near(t, self.z0), t_end)
            model._h_next, dense = h_start, []
            sol = model.integrate(self.u_of_t, t, self.z0, t_stop, self.rtol, self.atol, [near],
                                  self.rates(osc), dense,
                                  RIPPLE_STEP / osc.omega if resolve else math.inf)
            H = sol.t - t
            z_end, u_end, v_end, _, _ = self.true_state(osc, H, sol.x)
            ringing = osc.ringing_bound(0.0)
            end = self.linearised(sol.t, z_end, u_end, v_end, previous=(
                start if ringing * max(abs(G_u), abs(G_v) * osc.omega)
                < FROZEN_ENOUGH * k2 * self.atol_u else None))
            shaken = self.shaken(osc, ringing, end)
            if shaken and not resolve:
                resolve = True   # the ripple left must be followed by the steps
                continue
            fit, nodes, values = self.forcing(osc, start, end, H, dense)
            drift = ringing * H * (abs(end[1] - G_u) / osc.omega + abs(end[2] - G_v)) / 4.0
            if abs(cf.poly_value(fit, nodes[4]) - values[4]) > k2 * self.atol_u or \
                    drift > self.atol_u:
                t_stop, guess = t + 0.5 * H, fit   # the cubic or the frozen terms too coarse
                continue
            if not self.saw_within_tolerance(guess, nodes, values, H):
                guess = fit
                continue
            break
        else:
            model._h_next = h_start
            return t_end
        return self.finish(sol, z_end, cf.DampedOscillator(alpha, k2, u0, v0, fit, negligible),
                           H, fit, end, shaken)

    def rates(self, osc):
        """The slow equations less the ringing's part, with u0 from osc. The last call's time
        and G are kept in self.last: the integrator's last call is at the end state (first
        same as last)."""
        t, mu, J_t, mr, det, load = self.t, self.mu, self.J_t, self.mr, self.det, \
            self.model._load
        true_state, f_u, f_v = self.true_state, self.f_u, self.f_v

        def rates(s, z, u):
            zt, u0, v0, u_r, v_r = true_state(osc, s - t, z)
            torque, F_axis, _, tail = load(s, u0, v0, zt[0] - mu * u0, zt[1] - mu * v0, zt[2:],
                                           u, 0.0)
            self.last = (s, (J_t * F_axis - mr * torque) / det)
            if not osc.rings:
                return [z[1], torque / J_t] + tail
            return [z[1]] + [f - a * u_r - b * v_r
                             for f, a, b in zip([torque / J_t] + tail, f_u, f_v)]
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
        w, atol_z = osc.omega, self.atol_z
        ripple = [ringing * (abs(a1 - a0) + abs(b1 - b0) * w) / w
                  for a0, a1, b0, b1 in zip(self.f_u, end[3], self.f_v, end[4])]
        return ripple[0] / w > atol_z[0] or any(r > a for r, a in zip(ripple, atol_z[1:]))

    def forcing(self, osc, start, end, H, dense):
        """(the cubic through R at 0, H/3, 2H/3, H; the nodes; R at them and at H/2, last)."""
        t, G_u, G_v = self.t, start[1], start[2]
        nodes = (0.0, H / 3.0, 2.0 * H / 3.0, H, 0.5 * H)
        inner = []
        for s in (nodes[1], nodes[2], nodes[4]):
            z, u0, v0, _, _ = self.true_state(osc, s, dopri.dense_value(dense, t + s))
            inner.append(self.forcing_at(t + s, z, u0, v0) - G_u * u0 - G_v * v0)
        # R is G - G_u u0 - G_v u0' with this segment's frozen terms, also at the end
        u_end, v_end = osc.state(H)
        values = [start[0], inner[0], inner[1],
                  end[0] + (end[1] - G_u) * u_end + (end[2] - G_v) * v_end, inner[2]]
        return cf.poly_through(nodes[:4], values[:4]), nodes, values

    def saw_within_tolerance(self, guess, nodes, values, H) -> bool:
        """Did the slow equations see u0 close enough to the fitted forcing's? They saw the
        response to the guess, which misses R by at most e at the nodes: a difference of at
        most 2 e/k^2 in u0 (its quasi-static part, and the ringing it starts), omega times that
        in u0'. The rates' errors from it over the segment: Omega's and the tail's by H, psi's
        by H^2/2."""
        e = 0.0
        for s, value in zip(nodes, values):
            e = max(e, abs(cf.poly_value(guess, s) - value))
        du = 2.0 * e / self.k2_eff
        dv = du * math.sqrt(self.k2_eff)
        atol_z, f_u, f_v = self.atol_z, self.f_u, self.f_v
        if 0.5 * (abs(f_u[0]) * du + abs(f_v[0]) * dv) * H * H > atol_z[0]:
            return False
        for a, b, tol in zip(f_u, f_v, atol_z[1:]):
            if (abs(a) * du + abs(b) * dv) * H > tol:
                return False
        return True

    def finish(self, sol, z_end, osc, H, fit, end, shaken):
        """The state at the segment's end; the fit, the end's linearisation and whether the
        ripple needed following carried to the next segment."""
        model, x, mu = self.model, self.x, self.mu
        u1, v1 = osc.state(H)
        x1 = [u1, v1, z_end[0] - mu * u1, z_end[1] - mu * v1] + x[4:8] + z_end[2:]
        if self.d0 > 0.0:  # the support damper's loss d0 u0'^2, integrated exactly
            x1[model._damper_state] += self.d0 * osc.damping_loss(H) / (2.0 * osc.alpha)
        model._carried = (sol.t, cf.poly_shift(fit, H), end, shaken)
        return sol.t, x1, sol.status == 1
