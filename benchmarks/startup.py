"""What a short run costs against the imports it cannot avoid, and what 2 sweep workers gain.

    python benchmarks/startup.py [--repeat 15] [--sweep] [--sweep-repeat 3]

prints (a) and (c), and (b) with --sweep.

(a) `crankfmu run scenarios/servo_press.toml --stop-time 0.002 --no-estimate` (2 steps: the run
is nearly all start-up: interpreter, imports, the FMUs' loading) against
`python -c "import fmpy, numpy"`, alternating, each a fresh process with its stderr on a
pseudo-terminal (as typed at a prompt), --repeat times each; prints the medians of wall time and
of CPU time (user + system of the child) and their ratios. Bytecode
caching is on for both (PYTHONDONTWRITEBYTECODE removed from their environment) and one run of
each comes first, untimed, so both find their caches warm (the FMUs built and unpacked, the
.pyc files written); the FMU cache is the user's (crankfmu.fmu.archive).

(c) the same 2-step run repeated in this process, as the Python API, a sweep's worker or the
test suite repeat runs (the imports done, the FMUs unpacked): CPU per run (time.process_time)
from loading the FMUs to the result, median and minimum over 3 x --repeat runs after one
untimed.

(b) with --sweep: benchmarks/sweep.py's 12 servo press runs of 3 s with --jobs 1 and --jobs 2,
--sweep-repeat times (the ratio needs two free cores: see the load averages printed).

The load average is printed before each part: on a shared machine other work inflates wall
times, and CPU times less so.
"""
from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RUN = [sys.executable, "-m", "crankfmu", "run", str(ROOT / "scenarios" / "servo_press.toml"),
       "--stop-time", "0.002", "--no-estimate"]
IMPORTS = [sys.executable, "-c", "import fmpy, numpy"]


def environment(out: Path) -> dict:
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(ROOT / "sources"),
                                                      env.get("PYTHONPATH")]))
    return env


def timed(command: list[str], env: dict, cwd: Path) -> tuple[float, float]:
    """(wall, CPU) seconds of one run of `command` in a fresh process, its stderr a terminal
    (a pseudo-terminal: as at a shell prompt, where crankfmu may draw a progress bar)."""
    import pty
    import threading
    terminal, stderr = pty.openpty()
    drain = threading.Thread(target=_read_all, args=(terminal,), daemon=True)
    drain.start()  # a full terminal buffer would block the child
    try:
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        start = time.perf_counter()
        subprocess.run(command, env=env, cwd=cwd, check=True, stdout=subprocess.DEVNULL,
                       stderr=stderr)
        wall = time.perf_counter() - start
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
    finally:
        os.close(stderr)
        drain.join(5)
        os.close(terminal)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def _read_all(fd: int) -> None:
    try:
        while os.read(fd, 1 << 16):
            pass
    except OSError:  # EIO: the terminal's other end is closed
        pass


def part_a(repeat: int, folder: Path) -> None:
    env = environment(folder)
    run = RUN + ["--fmus", str(ROOT / "fmus"), "--out", str(folder / "run.csv")]
    for command in (run, IMPORTS):  # warm: FMUs built and unpacked, bytecode written
        timed(command, env, folder)
    print(f"(a) load average {os.getloadavg()[0]:.2f} at start; {repeat} alternating runs each")
    figures = {"run": [], "imports": []}
    for _ in range(repeat):
        figures["run"].append(timed(run, env, folder))
        figures["imports"].append(timed(IMPORTS, env, folder))
    medians = {k: (statistics.median(w for w, _ in v), statistics.median(c for _, c in v))
               for k, v in figures.items()}
    (rw, rc), (iw, ic) = medians["run"], medians["imports"]
    print(f"  crankfmu run --stop-time 0.002 --no-estimate: median wall {rw:.3f} s, CPU {rc:.3f} s")
    print(f"  python -c 'import fmpy, numpy':              median wall {iw:.3f} s, CPU {ic:.3f} s")
    print(f"  ratio run / imports: wall {rw / iw:.2f}, CPU {rc / ic:.2f}; "
          f"load average {os.getloadavg()[0]:.2f} at end")


def part_c(repeat: int) -> None:
    sys.path.insert(0, str(ROOT / "sources"))
    from crankfmu.cosim.runner import RunOptions, run_scene
    from crankfmu.system.load import load_scene

    scene = load_scene(ROOT / "scenarios" / "servo_press.toml")
    scene.stop_time = scene.start_time + 0.002
    options = RunOptions(out=None, fmu_dir=ROOT / "fmus", progress=False)
    run_scene(scene, options)  # untimed: the first run imports and unpacks
    cpu = []
    for _ in range(3 * repeat):
        start = time.process_time()
        run_scene(scene, options)
        cpu.append(time.process_time() - start)
    print(f"(c) the 2-step run repeated in one process ({len(cpu)} runs): CPU per run median "
          f"{statistics.median(cpu) * 1e3:.2f} ms, min {min(cpu) * 1e3:.2f} ms; load average "
          f"{os.getloadavg()[0]:.2f}")


def part_b(repeat: int) -> None:
    print(f"(b) load average {os.getloadavg()[0]:.2f} at start")
    subprocess.run([sys.executable, str(ROOT / "benchmarks" / "sweep.py"), "--stop-time", "3",
                    "--repeat", str(repeat)], env=environment(ROOT), check=True)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=15)
    ap.add_argument("--sweep", action="store_true", help="also (b): the sweep's jobs 1 vs 2")
    ap.add_argument("--sweep-repeat", type=int, default=3)
    args = ap.parse_args()
    import tempfile
    with tempfile.TemporaryDirectory(prefix="crankfmu-startup-") as tmp:
        part_a(args.repeat, Path(tmp))
    part_c(args.repeat)
    if args.sweep:
        part_b(args.sweep_repeat)
    return 0


if __name__ == "__main__":
    sys.exit(main())
