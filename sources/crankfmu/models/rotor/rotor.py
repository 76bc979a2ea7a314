"""Linear test drive train: a rotor (torque in, speed out), and a rotor driven through a compliant
shaft (speed in, torque out). Their composition, the two-mass oscillator, has a closed-form
solution, so the masters' error and order are measured against it. Equations: README.md here."""
from __future__ import annotations

import numpy as np

from ...runtime.matrix_exponential import expm
from ...runtime.model import ParameterError, PhysicsModel, Variable, input_rows


class LinearModel(PhysicsModel):
    """x' = A x + B u; subclasses give `matrices()` -> (A, B). Outputs offered with derivative
    companions are affine in x and u (derivative_outputs_affine)."""

    derivative_outputs_affine = True

    def matrices(self) -> tuple[np.ndarray, np.ndarray]:
        raise NotImplementedError

    def derivatives(self, t, x, u):
        A, B = self.matrices()
        return A @ x + B @ u

    def jacobian(self, t, x, u):
        return self.matrices()[0]

    def state_rows(self, t, x, u_rows, order, delta, known=()):
        """Exact: x^(k+1) = A x^(k) + B u^(k)."""
        A, B = self.matrices()
        rows = [np.asarray(x, dtype=float)]
        for k in range(order):
            u_k = u_rows[k] if k < len(u_rows) else np.zeros(B.shape[1])
            rows.append(A @ rows[-1] + B @ np.asarray(u_k, dtype=float))
        return [r.tolist() for r in rows]

    def advance(self, t0, x0, h, u_of_t, rtol, atol):
        rows = input_rows(u_of_t, t0, h)
        if rows is None:  # not a polynomial in t: the numerical solver
            return super().advance(t0, x0, h, u_of_t, rtol, atol)
        z = self._transition(h, len(rows)) @ np.concatenate([x0, *rows])
        return z[:len(x0)].tolist()

    def _transition(self, h: float, rows: int = 3) -> np.ndarray:
        """expm(M h) of the augmented system z = [x, u, u', ..., u^(rows - 1)] (the input's
        Taylor chain), cached per step size and chain: a fixed-step run computes it once."""
        cache = self.__dict__.setdefault("_transitions", {})
        if (h, rows) not in cache:
            A, B = self.matrices()
            n, m = A.shape[0], B.shape[1]
            size = n + rows * m
            M = np.zeros((size, size))
            M[:n, :n], M[:n, n:n + m] = A, B
            for k in range(rows - 1):  # d/dt u^(k) = u^(k + 1)
                M[n + k * m:n + (k + 1) * m, n + (k + 1) * m:n + (k + 2) * m] = np.eye(m)
            if len(cache) > 256:  # variable steps: keep the cache small
                cache.clear()
            cache[h, rows] = expm(M * h)
        return cache[h, rows]


class Rotor(LinearModel):
    model_name = "Rotor"
    description = "Rigid rotor with optional spring and damper to ground, driven by a torque"
    seed = "textbook (two-mass oscillator test case, models/rotor/README.md)"
    parameters = (
        Variable("J", "kg.m2", "Rotor inertia", 1.0, min=0.0),
        Variable("c", "N.m/rad", "Spring to ground", 0.0, min=0.0),
        Variable("d", "N.m.s/rad", "Damper to ground", 0.0, min=0.0),
        Variable("phi0", "rad", "Initial angle", 0.0),
        Variable("w0", "rad/s", "Initial angular speed", 0.0),
    )
    inputs = (Variable("flange_tau", "N.m", "Torque applied to the rotor", 0.0),)
    outputs = (
        Variable("flange_w", "rad/s", "Rotor angular speed"),
        Variable("flange_phi", "rad", "Rotor angle"),
        Variable("E", "J", "Stored energy J w^2/2 + c phi^2/2"),
    )
    derivative_outputs = ("flange_w", "flange_phi")

    def check(self, p):
        if p.J <= 0.0:
            raise ParameterError(self.model_name, "J", p.J, "> 0 kg.m2")

    def state_names(self):
        return ("phi", "w")

    def initial_state(self, u):
        return np.array([self.p.phi0, self.p.w0])

    def matrices(self):
        p = self.p
        return (np.array([[0.0, 1.0], [-p.c / p.J, -p.d / p.J]]),
                np.array([[0.0], [1.0 / p.J]]))

    def output_values(self, t, x, u):
        phi, w = x
        return np.array([w, phi, 0.5 * self.p.J * w ** 2 + 0.5 * self.p.c * phi ** 2])


class ShaftRotor(LinearModel):
    model_name = "ShaftRotor"
    description = "Rotor driven through a compliant shaft (spring-damper) from a speed input"
    seed = "textbook (two-mass oscillator test case, models/rotor/README.md)"
    parameters = (
        Variable("J", "kg.m2", "Rotor inertia", 1.0, min=0.0),
        Variable("k", "N.m/rad", "Shaft torsional stiffness", 100.0, min=0.0),
        Variable("d_s", "N.m.s/rad", "Shaft damping", 0.0, min=0.0),
        Variable("c", "N.m/rad", "Spring from the rotor to ground", 0.0, min=0.0),
        Variable("d", "N.m.s/rad", "Damper from the rotor to ground", 0.0, min=0.0),
        Variable("theta0", "rad", "Initial shaft twist phi_flange - phi", 0.0),
        Variable("phi0", "rad", "Initial rotor angle", 0.0),
        Variable("w0", "rad/s", "Initial rotor angular speed", 0.0),
    )
    inputs = (Variable("flange_w", "rad/s", "Angular speed of the driving flange", 0.0),)
    outputs = (
        Variable("flange_tau", "N.m", "Torque the shaft applies to the driving flange",
                 depends_on=("flange_w",)),
        Variable("w", "rad/s", "Rotor angular speed"),
        Variable("phi", "rad", "Rotor angle"),
        Variable("E", "J", "Stored energy J w^2/2 + k theta^2/2 + c phi^2/2"),
    )
    derivative_outputs = ("flange_tau",)

    def check(self, p):
        if p.J <= 0.0:
            raise ParameterError(self.model_name, "J", p.J, "> 0 kg.m2")

    def state_names(self):
        return ("theta", "phi", "w")

    def initial_state(self, u):
        return np.array([self.p.theta0, self.p.phi0, self.p.w0])

    def matrices(self):
        p = self.p
        A = np.array([[0.0, 0.0, -1.0],
                      [0.0, 0.0, 1.0],
                      [p.k / p.J, -p.c / p.J, -(p.d_s + p.d) / p.J]])
        return A, np.array([[1.0], [0.0], [p.d_s / p.J]])

    def output_values(self, t, x, u):
        theta, phi, w = x
        p = self.p
        tau = -(p.k * theta + p.d_s * (u[self.IN.flange_w] - w))
        return np.array([tau, w, phi,
                         0.5 * (p.J * w ** 2 + p.k * theta ** 2 + p.c * phi ** 2)])
