"""Cold pipe rolling mill stand drive: twin crank-slider with assembly preload, pin friction and
rolling load (seed mill_stand_drive_structure).
Kinematics, reduced dynamics, preload, friction, variables and tests: README.md in this folder.
"""
from __future__ import annotations

import math

import numpy as np

from ...runtime.model import Effect, ParameterError, PhysicsModel, Variable
from ...runtime.driven_crank import SHAFT_INPUTS, SHAFT_NAMES, crank_from_shaft

# seed's structure table (W counts the local mobilities) and the rank count of the shipped
# coaxial drives (scenarios/mechanisms/stand_drive_*_coaxial.toml, *_guided.toml);
# tests/test_mill_stand.py checks these against crankfmu.studies.structure.
VARIANT_NAMES = ("all revolute (p1)", "p3 at A, H and p2 at C, F", "p4 at A, H")
W_SEED = (2, 5, 5)
Q_SEED = (3, 0, 0)
Q_RANK_FREE_SKEW = (4, 0, 0)
Q_RANK_GUIDED = (7, 1, 1)


class MillStandDrive(PhysicsModel):
    model_name = "MillStandDrive"
    description = ("Cold pipe rolling mill stand drive: twin crank-slider with rigid or "
                   "self-aligning joints, assembly preload and its friction")
    seed = "mill_stand_drive_structure.txt (structure table, fig. 1-3)"
    integrator = "DOP853"

    parameters = (
        Variable("r", "m", "Crank radius (both crank gears)", 0.25, min=0.0),
        Variable("l", "m", "Nominal rod length l = (l2 + l4)/2, pin centre to pin centre", 1.2,
                 min=0.0),
        Variable("m_stand", "kg", "Stand mass (rod masses lumped into it)", 8000.0, min=0.0),
        Variable("J_crank", "kg.m2", "Inertia of the crank shaft with both crank gears", 600.0,
                 min=0.0),
        Variable("gear_ratio", "1", "Gear ratio i = motor speed / crank speed", 10.0, min=0.0),
        Variable("joint_variant", "1", "Joints: 0 all revolute (q = 3), 1 self-aligning p3 at "
                 "A, H and p2 at C, F, 2 self-aligning p4 at A, H (q = 0)", 0.0, min=0.0,
                 max=2.0),
        Variable("rod_mismatch", "m", "Rod length error d = l2 - l4 (rod 2 minus rod 4)", 0.0),
        Variable("rod_area", "m2", "Rod cross-section area A", 0.008, min=0.0),
        Variable("E_rod", "Pa", "Young's modulus of the rods", 2.1e11, min=0.0),
        Variable("mu_joint", "1", "Friction coefficient in the pins A, C, F, H", 0.08, min=0.0),
        Variable("r_pin", "m", "Pin (journal) radius of A, C, F, H", 0.09, min=0.0),
        Variable("rod_spacing", "m", "Distance 2b between the two rods along the crank shaft",
                 1.0, min=0.0),
        Variable("guides_hold_skew", "1", "1 if the stand guides hold the stand's skew (then "
                 "the rod-length constraint stays redundant in every variant), 0 as in the seed",
                 0.0, min=0.0, max=1.0),
        Variable("F_roll", "N", "Rolling force against the stand motion (effect rolling_load)",
                 150e3, min=0.0),
        Variable("w_reg", "rad/s", "Crank speed scale of the friction sign regularisation",
                 0.01, min=0.0),
        Variable("v_reg", "m/s", "Stand speed scale of the rolling load sign regularisation",
                 0.001, min=0.0),
        Variable("phi_start", "rad", "Crank angle at the start time (0: stand at the far end)",
                 0.0),
        Variable("w_start", "rad/s", "Crank angular velocity at the start time", 0.0),
    )
    effects = (
        Effect("assembly_preload", "Preload from the rod length error where the joints are "
               "redundant, and the pin friction it causes"),
        Effect("rolling_load", "Constant rolling force F_roll against the stand velocity"),
        Effect("driven_crank", "No crank states: the crank follows shaft_phi/shaft_w of a "
               "rigidly coupled driver, which takes shaft_tau and shaft_J (rigid coupling, "
               "docs/ports.md)"),
    )
    inputs = (
        Variable("flange_tau", "N.m", "Drive torque M_D on the motor shaft", 0.0),
        Variable("flange_J", "kg.m2", "Inertia rigidly on the motor shaft (J_input)", 0.0,
                 min=0.0),
    ) + SHAFT_INPUTS
    _ff = ("flange_tau", "flange_J")
    _driven = SHAFT_NAMES  # feedthrough with effect driven_crank only
    outputs = (
        Variable("flange_w", "rad/s", "Motor shaft angular velocity i*phi'", depends_on=_driven),
        Variable("flange_phi", "rad", "Motor shaft angle i*phi", depends_on=_driven),
        Variable("phi", "rad", "Crank angle (continuous, not wrapped)", depends_on=_driven),
        Variable("w_crank", "rad/s", "Crank angular velocity phi'", depends_on=_driven),
        Variable("stand_x", "m", "Stand position: crank axis to stand pins, l + r at phi = 0",
                 depends_on=_driven),
        Variable("stand_v", "m/s", "Stand velocity", depends_on=_driven),
        Variable("stand_a", "m/s2", "Stand acceleration (0 with driven_crank: the crank "
                 "acceleration is the driver's)", depends_on=_ff + _driven),
        Variable("F_rod2", "N", "Axial force in rod 2 (tension positive; 0 with driven_crank)",
                 depends_on=_ff + _driven),
        Variable("F_rod4", "N", "Axial force in rod 4 (tension positive; 0 with driven_crank)",
                 depends_on=_ff + _driven),
        Variable("preload", "N", "Assembly preload P (compression of rod 2, tension of rod 4)"),
        Variable("stand_skew", "rad", "Skew of the stand that takes up the rod length error "
                 "(self-aligning variants)"),
        Variable("M_friction", "N.m", "Pin friction torque from the preload, at the crank",
                 depends_on=_driven),
        Variable("P_friction", "W", "Friction loss power in the pins A, C, F, H",
                 depends_on=_driven),
        Variable("E_friction", "J", "Friction energy dissipated since the start"),
        Variable("F_load", "N", "Rolling force on the stand (along x)", depends_on=_driven),
        Variable("E_load", "J", "Work done against the rolling force since the start"),
        Variable("J_reduced", "kg.m2", "Reduced inertia J(phi) at the crank",
                 depends_on=("flange_J",) + _driven),
        Variable("W_mobility", "1", "Seed's mobility count W (main + local) of the variant"),
        Variable("q_malyshev", "1", "Seed's redundant constraints q (Malyshev/Ozol with W)"),
        Variable("q_rank", "1", "Redundant constraints of the coaxial drive by the Jacobian "
                 "rank (with the guides if guides_hold_skew)"),
        Variable("shaft_tau", "N.m", "Torque of the stand on its input shaft apart from inertia, "
                 "(M_f + x' F_load - m_s x' x'' phi'^2)/i (for a rigidly coupled driver)",
                 depends_on=_driven),
        Variable("shaft_J", "kg.m2", "Stand inertia at its input shaft J(phi)/i^2 (for a "
                 "rigidly coupled driver)", depends_on=("flange_J",) + _driven),
    )
    # the shaft's motion, i phi' and i phi: affine in the state (and in the driver's shaft)
    derivative_outputs = ("flange_w", "flange_phi")
    derivative_outputs_affine = True

    def check(self, p):
        name = self.model_name
        for key in ("r", "l", "rod_area", "E_rod", "gear_ratio", "J_crank", "w_reg", "v_reg",
                    "rod_spacing"):
            if getattr(p, key) <= 0.0:
                raise ParameterError(name, key, getattr(p, key), "> 0")
        if p.l <= p.r:
            raise ParameterError(name, "l", p.l, f"> r = {p.r} m (a rod shorter than the crank "
                                 "cannot assemble)")
        if p.joint_variant not in (0.0, 1.0, 2.0):
            raise ParameterError(name, "joint_variant", p.joint_variant,
                                 "0 (all revolute), 1 (p3 at A, H, p2 at C, F) or 2 (p4 at A, H)")
        if p.guides_hold_skew not in (0.0, 1.0):
            raise ParameterError(name, "guides_hold_skew", p.guides_hold_skew, "0 or 1")
        if abs(p.rod_mismatch) > 0.01 * p.l:
            raise ParameterError(name, "rod_mismatch", p.rod_mismatch,
                                 f"|d| <= 0.01 l = {0.01 * p.l:g} m (small elastic deformation)")
        if self.on("assembly_preload") and p.r_pin <= 0.0 and p.mu_joint > 0.0:
            raise ParameterError(name, "r_pin", p.r_pin, "> 0 when mu_joint > 0")

    def __init__(self, parameters=None, effects=None):
        super().__init__(parameters, effects)
        p = self.p
        # the effect switches and what the parameters fix, read in every right-hand-side call
        self._driven, self._rolling = self.on("driven_crank"), self.on("rolling_load")
        P = self.preload()
        # 2 mu r_pin |P|: the pin friction torque per unit lever (section 5); 0: no friction
        self._friction_scale = 2.0 * p.mu_joint * p.r_pin * abs(P)
        self._constants = (p.r, p.l, p.r * p.r, p.gear_ratio ** 2, p.J_crank, p.m_stand)
        # rod force shares of the total tension T and the preload on top (section 4)
        if self.redundant_rod_length():
            l2, l4 = self.rod_lengths()
            self._rod_shares = (l4 / (l2 + l4), l2 / (l2 + l4), P)
        else:
            self._rod_shares = (0.5, 0.5, P)
        names = self.state_names()
        self._energy_index = tuple(names.index(n) if n in names else None
                                   for n in ("E_friction", "E_load"))
        v = self.variant
        q_rank = (Q_RANK_GUIDED if p.guides_hold_skew == 1.0 else Q_RANK_FREE_SKEW)[v]
        # the outputs that are constant for a parameter set
        self._constant_outputs = (P, self.stand_skew(), W_SEED[v], Q_SEED[v], q_rank)

    # -- the equations: one scalar core -----------------------------------------------------
    # The right-hand side and the outputs call `crank_terms` on floats (math: ~20x cheaper than
    # numpy on one value); the public functions below reach the same core (kinematics and
    # reduced_inertia also over an array of phi, by np.vectorize: the analyses' grids), so each
    # equation is written once.
    def crank_terms(self, phi: float, w: float, J_input: float) -> tuple[float, ...]:
        """(J, J'/2, M_f, F_load, M_load, x, x', x'', beta, beta') at one crank state (phi,
        phi' = w): kinematics (README section 2), reduced inertia (3), pin friction (5), rolling
        load (6) and M_load = M_f + x' F_load - J'/2 phi'^2, the generalized force on the crank
        apart from the drive's: J phi'' = i M_D + M_load. One function, not one per quantity:
        the right-hand side calls it 7 times per step."""
        r, l, r2, i2_, J_crank, m_s = self._constants
        s, c = math.sin(phi), math.cos(phi)
        rs = r * s
        R = math.sqrt(l * l - rs * rs)
        q = r2 * s * c / R                              # -dR/dphi
        x = r * c + R
        dx = -rs - q
        ddx = -r * c - (r2 * (c - s) * (c + s) + q * q) / R  # r^2 cos 2phi: (c - s)(c + s)
        dbeta = r * c / R
        J = i2_ * J_input + J_crank + m_s * dx * dx
        half_dJ = m_s * dx * ddx
        M_f = F_load = 0.0
        if self._friction_scale:  # sgn(phi') regularised; the lever (1 + beta') + |beta'|
            M_f = -self._friction_scale * ((1.0 + dbeta) + abs(dbeta)) * \
                math.tanh(w / self.p.w_reg)
        if self._rolling:
            F_load = -self.p.F_roll * math.tanh(dx * w / self.p.v_reg)
        M_load = M_f + dx * F_load - half_dJ * w * w
        return J, half_dJ, M_f, F_load, M_load, x, dx, ddx, math.asin(rs / l), dbeta

    def _crank_acceleration(self, J: float, M_load: float, u) -> float:
        """phi'' = (i M_D + M_load)/J from the core's J and M_load: the reduced equation
        (section 3)."""
        return (self.p.gear_ratio * u[self.IN.flange_tau] + M_load) / J

    # -- the core for callers, and the rod forces --------------------------------------------
    def kinematics(self, phi):
        """(x, x', x'', beta, beta') for scalar or array phi (' = d/dphi)."""
        return _over(lambda a: self.crank_terms(a, 0.0, 0.0)[5:], phi, 5)

    def reduced_inertia(self, phi, J_input: float):
        """(J(phi), J'(phi)/2) at the crank."""
        return _over(lambda a: self.crank_terms(a, 0.0, J_input)[:2], phi, 2)

    def crank_acceleration(self, phi: float, w: float, u) -> float:
        """phi'' at crank angle phi and speed w = phi' for the input vector u."""
        terms = self.crank_terms(phi, w, u[self.IN.flange_J])
        return self._crank_acceleration(terms[0], terms[4], u)

    def rod_forces(self, a: float, F_load: float, beta: float) -> tuple[float, float]:
        """(T2, T4): rod tensions for stand acceleration a (section 4): T = (F_load - m_s a) /
        cos beta shared by the rods' stiffness (or equally, self-aligning), and the preload."""
        share2, share4, P = self._rod_shares
        T = (F_load - self.p.m_stand * a) / math.cos(beta)
        return T * share2 - P, T * share4 + P

    # -- preload --------------------------------------------------------------------------
    @property
    def variant(self) -> int:
        return int(self.p.joint_variant)

    def redundant_rod_length(self) -> bool:
        """True if the rod-length equality is a redundant constraint (preload can arise)."""
        return self.variant == 0 or self.p.guides_hold_skew == 1.0

    def rod_lengths(self):
        d = self.p.rod_mismatch
        return self.p.l + 0.5 * d, self.p.l - 0.5 * d

    def preload(self) -> float:
        """P = E A d/(l2 + l4) (the two rods in series around the loop), 0 if not redundant."""
        if not (self.on("assembly_preload") and self.redundant_rod_length()):
            return 0.0
        l2, l4 = self.rod_lengths()
        return self.p.E_rod * self.p.rod_area * self.p.rod_mismatch / (l2 + l4)

    def stand_skew(self) -> float:
        """Skew d/(2b) that takes up the rod length error when it is not redundant."""
        if self.redundant_rod_length():
            return 0.0
        return self.p.rod_mismatch / self.p.rod_spacing

    # -- contract -------------------------------------------------------------------------
    def state_names(self):
        names = [] if self.on("driven_crank") else ["phi", "w_crank"]
        if self.on("assembly_preload"):
            names.append("E_friction")
        if self.on("rolling_load"):
            names.append("E_load")
        return tuple(names)

    def initial_state(self, u):
        crank = [] if self.on("driven_crank") else [self.p.phi_start, self.p.w_start]
        return crank + [0.0] * (len(self.state_names()) - len(crank))

    def crank_motion(self, x, u) -> tuple[float, float]:
        """(phi, phi'): the states, or with driven_crank the driver's shaft over the gear."""
        if self._driven:
            return crank_from_shaft(self, u)
        return x[0], x[1]

    def derivatives(self, t, x, u):
        phi, w = self.crank_motion(x, u)
        J, _, M_f, F_load, M_load, _, dx, _, _, _ = self.crank_terms(phi, w, u[self.IN.flange_J])
        out = [] if self._driven else [w, self._crank_acceleration(J, M_load, u)]
        friction, load = self._energy_index
        if friction is not None:
            out.append(-M_f * w)
        if load is not None:
            out.append(-F_load * dx * w)
        return out

    def output_values(self, t, x, u):
        phi, w = self.crank_motion(x, u)
        i = self.p.gear_ratio
        J, _, M_f, F_load, M_load, xs, dx, ddx, beta, _ = self.crank_terms(
            phi, w, u[self.IN.flange_J])
        if self._driven:  # the crank acceleration is the driver's, not known here
            a = T2 = T4 = 0.0
        else:
            a = ddx * w * w + dx * self._crank_acceleration(J, M_load, u)
            T2, T4 = self.rod_forces(a, F_load, beta)
        friction, load = self._energy_index
        P, skew, W, q, q_rank = self._constant_outputs
        return self.output_vector(dict(
            flange_w=i * w, flange_phi=i * phi, phi=phi, w_crank=w, stand_x=xs, stand_v=dx * w,
            stand_a=a, F_rod2=T2, F_rod4=T4, preload=P, stand_skew=skew,
            M_friction=M_f, P_friction=-M_f * w,
            E_friction=0.0 if friction is None else x[friction], F_load=F_load,
            E_load=0.0 if load is None else x[load], J_reduced=J, W_mobility=W,
            q_malyshev=q, q_rank=q_rank, shaft_tau=M_load / i, shaft_J=J / (i * i)))


def _over(scalar_function, phi, n_out: int):
    """scalar_function at a scalar phi, or elementwise over an array (tuples of arrays)."""
    if isinstance(phi, (float, int)):
        return scalar_function(float(phi))
    return np.vectorize(scalar_function, otypes=[float] * n_out)(np.asarray(phi, dtype=float))
