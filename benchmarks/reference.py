"""What a monolithic reference costs: its record times read from the solver's dense output, or
the integration restarted at each of them (how every reference was solved before).

    python benchmarks/reference.py [--rtol 1e-10] [--repeat 3] [--scenes servo_press,...]

For each shipped scene (default: all; `crankfmu reference`'s solve, the scene's own stop time
and record grid), alternately `--repeat` times: solve_reference(dense=True), the product's
default, and solve_reference(dense=False), after one untimed short solve (the imports).
Prints the medians of CPU (time.process_time: the solve and the recording, in this process),
the right-hand-side calls, their ratios, and the largest difference of a recorded variable
between the two, relative to its largest magnitude (both solutions are the solver's at the
same rtol, so this is of the order of their global error; the contact forces P and T of the
hammers, samples of a 0.4 ms pulse, move most).
Scenes whose composed model needs Radau restart at every record time either way (its dense
output is of lower order than its steps): their ratio is 1.
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "sources"))


def solve(scene, rtol: float, dense: bool):
    """(CPU seconds, the ReferenceResult) of one solve."""
    from crankfmu.monolithic.solve import solve_reference
    start = time.process_time()
    result = solve_reference(scene, rtol=rtol, dense=dense)
    return time.process_time() - start, result


def largest_difference(a, b) -> tuple[float, str]:
    """The largest |a - b| of a recorded variable over its largest |b|, and its name."""
    worst = (0.0, "-")
    for j, name in enumerate(a.recorder.names):
        x, y = a.recorder.rows[:, j + 1], b.recorder.rows[:, j + 1]
        difference = float(np.max(np.abs(x - y)) / max(np.max(np.abs(y)), 1e-300))
        if difference > worst[0]:
            worst = (difference, name)
    return worst


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rtol", type=float, default=1e-10)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--scenes", default="", help="comma-separated names (default: all)")
    args = parser.parse_args(argv)
    from crankfmu.system.load import load_scene

    names = args.scenes.split(",") if args.scenes else sorted(
        p.stem for p in (ROOT / "scenarios").glob("*.toml"))
    print(f"monolithic references at rtol {args.rtol:g}: median CPU of {args.repeat} "
          "(alternating), right-hand-side calls")
    print(f"{'scene':<24} {'method':<7} {'records':>7} {'dense s':>8} {'restart s':>9} "
          f"{'ratio':>6} {'dense rhs':>9} {'restart rhs':>11} {'largest difference':>28}")
    warm = load_scene(ROOT / "scenarios" / f"{names[0]}.toml")
    warm.stop_time = warm.start_time + 10 * warm.master.step
    solve(warm, args.rtol, True)  # untimed: scipy's import and first calls
    total = {True: 0.0, False: 0.0}
    dop853 = {True: 0.0, False: 0.0}  # the scenes the dense output serves
    for name in names:
        scene = load_scene(ROOT / "scenarios" / f"{name}.toml")
        cpu: dict[bool, list[float]] = {True: [], False: []}
        last = {}
        for _ in range(args.repeat):
            for dense in (True, False):
                seconds, last[dense] = solve(scene, args.rtol, dense)
                cpu[dense].append(seconds)
        median = {d: statistics.median(c) for d, c in cpu.items()}
        for d in total:
            total[d] += median[d]
            dop853[d] += median[d] if last[True].method == "DOP853" else 0.0
        difference, variable = largest_difference(last[True], last[False])
        print(f"{name:<24} {last[True].method:<7} {last[True].recorder.count:>7} "
              f"{median[True]:>8.2f} {median[False]:>9.2f} {median[False] / median[True]:>6.1f} "
              f"{last[True].rhs_calls:>9} {last[False].rhs_calls:>11} "
              f"{difference:>9.1e} {variable:>18}")
    for label, sums in (("all DOP853 scenes", dop853), ("all scenes", total)):
        print(f"{label:<40} {sums[True]:>8.2f} {sums[False]:>9.2f} "
              f"{sums[False] / max(sums[True], 1e-12):>6.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
