"""Cold pipe rolling mill stand drive: twin crank-slider with assembly preload, pin friction and
rolling load (seed mill_stand_drive_structure; MODELS.md section 5).
Kinematics, reduced dynamics, preload, friction, variables and tests: README.md in this folder.
"""
from __future__ import annotations


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

    # -- kinematics -----------------------------------------------------------------------
    def kinematics(self, phi):
        """(x, x', x'', beta, beta') for scalar or array phi (' = d/dphi)."""
        r, l = self.p.r, self.p.l
        s, c = np.sin(phi), np.cos(phi)
        R = np.sqrt(l * l - (r * s) ** 2)
        x = r * c + R
        dx = -r * s - r * r * s * c / R
        ddx = -r * c - r * r * np.cos(2 * phi) / R - r ** 4 * s * s * c * c / R ** 3
        beta = np.arcsin(r * s / l)
        dbeta = r * c / R
        return x, dx, ddx, beta, dbeta

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

    def friction_torque(self, phi, w):
        """M_f at the crank from the preload in the four pins (resisting, sign of -w)."""
        P = abs(self.preload())
        if P == 0.0 or self.p.mu_joint == 0.0:
            return 0.0 * np.asarray(phi, dtype=float)
        dbeta = self.kinematics(phi)[4]
        lever = (1.0 + dbeta) + np.abs(dbeta)
        return -2.0 * self.p.mu_joint * self.p.r_pin * P * lever * np.tanh(w / self.p.w_reg)

    def load_force(self, phi, w):
        if not self.on("rolling_load"):
            return 0.0 * np.asarray(phi, dtype=float)
        v = self.kinematics(phi)[1] * w
        return -self.p.F_roll * np.tanh(v / self.p.v_reg)

    def reduced_inertia(self, phi, J_input: float):
        p = self.p
        _, dx, ddx, _, _ = self.kinematics(phi)
        J = p.gear_ratio ** 2 * J_input + p.J_crank + p.m_stand * dx * dx
        return J, p.m_stand * dx * ddx

    def crank_acceleration(self, phi, w, u):
        J, half_dJ = self.reduced_inertia(phi, u[self.IN.flange_J])
        dx = self.kinematics(phi)[1]
        M = (self.p.gear_ratio * u[self.IN.flange_tau] + self.friction_torque(phi, w)
             + dx * self.load_force(phi, w) - half_dJ * w * w)
        return M / J

    def rod_forces(self, phi, w, u):
        """(T2, T4, a): rod tensions and stand acceleration."""
        x, dx, ddx, beta, _ = self.kinematics(phi)
        a = ddx * w * w + dx * self.crank_acceleration(phi, w, u)
        T = (self.load_force(phi, w) - self.p.m_stand * a) / np.cos(beta)
        if self.redundant_rod_length():
            l2, l4 = self.rod_lengths()
            P = self.preload()
            return T * l4 / (l2 + l4) - P, T * l2 / (l2 + l4) + P, a
        return 0.5 * T, 0.5 * T, a

    def shaft_load(self, phi, w, J_input: float = 0.0) -> tuple[float, float]:
        """(shaft_tau, shaft_J) at the input shaft for crank angle phi and speed w = phi'."""
        i = self.p.gear_ratio
        J, half_dJ = self.reduced_inertia(phi, J_input)
        dx = self.kinematics(phi)[1]
        M = self.friction_torque(phi, w) + dx * self.load_force(phi, w) - half_dJ * w * w
        return float(M) / i, float(J) / (i * i)

    def crank_motion(self, x, u) -> tuple[float, float]:
        """(phi, phi'): the states, or with driven_crank the driver's shaft over the gear."""
        if self.on("driven_crank"):
            return crank_from_shaft(self, u)
        return x[0], x[1]

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
        return np.array(crank + [0.0] * (len(self.state_names()) - len(crank)), dtype=float)

    def derivatives(self, t, x, u):
        phi, w = self.crank_motion(x, u)
        out = [] if self.on("driven_crank") else [w, self.crank_acceleration(phi, w, u)]
        if self.on("assembly_preload"):
            out.append(-self.friction_torque(phi, w) * w)
        if self.on("rolling_load"):
            out.append(-self.load_force(phi, w) * self.kinematics(phi)[1] * w)
        return np.array(out, dtype=float)

    def output_values(self, t, x, u):
        phi, w = self.crank_motion(x, u)
        names = self.state_names()
        i = self.p.gear_ratio
        xs, dx, _, _, _ = self.kinematics(phi)
        T2, T4, a = (0.0, 0.0, 0.0) if self.on("driven_crank") else self.rod_forces(phi, w, u)
        M_f = self.friction_torque(phi, w)
        J, _ = self.reduced_inertia(phi, u[self.IN.flange_J])
        E_f = x[names.index("E_friction")] if "E_friction" in names else 0.0
        E_l = x[names.index("E_load")] if "E_load" in names else 0.0
        v = self.variant
        q_rank = (Q_RANK_GUIDED if self.p.guides_hold_skew == 1.0 else Q_RANK_FREE_SKEW)[v]
        shaft_tau, shaft_J = self.shaft_load(phi, w, u[self.IN.flange_J])
        return np.array(self.output_vector(dict(
            flange_w=i * w, flange_phi=i * phi, phi=phi, w_crank=w, stand_x=xs, stand_v=dx * w,
            stand_a=a, F_rod2=T2, F_rod4=T4, preload=self.preload(), stand_skew=self.stand_skew(),
            M_friction=M_f, P_friction=-M_f * w, E_friction=E_f, F_load=self.load_force(phi, w),
            E_load=E_l, J_reduced=J, W_mobility=W_SEED[v], q_malyshev=Q_SEED[v], q_rank=q_rank,
            shaft_tau=shaft_tau, shaft_J=shaft_J)), dtype=float)
