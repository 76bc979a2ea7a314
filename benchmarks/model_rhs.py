"""What one right-hand side and one 1 ms step of each physics model cost, in-process (no FMU):
the figure behind "named input access must not slow the right-hand side".

    python benchmarks/model_rhs.py

Each catalog model on its default effects and start inputs: CPU per derivatives() call (20000
calls) and per step() of 1 ms (200 steps, rtol 1e-8), the median of 7 repeats. To compare two
versions of the code, run it with PYTHONPATH at each tree's sources/, alternately (the machine
is shared: printed, not asserted)."""
from __future__ import annotations

import statistics
import time

from crankfmu.models.catalog import FMU_MODELS, physics_class
from crankfmu.runtime.model import held

REPEATS = 7
CALLS = 20000
STEPS = 200
STEP_S = 1e-3
RTOL = 1e-8


def rhs_seconds(cls) -> float:
    model = cls()
    u = [float(v.start) for v in cls.inputs]
    x = list(model.initial_state(u))
    times = []
    for _ in range(REPEATS):
        start = time.process_time()
        for _ in range(CALLS):
            model.derivatives(0.0, x, u)
        times.append((time.process_time() - start) / CALLS)
    return statistics.median(times)


def step_seconds(cls) -> float:
    u = [float(v.start) for v in cls.inputs]
    times = []
    for _ in range(REPEATS):
        model = cls()
        x = list(model.initial_state(u))
        atol = [RTOL * v for v in model.state_nominal()]
        start = time.process_time()
        for k in range(STEPS):
            x = list(model.step(k * STEP_S, x, STEP_S, held(u), RTOL, atol))
        times.append((time.process_time() - start) / STEPS)
    return statistics.median(times)


def main() -> int:
    print(f"CPU per call, median of {REPEATS}: derivatives() [us], "
          f"step() of {STEP_S * 1e3:g} ms [us]")
    for name in FMU_MODELS:
        cls = physics_class(name)
        print(f"    {name:<22} derivatives {rhs_seconds(cls) * 1e6:7.2f}   "
              f"step {step_seconds(cls) * 1e6:8.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
