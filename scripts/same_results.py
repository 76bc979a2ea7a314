"""Do the shipped scenes give the same results as before a change to the models or the runtime?

    python scripts/same_results.py save DIR       # before the change: every scene's CSV in DIR
    python scripts/same_results.py compare DIR    # after it: the table of worst differences

Every scene in scenarios/ runs as shipped (no error estimate). `compare` runs them again and
prints, per scene, the worst difference of each recorded variable against the saved run:
relative to the variable's largest magnitude, except event times (absolute, s). The bounds are
those of tests/test_runtime_scenes.py, where two correct integrations of one scene were measured
apart: 100 x the scene's fmu_tolerance for every variable; event times within 1e-7 s; impact
peaks (P_peak, T_peak) within 1e-9 relative at a tolerance of 1e-10. The contact forces P and T
sampled across a moving 0.4 ms pulse are listed but not bounded (a shift of the impact by
2e-10 s moves a sample by 1e-6 of the peak); their peaks are. Exit status 1 if a bound is
exceeded or a scene's rows or columns differ.
"""
from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "sources"))  # this tree's crankfmu, whatever is installed
GLOBAL_FACTOR = 100.0
PULSE_SAMPLES = {"P", "T"}
EVENT_TIMES = {"t_lock_b", "t_slip_b", "t_lock_h", "t_slip_h", "t_command"}


def _scenes():
    return sorted((ROOT / "scenarios").glob("*.toml"))


def _run(path: Path, out: Path):
    from crankfmu.cosim.runner import RunOptions, run_scene
    from crankfmu.system.load import load_scene

    scene = load_scene(path)
    run_scene(scene, RunOptions(out=out, progress=False))
    return scene


def _read(csv: Path) -> dict[str, np.ndarray]:
    data = np.genfromtxt(csv, delimiter=",", names=True, deletechars="")
    return {name.strip('"'): np.asarray(data[name], dtype=float) for name in data.dtype.names}


def _bound(var: str, tol: float):
    if var in PULSE_SAMPLES:
        return None, "rel."
    if var in EVENT_TIMES:
        return 1e-7, "s"
    if var in ("P_peak", "T_peak") and tol <= 1e-10:
        return 1e-9, "rel."
    return GLOBAL_FACTOR * tol, "rel."


def compare_scene(path: Path, saved: Path, fresh: Path) -> bool:
    scene = _run(path, fresh)
    tol = scene.master.fmu_tolerance
    before, after = _read(saved), _read(fresh)
    if list(before) != list(after) or len(before["time"]) != len(after["time"]):
        print(f"\n{path.stem}: columns or rows differ ({len(before['time'])} rows before, "
              f"{len(after['time'])} after)")
        return False
    ok, lines = True, []
    for column, b in before.items():
        if column == "time":
            continue
        a = after[column]
        var = column.split(".", 1)[-1]
        bound, unit = _bound(var, tol)
        diff = float(np.max(np.abs(a - b))) if len(a) else 0.0
        worst = diff if unit == "s" else diff / max(float(np.max(np.abs(b))), 1e-300)
        flag = ""
        if bound is not None and not worst <= bound:
            ok, flag = False, "  EXCEEDS"
        shown = f"(bound {bound:.0e})" if bound else "(pulse sample: see peaks)"
        lines.append(f"  {column:<28} {worst:9.2e} {unit:<4} {shown}{flag}")
    print(f"\n{path.stem} (fmu_tolerance {tol:g}): worst difference against the saved run")
    print("\n".join(lines))
    return ok


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) != 2 or argv[0] not in ("save", "compare"):
        print(__doc__)
        return 2
    folder = Path(argv[1])
    if argv[0] == "save":
        folder.mkdir(parents=True, exist_ok=True)
        for path in _scenes():
            _run(path, folder / f"{path.stem}.csv")
            print(f"saved {path.stem}")
        return 0
    with tempfile.TemporaryDirectory() as fresh:  # DIR is only read: two checks may share it
        results = [compare_scene(p, folder / f"{p.stem}.csv", Path(fresh) / f"{p.stem}.csv")
                   for p in _scenes()]
    print(f"\n{sum(results)} of {len(results)} scenes within their bounds")
    return 0 if all(results) else 1


if __name__ == "__main__":
    sys.exit(main())
