"""The matrix exponential expm(A) on numpy alone: scaling and squaring with a diagonal Pade
approximant (N. J. Higham, "The scaling and squaring method for the matrix exponential
revisited", SIAM J. Matrix Anal. Appl. 26(4), 2005, Algorithm 2.3: the degrees 3, 5, 7, 9, 13,
their 1-norm bounds theta_m and coefficients b_k are that paper's).

It is here, not imported from scipy.linalg, because `import scipy.linalg` costs 0.24-0.29 s of
CPU in every process that loads an FMU whose model needs an exponential (Rotor and ShaftRotor at
their first step), on matrices of 2 to 8 rows; the rocker's linear theory
(rocker_linear.LinearFlow), which no FMU step calls, still uses scipy's. Against
scipy.linalg.expm it agrees to a few units of round-off (tests/test_matrix_exponential.py).

Degree m is the lowest whose bound theta_m exceeds ||A||_1: the approximant r_m(A) then equals
expm(A) to double precision (backward error below 2^-53). Above theta_13, A is scaled by 2^-s
into the bound and r_13 squared s times.
"""
from __future__ import annotations

import math

import numpy as np

# theta_m: the largest ||A||_1 for which the [m/m] Pade approximant has a backward error below
# the unit round-off 2^-53 (Higham 2005, Table 2.3)
_THETA = {3: 1.495585217958292e-2, 5: 2.539398330063230e-1, 7: 9.504178996162932e-1,
          9: 2.097847961257068e0, 13: 5.371920351148152e0}
# b_k, k = 0..m: the numerator p_m(x) = sum_k b_k x^k of the approximant r_m = p_m(x)/p_m(-x)
_B = {
    3: (120.0, 60.0, 12.0, 1.0),
    5: (30240.0, 15120.0, 3360.0, 420.0, 30.0, 1.0),
    7: (17297280.0, 8648640.0, 1995840.0, 277200.0, 25200.0, 1512.0, 56.0, 1.0),
    9: (17643225600.0, 8821612800.0, 2075673600.0, 302702400.0, 30270240.0, 2162160.0,
        110880.0, 3960.0, 90.0, 1.0),
    13: (64764752532480000.0, 32382376266240000.0, 7771770303897600.0, 1187353796428800.0,
         129060195264000.0, 10559470521600.0, 670442572800.0, 33522128640.0, 1323241920.0,
         40840800.0, 960960.0, 16380.0, 182.0, 1.0),
}


def expm(A) -> np.ndarray:
    """exp(A) of a real square matrix."""
    A = np.asarray(A, dtype=float)
    if A.ndim != 2 or A.shape[0] != A.shape[1]:
        raise ValueError(f"expm needs a square matrix, got shape {A.shape}")
    if not np.all(np.isfinite(A)):
        raise ValueError("expm needs finite entries")
    norm = float(np.max(np.sum(np.abs(A), axis=0))) if A.size else 0.0
    for m in (3, 5, 7, 9):
        if norm <= _THETA[m]:
            return _pade_ratio(*_odd_even_parts(A, m))
    squarings = max(0, math.ceil(math.log2(norm / _THETA[13]))) if norm > 0.0 else 0
    X = _pade_ratio(*_odd_even_parts_13(A / 2.0 ** squarings))
    for _ in range(squarings):
        X = X @ X
    return X


def _odd_even_parts(A: np.ndarray, m: int) -> tuple[np.ndarray, np.ndarray]:
    """(U, V): the odd and even parts of p_m(A) = V + U, degree m in 3, 5, 7, 9."""
    b = _B[m]
    identity = np.eye(A.shape[0])
    A2 = A @ A
    power = identity  # A^(2j)
    odd = np.zeros_like(A)
    even = np.zeros_like(A)
    for j in range((m + 1) // 2):
        odd += b[2 * j + 1] * power
        even += b[2 * j] * power
        power = power @ A2
    return A @ odd, even


def _odd_even_parts_13(A: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(U, V) of p_13(A), evaluated with six products (Higham 2005, eq. 2.11)."""
    b = _B[13]
    identity = np.eye(A.shape[0])
    A2 = A @ A
    A4 = A2 @ A2
    A6 = A2 @ A4
    U = A @ (A6 @ (b[13] * A6 + b[11] * A4 + b[9] * A2)
             + b[7] * A6 + b[5] * A4 + b[3] * A2 + b[1] * identity)
    V = (A6 @ (b[12] * A6 + b[10] * A4 + b[8] * A2)
         + b[6] * A6 + b[4] * A4 + b[2] * A2 + b[0] * identity)
    return U, V


def _pade_ratio(U: np.ndarray, V: np.ndarray) -> np.ndarray:
    """r_m(A) = p_m(-A)^-1 p_m(A) = (V - U)^-1 (V + U)."""
    return np.linalg.solve(V - U, V + U)
