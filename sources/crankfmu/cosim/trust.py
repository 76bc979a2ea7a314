"""When a run that completed says itself that it is not to be trusted.

A co-simulation can run to its stop time with finite values and still have lost the solution:
an explicit master beyond its stability limit (Jacobi at 16 ms on the servo press ends with its
own error estimate at 1.05, the crank speed wrong by its own size) or events that the step no
longer resolves. Two figures every run has without a reference say so:

    the estimated global error (cosim/estimate.py: Richardson from a companion at half the
    step, in the scene's accuracy metric, relative), and whether that companion counts the
    same events as the run;
    the port energy mismatch (masters/power.py: the energy the two sides of a torque/speed
    port disagree on, relative to the energy through the port).

A run is marked `unreliable` (sidecar "status" and "outcome", `Result.status`; the causes in
"unreliable" with the remedy) when

    the estimate exceeds ESTIMATE_LIMIT,
    the companion at half the step counts other events than the run, or
    a port's relative energy mismatch exceeds MISMATCH_LIMIT.

The limits were chosen from scripts/large_steps.py: every shipped scene with Gauss-Seidel,
Jacobi and the iterative master (the scene's extrapolation) at 1, 2, 4, 8, 16 and 32 x its
step, 234 runs, each against the monolithic reference in the scene's metric (docs/error_estimate.md,
"When a run is marked unreliable"):

    at their own settings the shipped scenes' estimates are at most 4.1e-3 (the speed loop)
    and their port mismatches at most 1.4e-4: 24 and 700 times below the limits;
    all 16 runs whose true error exceeded 0.1 are marked (9 by the estimate alone, 7 by the
    estimate and the mismatch), and 13 of the 17 that count other events than the reference
    (7 of them by the companion's event count, 2 by the mismatch alone); the 4 left count the
    same wrong events as their companion, with estimates of 0.02 to 0.07;
    of the 201 runs within 0.1 of the reference 2 are marked, both at 7.7 % true error with an
    estimate of 0.10 and 0.12 (the speed loop at 8 x its step); the largest mismatch among
    them was 0.040.

The mismatch speaks also where there is no estimate (--no-estimate, the runs of a sweep): then
it marks the Jacobi runs that lost the solution (7 of the 16; the Gauss-Seidel ones keep a
small mismatch while their error grows). Over a short run from rest the relative mismatch is
larger than over a long one (the servo press with Jacobi at 2 ms: 0.14 over 0.05 s, 0.069 over
1 s), so a short run at a coarse step is marked sooner.

The remedy is the same whatever the cause: a smaller step, another master (the iterative one
solves the coupling in every step, the adaptive one chooses its steps), or a target error that
chooses master and step from the estimate (`--target`, `target=`).
"""
from __future__ import annotations

import math

ESTIMATE_LIMIT = 0.1     # estimated global error in the scene's metric [1]
MISMATCH_LIMIT = 0.1     # relative port energy mismatch [1]
REMEDY = ("use a smaller step (--step), another master (--algorithm iterative or adaptive), "
          "or --target TOL to choose master and step for the error wanted")


class UnreliableResultWarning(UserWarning):
    """The Python API's warning for a run marked unreliable (its message: warning_line)."""


def causes(estimate, coupling_error: dict) -> list[str]:
    """Why a completed run is not to be trusted (empty: nothing says so). `estimate`: the
    run's cosim.estimate.Estimate or None; `coupling_error`: the master's report."""
    found = []
    if estimate is not None:
        if estimate.ok and estimate.error > ESTIMATE_LIMIT:
            found.append(f"its estimated error {estimate.error:.3g} ({estimate.error:.0%}) "
                         f"exceeds {ESTIMATE_LIMIT:g}")
        elif not estimate.ok and estimate.events_differ:
            found.append("its companion at half the step counts other events, so the step "
                         "does not resolve them")
    for port in coupling_error.get("ports", []):
        rel = port.get("relative_mismatch")
        if rel is not None and math.isfinite(rel) and rel > MISMATCH_LIMIT:
            found.append(f"the port energy mismatch at {port['driver']} -> {port['receiver']} "
                         f"is {rel:.3g} ({rel:.0%}) of the energy through the port, above "
                         f"{MISMATCH_LIMIT:g}")
    return found


def judge_result(scene, result) -> list[str]:
    """Mark `result` (a cosim.runner.RunResult that completed) unreliable in its metadata when
    `causes` finds a reason; returns the causes."""
    found = causes(result.estimate, result.coupling_error)
    if found:
        result.metadata.update({"status": "unreliable", "outcome": "unreliable",
                                "unreliable": found, "remedy": REMEDY})
    return found


def warning_line(name: str, metadata: dict) -> str | None:
    """The one-line warning of an unreliable run (None for any other)."""
    if metadata.get("outcome") != "unreliable":
        return None
    return (f"{name}: the result is unreliable: " + "; ".join(metadata["unreliable"])
            + f". Remedy: {metadata['remedy']}")
