"""The planetary drive's step two ways, side by side in one run: the exact step (inputs held
over the step, exponential brake laws) against the runtime's Dormand-Prince on derivatives()
(on_input_change, then PhysicsModel.advance: the drive's advance without the exact step).

    python benchmarks/planetary_step.py [--repeats R]

In process (no FMU), the planetary_engagement scene's drive and motor: 4000 communication steps
of 0.1 ms through the command edge, the carrier's break-free and the ring's lock, the motor
torque held over each step, fmu_tolerance 1e-10. Printed: CPU per advance() of each way (thread
time, median of R repeats), their ratio, the largest difference of the two runs' states
(relative to each state's largest magnitude) and of their lock times; and CPU per call of
derivatives() and output_values(). The figures behind the choice in the drive's model card
(sources/crankfmu/models/planetary_drive/README.md section 11). Printed, not asserted: the
machine is shared.
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "sources"))

from crankfmu.models.induction_motor.induction_motor import InductionMotor  # noqa: E402
from crankfmu.models.planetary_drive.planetary_drive import PlanetaryClutchDrive  # noqa: E402
from crankfmu.runtime.model import PhysicsModel, held  # noqa: E402

STEP_S, STEPS, TOLERANCE = 1e-4, 4000, 1e-10


def scene_models():
    scene = tomllib.loads((ROOT / "scenarios" / "planetary_engagement.toml").read_text())
    parts = scene["components"]
    return (PlanetaryClutchDrive(parts["drive"]["parameters"]),
            InductionMotor(parts["motor"]["parameters"]))


def run(exact: bool):
    """(CPU seconds per advance, states after every step, lock time of the ring)."""
    drive, motor = scene_models()
    x = list(drive.initial_state([0.0, 0.0, 0.0, 0.0, 0.0]))
    x = list(drive.initial_state([0.0, motor.torque(drive.sun_speed(x)), 0.0, 0.0, 0.0]))
    atol = [TOLERANCE * v for v in drive.state_nominal()]
    states, cpu = [], 0.0
    for k in range(STEPS):
        u_of_t = held([1.0, motor.torque(drive.sun_speed(x)), 0.0, 0.0, 0.0])
        t = k * STEP_S
        start = time.thread_time()
        if exact:
            x = drive.advance(t, x, STEP_S, u_of_t, TOLERANCE, atol)
        else:
            x = drive.on_input_change(t, x, u_of_t(t))
            x = PhysicsModel.advance(drive, t, x, STEP_S, u_of_t, TOLERANCE, atol)
        cpu += time.thread_time() - start
        states.append(list(x))
    return cpu / STEPS, states, drive.discrete_state()["elements"]["b"]["t_lock"]


def per_call(function, calls: int = 20000) -> float:
    start = time.thread_time()
    for _ in range(calls):
        function()
    return (time.thread_time() - start) / calls


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args(argv)
    samples = {True: [], False: []}
    for _ in range(args.repeats):
        for exact in (True, False):
            samples[exact].append(run(exact))
    exact, integrated = (statistics.median(s[0] for s in samples[k]) for k in (True, False))
    x_exact, x_integrated = samples[True][0][1], samples[False][0][1]
    scale = [max(abs(row[i]) for row in x_integrated) or 1.0 for i in range(len(x_exact[0]))]
    worst = max(abs(a - b) / s for r, q in zip(x_exact, x_integrated)
                for a, b, s in zip(r, q, scale))
    drive, motor = scene_models()
    u = [1.0, 20.0, 0.0, 0.0, 0.0]
    x = list(drive.initial_state(u))
    print(f"planetary_engagement's drive, {STEPS} steps of {STEP_S * 1e3:g} ms "
          f"(median of {args.repeats}; thread CPU time)")
    print(f"  exact step                      {exact * 1e6:8.1f} us per advance")
    print(f"  Dormand-Prince on derivatives   {integrated * 1e6:8.1f} us per advance   "
          f"({integrated / exact:.1f} x)")
    print(f"  states apart: {worst:.1e} of their largest magnitudes; ring lock times apart: "
          f"{abs(samples[True][0][2] - samples[False][0][2]):.1e} s")
    print(f"  derivatives()   {per_call(lambda: drive.derivatives(0.05, x, u)) * 1e6:6.2f} us "
          f"per call;  output_values() "
          f"{per_call(lambda: drive.output_values(0.05, x, u)) * 1e6:6.2f} us per call")
    return 0


if __name__ == "__main__":
    sys.exit(main())
