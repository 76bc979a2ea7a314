"""Monolithic RIGID reference for the clutch scenes (induction motor + planetary clutch drive +
a mechanism whose crank shaft is rigidly the carrier's): scenarios/clutch_hammer.toml and
scenarios/clutch_mill_stand.toml. One ODE, solved with scipy (DOP853) at rtol 1e-11.

Independent of the mechanisms' driven_crank mode: the mechanism is built in its own,
INTEGRATING mode (crank states phi, w_crank), and the rigid shaft's load is read from that
mode's public contract, with the crank states taken from the carrier, phi = phi_start + phi_h/i,
phi' = w_h/i, and no drive torque (flange_tau = flange_J = 0):

    crank equation of the integrating mode   J_cr(phi) phi'' = i flange_tau + M(phi, phi', ...)
    so with flange_tau = 0                   M = J_cr(phi) * derivatives(...)[w_crank]
    the carrier then carries                 flange_tau = M/i,  flange_J = J_cr(phi)/i^2

(J_cr: the hammer's J_crank; the stand's reduced_inertia(phi, 0)). The mechanism's other states
(rocker, contact, support, energy integrals) take their derivatives from the same call; the work
of the crank on the mechanism, W_drive of driven_crank, is -M phi'. Every input (motor torque,
flange_tau, flange_J) is evaluated from the CURRENT state at every right-hand-side and
event-function call, so the carrier, the shaft and the crank are one rigid body: the rigid
system's Lagrange equation with no communication step. Events: the drive's (locks, break-frees,
command edges) and the hammer's contact begin/end, located by solve_ivp; the command table is
applied at its switching times (integration restarted there, as the drive's on_input_change
does).
"""
from __future__ import annotations

import tomllib

import numpy as np

from crankfmu.runtime.model import PhysicsModel
from crankfmu.models.rocker_impact.crank_rocker import CrankRockerHammer
from crankfmu.models.induction_motor.induction_motor import InductionMotor
from crankfmu.models.mill_stand.mill_stand import MillStandDrive
from crankfmu.models.planetary_drive.planetary_drive import X as DRIVE_STATE
from crankfmu.models.planetary_drive.planetary_drive import PlanetaryClutchDrive
from crankfmu.system.load import load_scene

N_DRIVE = 9  # the drive's states come first
NO_DRIVE = np.array([0.0, 0.0])  # flange_tau, flange_J of the integrating mechanism


class RigidClutch(PhysicsModel):
    """drive + mechanism as one ODE; state = drive states + mechanism states without the crank
    (the crank's two states in the mechanism's vector are filled from the carrier)."""

    solver = "scipy"
    integrator = "DOP853"
    max_events_per_step = 10000

    def __init__(self, drive: PlanetaryClutchDrive, motor: InductionMotor, mech: PhysicsModel):
        super().__init__()
        self.drive, self.motor, self.mech = drive, motor, mech
        names = mech.state_names()
        self.i_phi, self.i_w = names.index("phi"), names.index("w_crank")
        self.keep = [k for k in range(len(names)) if k not in (self.i_phi, self.i_w)]
        self.command = 0.0
        self._kinds = []

    # -- the rigid shaft ------------------------------------------------------------------------
    def crank(self, X):
        i = self.mech.p.gear_ratio
        return self.mech.p.phi_start + X[DRIVE_STATE.phi_h] / i, X[DRIVE_STATE.w_h] / i

    def mech_state(self, X) -> np.ndarray:
        x = np.zeros(len(self.mech.state_names()))
        x[self.keep] = X[N_DRIVE:]
        x[self.i_phi], x[self.i_w] = self.crank(X)
        return x

    def crank_inertia(self, phi) -> float:
        if isinstance(self.mech, MillStandDrive):
            return float(self.mech.reduced_inertia(phi, 0.0)[0])
        return self.mech.p.J_crank

    def mech_terms(self, t, X):
        """(mechanism derivatives without the crank's, M at the crank, J_cr at the crank)."""
        x = self.mech_state(X)
        dx = np.asarray(self.mech.derivatives(t, x, NO_DRIVE), dtype=float)
        J = self.crank_inertia(x[self.i_phi])
        return dx, J * dx[self.i_w], J

    def drive_inputs(self, t, X, terms=None) -> np.ndarray:
        """The drive's inputs at state X (terms: mech_terms(t, X) if already at hand)."""
        _, M, J = terms or self.mech_terms(t, X)
        i = self.mech.p.gear_ratio
        w_a = self.drive.sun_speed(X[:N_DRIVE])
        return np.array([self.command, self.motor.torque(w_a), self.motor.J_shaft, M / i,
                         J / (i * i)])

    # -- contract -------------------------------------------------------------------------------
    def state_names(self):
        mech = self.mech.state_names()
        return self.drive.state_names() + tuple(mech[k] for k in self.keep)

    def state_nominal(self):
        return np.concatenate([self.drive.state_nominal(),
                               np.asarray(self.mech.state_nominal())[self.keep]])

    def initial_state(self):
        xd = self.drive.initial_state(np.zeros(5))
        xm = np.asarray(self.mech.initial_state(NO_DRIVE), dtype=float)
        X = np.concatenate([xd, xm[self.keep]])
        return np.concatenate([self.drive.initial_state(self.drive_inputs(0.0, X)), xm[self.keep]])

    def derivatives(self, t, X, u=None):
        terms = self.mech_terms(t, X)  # once: the drive's inputs are made of them too
        dx, M, _ = terms
        dd = self.drive.derivatives(t, X[:N_DRIVE], self.drive_inputs(t, X, terms))
        dm = dx[self.keep]
        names = [self.mech.state_names()[k] for k in self.keep]
        if "W_drive" in names:  # the crank's work on the rod, as driven_crank defines it
            dm[names.index("W_drive")] = -M * self.crank(X)[1]
        return np.concatenate([dd, dm])

    def event_functions(self, u_of_t):
        held = {}
        drive_events = self.drive.event_functions(lambda s: held["u"])
        mech_events = self.mech.event_functions(lambda s: NO_DRIVE)
        self._kinds = [("drive", k) for k in range(len(drive_events))] + \
            [("mech", k) for k in range(len(mech_events))]
        wrapped = []
        for g in drive_events:
            def wd(t, X, g=g):
                held["u"] = self.drive_inputs(t, X)
                return g(t, X[:N_DRIVE])
            wd.terminal, wd.direction = g.terminal, g.direction
            wrapped.append(wd)
        for g in mech_events:
            def wm(t, X, g=g):
                return g(t, self.mech_state(X))
            wm.terminal, wm.direction = g.terminal, g.direction
            wrapped.append(wm)
        return wrapped

    def on_event(self, t, X, u, index):
        X = np.array(X, dtype=float)
        part, k = self._kinds[index]
        if part == "drive":
            X[:N_DRIVE] = self.drive.on_event(t, X[:N_DRIVE], self.drive_inputs(t, X), k)
        else:
            X[N_DRIVE:] = np.asarray(self.mech.on_event(t, self.mech_state(X), NO_DRIVE,
                                                        k))[self.keep]
        return X

    def output_values(self, t, X, u=None) -> dict:
        """The drive's and the mechanism's outputs by name (inputs from the state)."""
        du = self.drive_inputs(t, X)
        x = self.mech_state(X)
        out = {"drive." + v.name: y for v, y in
               zip(self.drive.outputs, self.drive.output_values(t, X[:N_DRIVE], du))}
        out.update({"mech." + v.name: y for v, y in
                    zip(self.mech.outputs, self.mech.output_values(t, x, NO_DRIVE))})
        out["motor.flange_tau"] = du[1]
        names = [self.mech.state_names()[k] for k in self.keep]
        if "W_drive" in names:
            out["mech.W_drive"] = X[N_DRIVE + names.index("W_drive")]
        return out


def from_scene(path, mech_name: str):
    """(model, command table rows) from the scene file's parameters; the mechanism built
    without driven_crank (its integrating mode)."""
    scene = load_scene(path)
    comp = scene.components
    motor = InductionMotor(comp["motor"].parameters, comp["motor"].effects)
    drive = PlanetaryClutchDrive(comp["drive"].parameters, comp["drive"].effects)
    cls = {"CrankRockerHammer": CrankRockerHammer, "MillStandDrive": MillStandDrive}
    mc = comp[mech_name]
    mech = cls[mc.fmu](mc.parameters, [e for e in mc.effects if e != "driven_crank"])
    table = tomllib.loads(scene.path.read_text())["inputs"]["drive.command"]["table"]
    return RigidClutch(drive, motor, mech), table


def run(path, mech_name: str, t_end: float, names, dt: float = 1e-3, rtol: float = 1e-11):
    """Samples every dt to t_end: dict name -> array for `names` (drive.*, mech.*,
    motor.flange_tau) and time. A process solves each (scene, mechanism, dt, rtol) once, as far
    as it has been asked for (test_clutch_hammer.py and test_adaptive_edges.py ask for 1.6 and
    1.16 s of the clutch hammer: tests/conftest.py runs them on one worker)."""
    key = (str(path), mech_name, dt, rtol)
    if key not in _SOLVED:
        _SOLVED[key] = _Solution(path, mech_name, dt, rtol)
    return _SOLVED[key].samples(int(round(t_end / dt)), names)


CHUNK = 100  # samples integrated in one go (switches of the command table end a chunk early)


class _Solution:
    """The reference from t = 0, extended on demand a whole chunk at a time: integrated from a
    chunk's first sample to its last in one go (restarted only at events), the samples in
    between read from DOP853's dense output of the integration they fall in; a chunk ends at
    every switch of the command table. Chunks are integrated whole whatever was asked, so
    samples 0..n are the same numbers however far it went on. (Restarting at every sample, the
    clutch hammer's 1.6 s took 1600 solve_ivp calls, 0.99 s of CPU against 0.24 s now; the
    clutch mill stand's 1.9 s 1.10 s against 0.24 s.)"""

    def __init__(self, path, mech_name: str, dt: float, rtol: float):
        self.model, table = from_scene(path, mech_name)
        self.switches = {round(t / dt): v for t, v in table}
        self.dt, self.rtol = dt, rtol
        self.X = self.model.initial_state()
        self.atol = rtol * self.model.state_nominal()
        self.rows: list[dict] = []  # outputs at sample k

    def samples(self, n: int, names) -> dict:
        if not self.rows:
            self._at_sample(0)
        while len(self.rows) <= n:
            k0 = len(self.rows) - 1
            self._chunk(k0, min([k0 + CHUNK, *(k for k in self.switches if k > k0)]))
        rows = self.rows[:n + 1]
        return {"time": np.arange(n + 1) * self.dt} | {
            name: np.array([row[name] for row in rows], dtype=float) for name in names}

    def _at_sample(self, k: int) -> None:
        """At sample k, the state in self.X: the command's switch there, then the outputs."""
        model, t = self.model, k * self.dt
        if k in self.switches:
            model.command = float(self.switches[k])
            self.X[:N_DRIVE] = model.drive.on_input_change(
                t, self.X[:N_DRIVE], model.drive_inputs(t, self.X))
        self.rows.append(dict(model.output_values(t, self.X)))

    def _chunk(self, k0: int, k1: int) -> None:
        """Samples k0 + 1 .. k1 from the state at sample k0 (as PhysicsModel.advance: a sample
        at an event's time has the state after the event)."""
        model, dt = self.model, self.dt
        u = lambda s: (0.0,)  # noqa: E731 - the rigid system has no input
        t, x, t_end, k = k0 * dt, list(self.X), k1 * dt, k0 + 1
        for _ in range(model.max_events_per_step):
            model.restart_state = x
            dense: list = []
            sol = model.integrate(u, t, x, t_end, self.rtol, self.atol,
                                  model.event_functions(u), interpolant=dense)
            t_stop = t_end if sol.status == 0 else sol.t
            while k < k1 and k * dt < t_stop:  # in this integration's span, in this mode
                state = np.asarray(dense[0](k * dt), dtype=float)
                self.rows.append(dict(model.output_values(k * dt, state)))
                k += 1
            if sol.status == 0:
                x = sol.x
                break
            t, x = sol.t, model.on_event(sol.t, sol.x, u(sol.t), sol.event)
            if t >= t_end:
                break
        else:
            raise RuntimeError(f"more than {model.max_events_per_step} events before "
                               f"t = {t_end:.9g} s")
        self.X = np.asarray(x, dtype=float)
        self._at_sample(k1)


_SOLVED: dict[tuple, _Solution] = {}
