"""CPU per doStep of each FMU in its shipped scene, against the press's, side by side in one run.

    python benchmarks/fmu_cost.py [--repeats R] [--scale S]

Each row runs a shipped scene (cut to a span that shows its events; `--scale` multiplies it)
R times, interleaved with the others so that a load on the machine falls on every row alike,
and reports the median over the repeats of
  - CPU per doStep of the named FMU (thread CPU time around each fmi2DoStep: the FMUs run in
    this thread, so time other processes take is not counted),
  - the ratio to the StephensonPress's in servo_press (the issue's bars: <= 2.5 for the
    planetary drive, the mill stand and the hammer; <= 5 for the hammer with bearings),
  - the master's own CPU per communication step: the run's CPU (process time over stepping,
    from the sidecar) less every FMU's doStep CPU, divided by the communication steps.
Printed, not asserted: the machine is shared. Loading the FMUs is not in any figure.
"""
from __future__ import annotations

import argparse
import copy
import statistics
import sys
import tempfile
import time
import types
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "sources"))

# (scene, component, span [s] at --scale 1, bar: at most this many times the press's doStep)
ROWS = (
    ("servo_press", "press", 1.0, None),
    ("planetary_engagement", "drive", 0.4, 2.5),
    ("mill_stand", "stand", 1.0, 2.5),
    ("hammer", "hammer", 1.5, 2.5),
    ("hammer_bearings", "hammer", 1.5, 5.0),
    ("mo100_impact", "impact", None, None),
)


def _cpu_clock_in_fmu_stats() -> None:
    """FmuInstance times doStep with time.perf_counter (wall); here its module sees a `time`
    whose perf_counter is this thread's CPU clock."""
    from crankfmu.fmu import instance

    instance.time = types.SimpleNamespace(perf_counter=time.thread_time)


def measure(scene_name: str, component: str, span: float | None, scale: float,
            folder: Path) -> tuple[float, float]:
    """(CPU per doStep of `component`, master CPU per communication step), one run."""
    from crankfmu.cosim.runner import RunOptions, run_scene
    from crankfmu.system.load import load_scene

    scene = load_scene(ROOT / "scenarios" / f"{scene_name}.toml")
    if span is not None:
        scene.stop_time = scene.start_time + span * scale
    result = run_scene(copy.deepcopy(scene), RunOptions(out=folder / f"{scene_name}.csv",
                                                        progress=False))
    stats = result.metadata["statistics"]
    mine = stats[component]
    per_step = mine["doStep_seconds"] / mine["doStep_calls"]
    fmu_cpu = sum(s["doStep_seconds"] for s in stats.values())
    master = (result.metadata["cpu_seconds"] - fmu_cpu) / result.metadata["communication_steps"]
    return per_step, master


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--scale", type=float, default=1.0, help="multiply every span")
    args = parser.parse_args(argv)
    _cpu_clock_in_fmu_stats()
    samples = {row[:2]: [] for row in ROWS}
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        for scene_name, component, span, _ in ROWS:  # warm-up: builds, first loads
            measure(scene_name, component, span, 0.05, folder)
        for _ in range(args.repeats):
            for scene_name, component, span, _ in ROWS:
                samples[scene_name, component].append(
                    measure(scene_name, component, span, args.scale, folder))
    press = statistics.median(s[0] for s in samples["servo_press", "press"])
    print(f"CPU per doStep in the shipped scenes (median of {args.repeats}; thread CPU time)")
    print(f"{'scene':22s} {'FMU':8s} {'us/doStep':>10s} {'x press':>8s} {'bar':>5s} "
          f"{'master us/step':>15s}")
    for scene_name, component, _, bar in ROWS:
        rows = samples[scene_name, component]
        step = statistics.median(r[0] for r in rows)
        master = statistics.median(r[1] for r in rows)
        ratio = step / press
        verdict = "" if bar is None else ("  met" if ratio <= bar else "  NOT met")
        print(f"{scene_name:22s} {component:8s} {step * 1e6:10.1f} {ratio:8.2f} "
              f"{'' if bar is None else f'{bar:g}':>5s} {master * 1e6:15.1f}{verdict}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
