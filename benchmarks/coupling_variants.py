"""What else the coupling could do, tried on the servo press's first second (issue 25): an
energy-conserving correction at the torque/speed port (NEPCE-like), step control from the port's
energy residual (ECCO-like), and multirate stepping of the cheap FMU.

    python benchmarks/coupling_variants.py [--repeats R] [--out DIR]

Each variant is an example master defined here and registered for this run only (as
tests/examples/masters does), against the shipped master it modifies, in crankfmu accuracy's
"max" metric on the crank speed against the rtol 1e-10 reference, with the run's CPU (median of
R, runs interleaved) and its doStep calls per FMU:

(a) NEPCE-like: Gauss-Seidel; after each step the energy the port's two sides disagree on
    (masters/power.py: E_receiver - E_driver over the step) is put back over the next step by
    a constant torque offset -dE / (w h) on the receiver's (the press's) input. Against plain
    Gauss-Seidel with extrapolation 0, 1, 2 at 1, 2 and 4 ms.
(b) ECCO-like: a variable step without rollback: after each step the relative energy residual
    err = |dE| / (tolerance x the energy through the port over the step) sets the next step by a
    PI rule h (1/err)^0.15 (err_prev/err)^0.2 (Sadjina et al.'s gains), growth within
    [0.2, 5]. Against the adaptive master (extrapolation error, rollback) at equal error.
(c) Multirate: Gauss-Seidel with taylor 3, the motor (closed form, cheap) stepped m = 2, 4 times
    per communication step with the same input polynomial (its FMU carries the polynomial to
    each substep's end), the press (Dormand-Prince, the costly one) once.

Printed, not asserted; docs/architecture.md ("Taylor coupling", "What else was tried") keeps the
figures and what was kept.
"""
from __future__ import annotations

import argparse
import copy
import statistics
import sys
import tempfile
import time
import warnings
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from coupling import ROOT, scene_setup  # noqa: E402

CLOCK = time.process_time


def example_masters():
    """The three variants as master classes (imported here: they sit on crankfmu.masters)."""
    from crankfmu.masters.adaptive import Adaptive
    from crankfmu.masters.gauss_seidel import GaussSeidel

    class EnergyCorrected(GaussSeidel):
        """Gauss-Seidel plus the NEPCE-like correction (module docstring (a))."""
        name = "nepce-gs"

        def __init__(self, system, settings):
            super().__init__(system, settings)
            self.offset = 0.0  # N.m on the receiver's torque input over the next step
            # the sweeps call the per-FMU gather functions of `_sweep_plan` (masters/base.py):
            # the receiver's is wrapped there
            receiver = self.power.ports[0].receiver if self.power.ports else None
            self._sweep_plan = [(c, self._corrected(g) if c == receiver else g, a, r)
                                for c, g, a, r in self._sweep_plan]

        def _corrected(self, gather):
            tau_in = self.power.ports[0].tau_in

            def corrected(coefficients):
                rows = gather(coefficients)
                if not self.offset:
                    return rows
                value = list(rows[0])  # the rows are the sources' own: a new value row
                value[tau_in] += self.offset
                return [value, *rows[1:]]
            return corrected

        def step(self, t, h):
            port = self.power.ports[0]
            before = port.energy_receiver - port.energy_driver
            taken = super().step(t, h)
            mismatch = port.energy_receiver - port.energy_driver - before
            w = float(self.system.outputs[port.receiver][port.w_out])
            self.offset = -mismatch / (w * taken) if abs(w) > 1e-9 else 0.0
            return taken

    class PowerBond(Adaptive):
        """Variable step from the port's energy residual, no rollback (module docstring
        (b))."""
        name = "ecco"
        needs_rollback = False

        def __init__(self, system, settings):
            super().__init__(system, settings)
            self.previous_error = 1.0

        def _step(self, t, h):
            h = self._to_edge(t, h)
            order = min(self.extrapolation, len(self.history.times) - 1)
            self.sequential_sweep(t, h, order)
            self._count(t, h, 0.0)
            return h

        def step(self, t, h):
            port = self.power.ports[0]
            before = (port.energy_receiver - port.energy_driver, port.throughput)
            taken = super().step(t, h)
            residual = abs(port.energy_receiver - port.energy_driver - before[0])
            through = port.throughput - before[1]
            error = max(residual / (self.tolerance * through), 1e-10) if through > 0 else 1.0
            factor = (1.0 / error) ** 0.15 * (self.previous_error / error) ** 0.2
            self.previous_error = error
            self.next_step = self._clip(taken * min(5.0, max(0.2, factor)))
            return taken

    class Multirate(GaussSeidel):
        """Gauss-Seidel (taylor) with the last component substepped (module docstring (c));
        `substeps` set on the class by the benchmark."""
        name = "multirate-gs"
        substeps = 2

        def __init__(self, system, settings):
            super().__init__(system, settings)
            fmu = system.fmus[system.order[-1]]
            single, m = fmu.do_step, self.substeps

            def substepped(t, h):
                for k in range(m):
                    single(t + k * h / m, h / m)
            fmu.do_step = substepped  # this run's instance only

        def _written_sweep(self, sequential, order):
            return None  # a sweep written out (masters/sweep_code.py) calls doStep directly

    return EnergyCorrected, PowerBond, Multirate


def run(scene, metric, ref, settings: dict):
    from crankfmu.cosim.runner import RunOptions, run_scene
    trial = copy.deepcopy(scene)
    for key, value in settings.items():
        setattr(trial.master, key, value)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = run_scene(trial, RunOptions(out=None, fmu_dir=ROOT / "fmus", progress=False))
    rec = result.recorder
    error = metric.error(rec.rows[:, 0], {k: rec.column(k) for k in rec.names}, ref)
    calls = max(s["doStep_calls"] for s in result.statistics.values())
    mismatch = result.coupling_error.get("max_relative_mismatch")
    return result.cpu_seconds, error, calls, mismatch


def table(title: str, rows: list, scene, metric, ref, repeats: int) -> None:
    measured = {label: [] for label, _ in rows}
    outcome = {}
    for _ in range(repeats):
        for label, settings in rows:
            cpu, error, calls, mismatch = run(scene, metric, ref, settings)
            measured[label].append(cpu)
            outcome[label] = (error, calls, mismatch)
    print(title)
    for label, _ in rows:
        error, calls, mismatch = outcome[label]
        print(f"  {label:<44} error {error:8.2e}  CPU {statistics.median(measured[label]) * 1e3:7.1f}"
              f" ms  {calls:5d} doSteps  port energy mismatch "
              f"{mismatch if mismatch is not None else float('nan'):.1e}")


def main(argv=None) -> int:
    from crankfmu.masters import MASTERS, register

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--out", type=Path, default=Path(tempfile.gettempdir()) / "crankfmu_coupling")
    args = ap.parse_args(argv)
    energy, bond, multirate = example_masters()
    for cls in (energy, bond, multirate):
        register(cls)
    try:
        scene, metric, ref = scene_setup("servo_press", args.out)
        nepce = []
        for ex in (0, 1, 2):
            for h in (1e-3, 2e-3, 4e-3):
                nepce += [(f"gauss-seidel ex{ex} h {h:g}",
                           dict(algorithm="gauss-seidel", extrapolation=ex, step=h)),
                          (f"  + NEPCE-like correction (ex{ex} h {h:g})",
                           dict(algorithm="nepce-gs", extrapolation=ex, step=h))]
        table("(a) energy-conserving correction at the port (NEPCE-like)", nepce, scene, metric,
              ref, args.repeats)
        ecco = []
        for coupling in (dict(extrapolation=2), dict(taylor=3, fmu_tolerance=1e-6)):
            text = f"taylor {coupling['taylor']}" if "taylor" in coupling else "ex2"
            for tol in (1e-2, 3e-3, 1e-3, 3e-4):
                ecco += [(f"adaptive {text} tol {tol:g}",
                          dict(algorithm="adaptive", tolerance=tol, max_step=0.05, **coupling)),
                         (f"ECCO-like {text} tol {tol:g}",
                          dict(algorithm="ecco", tolerance=tol, max_step=0.05, **coupling))]
        table("(b) step control from the port's energy residual (ECCO-like), no rollback",
              ecco, scene, metric, ref, args.repeats)
        rates = []
        for m in (1, 2, 4):
            multirate.substeps = m
            rates.append((f"gauss-seidel taylor 3 h 4e-3, motor x {m}",
                          dict(algorithm="multirate-gs", taylor=3, step=4e-3,
                               fmu_tolerance=1e-6)))
        multirate.substeps = 1
        for label, settings in rates:  # the class attribute is the run's: measure one by one
            multirate.substeps = int(label.rsplit("x ", 1)[1])
            table(f"(c) multirate, motor substeps {multirate.substeps}", [(label, settings)],
                  scene, metric, ref, args.repeats)
    finally:
        for cls in (energy, bond, multirate):
            MASTERS.pop(cls.name, None)
    return 0


if __name__ == "__main__":
    sys.exit(main())
