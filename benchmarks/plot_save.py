"""A run's plot saved as PNG two ways, side by side in one run: matplotlib's savefig of the figure
as tight_layout leaves it (a placeholder layout engine on it: savefig draws it once to lay it out,
then again to render it) against crankfmu.cosim.results.figure_png (the placeholder removed
first: one draw). The same PNG bytes either way (checked here too).

    python benchmarks/plot_save.py [--repeats R]

The figures are those `crankfmu run --plot` writes: the servo press's steady state (crank speed
and drive torque over the last revolutions, three panels) and the panels-over-time figure of the
planetary_engagement scene's recorded variables, from short runs in this process (the FMUs in
fmus/, built if missing). Printed: CPU per save of each way (process time, median of R
alternated repeats, each on a new figure) and their ratio. Printed, not asserted: the machine
is shared.
"""
from __future__ import annotations

import argparse
import io
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "sources"))

from crankfmu.cosim.results import figure_png, run_figure  # noqa: E402
from crankfmu.cosim.runner import RunOptions, plot_roles, run_scene  # noqa: E402
from crankfmu.system.load import load_scene  # noqa: E402

SCENES = {"servo_press": 1.5, "planetary_engagement": 0.3}  # scene: stop time (s)


def make_figure(scene, recorder):
    return lambda: run_figure(recorder, scene.name, plot_roles(scene))


def savefig_as_left(fig) -> bytes:
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=110)
    return buffer.getvalue()


def cpu_of(save, make) -> tuple[float, bytes]:
    fig = make()
    start = time.process_time()
    data = save(fig)
    return time.process_time() - start, data


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeats", type=int, default=7)
    args = parser.parse_args()
    print(f"{'figure':<22} {'savefig (ms)':>13} {'figure_png (ms)':>16} {'ratio':>6}  same PNG")
    for name, stop in SCENES.items():
        scene = load_scene(ROOT / "scenarios" / f"{name}.toml")
        scene.stop_time = stop
        make = make_figure(scene, run_scene(scene, RunOptions(progress=False)).recorder)
        cpu_of(figure_png, make)  # matplotlib's first draw loads fonts and caches
        before, after, same = [], [], True
        for _ in range(args.repeats):
            t0, png0 = cpu_of(savefig_as_left, make)
            t1, png1 = cpu_of(figure_png, make)
            before.append(t0)
            after.append(t1)
            same &= png0 == png1
        b, a = statistics.median(before), statistics.median(after)
        print(f"{name:<22} {1e3 * b:13.1f} {1e3 * a:16.1f} {a / b:6.2f}  {same}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
