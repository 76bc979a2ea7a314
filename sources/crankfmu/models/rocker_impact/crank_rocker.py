"""Crank-rocker hammer: a motor-driven crank swings RockerImpact's rocker through a spring rod,
or follows a driver that integrates the shaft (effect driven_crank).
Geometry, equations, why a compliant rod, variables and tests: crank_rocker.md in this folder.
"""
from __future__ import annotations

import math

import numpy as np

from ...runtime.model import Effect, IntegrationError, ParameterError, Variable
from ...runtime.driven_crank import SHAFT_INPUTS, SHAFT_NAMES, crank_from_shaft
from .rocker_impact import RockerImpact
from ...runtime.roots import brentq

def _with_driven(v: Variable) -> Variable:
    """RockerImpact's T and E_mech also depend on the rod force, so on the driven crank."""
    if v.name not in ("T", "E_mech"):
        return v
    return Variable(v.name, v.unit, v.description, v.start, v.min, v.max,
                    v.depends_on + SHAFT_NAMES)


_ROCKER_PARAMETERS = tuple(v for v in RockerImpact.parameters
                           if v.name not in ("strike_at_start", "theta_start", "w_start"))


class CrankRockerHammer(RockerImpact):
    model_name = "CrankRockerHammer"
    description = ("Crank-rocker hammer: motor-driven crank, spring rod, rocker striking an "
                   "elastic rod tool on an elastic pivot support")
    seed = "rocker_impact_unit.txt (rocker, contact, support); linkage: sources/crankfmu/models/rocker_impact/crank_rocker.md"

    parameters = _ROCKER_PARAMETERS + (
        Variable("crank_radius", "m", "Crank radius a", 0.04, min=0.0),
        Variable("arm_length", "m", "Distance pivot - rod eye b on the rocker", 0.15, min=0.0),
        Variable("arm_angle", "rad", "Angle of the rod eye from the pivot-strike line (pi: on "
                 "the far side of the pivot)", math.pi),
        Variable("crank_x", "m", "Crank centre A along the tool axis, from the pivot", -0.60),
        Variable("crank_y", "m", "Crank centre A across the tool axis, from the pivot", 0.15),
        Variable("rod_length", "m", "Free length L0 of the rod; 0: the length at the strike "
                 "position (theta = 0) with the crank at its outer dead centre", 0.0, min=0.0),
        Variable("k_rod", "N/m", "Rod (spring) stiffness", 6.0e4, min=0.0),
        Variable("c_rod", "N.s/m", "Rod damping", 0.0, min=0.0),
        Variable("J_crank", "kg.m2", "Crank inertia about its axis", 0.5, min=0.0),
        Variable("gear_ratio", "1", "Motor speed / crank speed", 5.0, min=0.0),
        Variable("phi_start", "rad", "Crank angle at the start (0: inner dead centre); the "
                 "rocker starts at rest with the rod at its free length", 0.0),
        Variable("support_damping", "N.s/m", "Viscous damping of the elastic pivot support "
                 "(0: the paper's undamped support)", 0.0, min=0.0),
    )
    effects = RockerImpact.effects + (
        Effect("driven_crank", "No crank states: the crank follows shaft_phi/shaft_w of a "
               "rigidly coupled driver, which takes shaft_tau and shaft_J (rigid coupling, "
               "docs/ports.md)"),
    )
    inputs = (
        Variable("flange_tau", "N.m", "Motor torque on the motor shaft (crank side of the gear)",
                 0.0),
        Variable("flange_J", "kg.m2", "Inertia rigidly on the motor shaft (rotor, flywheel)",
                 0.0, min=0.0),
    ) + SHAFT_INPUTS
    _driven = SHAFT_NAMES  # feedthrough with effect driven_crank only
    outputs = (
        Variable("flange_w", "rad/s", "Motor shaft speed i phi'", depends_on=_driven),
        Variable("flange_phi", "rad", "Motor shaft angle i phi", depends_on=_driven),
        Variable("phi", "rad", "Crank angle", depends_on=_driven),
        Variable("w_crank", "rad/s", "Crank speed", depends_on=_driven),
        Variable("theta", "rad", "Rocker angle from the strike position"),
        Variable("omega", "rad/s", "Rocker angular speed"),
        Variable("F_rod", "N", "Rod force (tension > 0)", depends_on=_driven),
        Variable("M_load", "N.m", "Load torque of the rod on the motor shaft, -M_rod/i",
                 depends_on=_driven),
        Variable("W_drive", "J", "Work of the motor torque, cumulative (driven_crank: work of "
                 "the crank on the rod)"),
        Variable("E_damped", "J", "Energy dissipated in the rod and support dampers, cumulative"),
        Variable("shaft_tau", "N.m", "Torque of the hammer on its input shaft apart from the "
                 "crank's inertia, M_rod/i (for a rigidly coupled driver)", depends_on=_driven),
        Variable("shaft_J", "kg.m2", "Inertia at the input shaft J_crank/i^2 + flange_J (for a "
                 "rigidly coupled driver)", depends_on=("flange_J",)),
    ) + tuple(_with_driven(v) for v in RockerImpact.outputs
              if v.name not in ("flange_w", "flange_phi"))

    def __init__(self, parameters=None, effects=None):
        super().__init__(parameters, effects)
        p = self.p
        self._driven = self.on("driven_crank")
        self._i2 = p.gear_ratio ** 2
        self._support_damping = p.support_damping
        self._damper_state = -1  # E_damped, the last state
        self._L0 = self.free_length

    def _check_geometry(self, p):
        for name in ("crank_radius", "arm_length", "gear_ratio"):
            if getattr(p, name) <= 0.0:
                raise ParameterError(self.model_name, name, getattr(p, name), "> 0")
        if p.k_rod <= 0.0:
            raise ParameterError(self.model_name, "k_rod", p.k_rod, "> 0 N/m")
        if math.hypot(p.crank_x, p.crank_y) <= p.crank_radius + p.arm_length:
            raise ParameterError(self.model_name, "crank_x", p.crank_x,
                                 "a crank centre farther from the pivot than crank_radius + "
                                 "arm_length (the crank would sweep through the rocker)")

    def check(self, p):
        self._check_rocker(p, needs_V0=True)
        self._check_geometry(p)

    # -- geometry -----------------------------------------------------------------------------
    @property
    def gap(self) -> float:
        return self.p.tool_gap

    def _eye(self, u0: float, th: float) -> tuple[float, float]:
        """The rod eye B for the support at u0 and the rocker at th."""
        b, ang = self.p.arm_length, th + self.p.arm_angle
        return u0 + b * math.sin(ang), -b * math.cos(ang)

    def _pin(self, phi: float) -> tuple[float, float]:
        """The crank pin Q at the crank angle phi."""
        p = self.p
        a = p.crank_radius
        return p.crank_x + a * math.cos(phi), p.crank_y + a * math.sin(phi)

    def _rod_length(self, u0: float, th: float, phi: float) -> float:
        (Bx, By), (Qx, Qy) = self._eye(u0, th), self._pin(phi)
        return math.hypot(Qx - Bx, Qy - By)

    @property
    def free_length(self) -> float:
        if self.p.rod_length > 0.0:
            return self.p.rod_length
        return self._rod_length(0.0, 0.0, math.pi)

    def crank_motion(self, x, u) -> tuple[float, float]:
        """(phi, phi'): the crank states, or with driven_crank the driver's shaft over the gear."""
        if self._driven:
            return crank_from_shaft(self, u)
        return x[-4], x[-3]

    def rod(self, u0, v0, th, om, phi, w):
        """(F_rod, torque on the rocker about O, force on the rocker along x, torque on the
        crank, rod stretch l - L0, rate l') for the support (u0, v0), the rocker (th, om) and
        the crank (phi, w)."""
        p = self.p
        a, b = p.crank_radius, p.arm_length
        ang = th + p.arm_angle
        sin_a, cos_a = math.sin(ang), math.cos(ang)
        sin_p, cos_p = math.sin(phi), math.cos(phi)
        rBx, rBy = b * sin_a, -b * cos_a                  # B - O
        rQx, rQy = a * cos_p, a * sin_p                   # Q - A
        dx, dy = p.crank_x + rQx - u0 - rBx, p.crank_y + rQy - rBy
        ell = math.hypot(dx, dy)
        ex, ey = dx / ell, dy / ell
        # l' = e . (Q' - B'), B' = (v0 + b om cos, b om sin), Q' = a w (-sin, cos)
        rate = ex * (-a * w * sin_p - v0 - b * om * cos_a) + ey * (a * w * cos_p - b * om * sin_a)
        stretch = ell - self._L0
        F = p.k_rod * stretch + p.c_rod * rate
        return (F, F * (rBx * ey - rBy * ex), F * ex, -F * (rQx * ey - rQy * ex), stretch, rate)

    def kinematic_theta(self, phi: float) -> float:
        """Rocker angle with the rod at its free length (pivot at rest), on the branch
        -pi/2 < theta <= small (the rocker hangs toward the tool side of its swing)."""
        L0 = self.free_length

        def f(th):
            return self._rod_length(0.0, th, phi) - L0
        lo, hi = -math.pi / 2, 0.5
        if f(lo) * f(hi) > 0.0:
            raise ParameterError(self.model_name, "phi_start", self.p.phi_start,
                                 "an angle at which the rod (free length) reaches the rocker arm")
        return brentq(f, lo, hi, xtol=1e-15)

    # -- contract -------------------------------------------------------------------------------
    def state_names(self):
        crank = () if self._driven else ("phi", "w_crank")
        return super().state_names() + crank + ("W_drive", "E_damped")

    def state_nominal(self) -> np.ndarray:
        crank: list[float] = [] if self._driven else [1.0, 30.0]
        return np.concatenate([super().state_nominal(), crank + [1e3, 1e3]])

    def initial_state(self, u):
        p = self.p
        c, c0 = self.stiffnesses(0.0)        # the rocker alone strikes: its own J
        theta = self.kinematic_theta(p.phi_start)
        if p.S * theta - self.gap > 0.0:
            raise ParameterError(self.model_name, "tool_gap", p.tool_gap,
                                 f">= S theta_start = {p.S * theta:.6g} m (the rocker may not "
                                 f"start inside the tool)")
        crank = [] if self._driven else [p.phi_start, 0.0]
        x = (([0.0, 0.0] if self._compliant else []) +
             [theta, 0.0, 0.0, 0.0, 0.0, 0.0] + crank + [0.0, 0.0])
        self._d = self._fresh_discrete(c, c0, False)
        self._use_stiffnesses()
        self._carried = None
        return x

    def _crank_inertia(self, u) -> float:
        return self.p.J_crank + self._i2 * u[self.IN.flange_J]

    def shaft_load(self, x, u) -> tuple[float, float]:
        """(shaft_tau, shaft_J) at the input shaft: M_rod/i and J_cr/i^2."""
        i = self.p.gear_ratio
        o = self._theta
        u0, v0 = self._support(x)
        phi, w = self.crank_motion(x, u)
        return self.rod(u0, v0, x[o], x[o + 1], phi, w)[3] / i, self._crank_inertia(u) / (i * i)

    def _rocker_inertia(self, u) -> float:
        return self.p.J  # the motor's inertia is on the crank, not the rocker

    def _crank(self, tail, u) -> tuple[float, float]:
        """(phi, phi') from the states after the rocker's, or from the driver's shaft."""
        return crank_from_shaft(self, u) if self._driven else (tail[0], tail[1])

    def _pull(self, t, u0, v0, th, om, tail, u):
        phi, w = self._crank(tail, u)
        _, M_rocker, F_axis, _, _, _ = self.rod(u0, v0, th, om, phi, w)
        return M_rocker, F_axis

    def _load(self, t, u0, v0, th, om, tail, u, support_power):
        """The rod's pull on the rocker, and the crank's and the energies' rates."""
        p = self.p
        phi, w = self._crank(tail, u)
        _, M_rocker, F_axis, M_crank, _, rate = self.rod(u0, v0, th, om, phi, w)
        loss = p.c_rod * rate * rate + support_power
        if self._driven:  # the driver integrates the crank; W_drive: the crank's work on the rod
            return M_rocker, F_axis, p.J, [-M_crank * w, loss]
        drive = p.gear_ratio * u[self.IN.flange_tau]
        J_crank = self._crank_inertia(u)
        if J_crank == 0.0:
            raise IntegrationError(f"{self.model_name}: no inertia on the crank shaft (J_crank = "
                                   f"0 and flange_J = 0): the crank's acceleration is not finite")
        return M_rocker, F_axis, p.J, [w, (drive + M_crank) / J_crank, drive * w, loss]

    def mechanical_energy(self, x, u) -> float:
        """Rocker (own J) and support, contact, crank + motor kinetic energy, rod spring
        (driven_crank: without the crank's kinetic energy, which the driver carries)."""
        o = self._theta
        u0, v0 = self._support(x)
        phi, w = self.crank_motion(x, u)
        stretch = self.rod(u0, v0, x[o], x[o + 1], phi, w)[4]
        return self._rocker_energy(x, self.p.J) + self._linkage_energy(x, u, stretch)

    def _linkage_energy(self, x, u, stretch: float) -> float:
        """Crank + motor kinetic energy (none with driven_crank) and the rod's spring energy."""
        crank = 0.0
        if not self._driven:
            w = x[-3]
            crank = 0.5 * self._crank_inertia(u) * w * w
        return crank + 0.5 * self.p.k_rod * stretch ** 2

    def monitor_functions(self, u_of_t):
        """P' = 0 as in RockerImpact; with the elastic support T' = k(u0) u0' + d0 u0'' = 0,
        k = dT/du0 of the bearing's spring."""
        monitors = super().monitor_functions(u_of_t)
        if not (self._d["contact"] and self._compliant and self._support_damping > 0.0):
            return monitors
        o, d0 = self._theta, self._support_damping

        def t_extremum(t, x):
            u0, v0 = x[0], x[1]
            torque, F_axis = self._pull(t, u0, v0, x[o], x[o + 1], x[o + 6:], u_of_t(t))
            ddu = self._accelerations(u0, v0, self._force(x), torque, self.p.J, F_axis)[0]
            return self.spring_rate(u0) * v0 + d0 * ddu
        t_extremum.terminal, t_extremum.direction = False, 0.0
        return [monitors[0], t_extremum]

    def _output_dict(self, t, x, u) -> dict:
        p = self.p
        o = self._theta
        u0, v0 = self._support(x)
        th, om = x[o], x[o + 1]
        phi, w = self.crank_motion(x, u)
        F, M_rocker, F_axis, M_crank, stretch, _ = self.rod(u0, v0, th, om, phi, w)
        out = self._rocker_outputs(x, M_rocker, F_axis, p.J)
        i = p.gear_ratio
        out.update(flange_w=i * w, flange_phi=i * phi, phi=phi, w_crank=w, theta=th, omega=om,
                   F_rod=F, M_load=-M_crank / i, W_drive=x[-2], E_damped=x[-1],
                   shaft_tau=M_crank / i, shaft_J=self._crank_inertia(u) / (i * i),
                   E_mech=out["E_mech"] + self._linkage_energy(x, u, stretch))
        return out
