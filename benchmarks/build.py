"""What building FMUs costs: the whole catalog in one process, and one FMU in a fresh process
with the compiled launcher kept in the cache folder against compiling it.

    python benchmarks/build.py [--repeat 3]

(a) every catalog model's FMI 2.0 and FMI 3.0 FMU (build_all, build_all3 without fmpy validate:
what tests/conftest.py builds at the session's start), each repeat in a fresh process; CPU of
that process for the builds alone (its imports before them excluded) and of the C compiler it
runs (children).
(b) `build_fmu("DcServoMotor", ...)` in a fresh process (interpreter, imports and build):
CPU of the whole process tree, with a cache folder that holds the launcher (compiled by an
untimed first run) and with none (CRANKFMU_CACHE_DIR="": compiled each time), alternating.
Medians of --repeat runs; CPU time, as wall times on a shared machine are noisy.
"""
from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

from jobs import timed  # benchmarks/, beside this file: CPU of a process tree

ROOT = Path(__file__).resolve().parents[1]
CATALOG = """
import contextlib, io, resource, sys, tempfile
from pathlib import Path
from crankfmu.fmu.build import build_all
from crankfmu.fmu.build_fmi3 import build_all3
before = resource.getrusage(resource.RUSAGE_SELF)
with contextlib.redirect_stdout(io.StringIO()):
    dest = Path(tempfile.mkdtemp(dir=sys.argv[1]))
    build_all(dest, check=False)
    build_all3(dest, check=False)
after = resource.getrusage(resource.RUSAGE_SELF)
children = resource.getrusage(resource.RUSAGE_CHILDREN)
print(after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime,
      children.ru_utime + children.ru_stime)
"""
ONE = "import sys; from pathlib import Path; from crankfmu.fmu.build import build_fmu; " \
      "build_fmu('DcServoMotor', Path(sys.argv[1]))"


def environment(cache: str) -> dict:
    env = {**os.environ, "CRANKFMU_CACHE_DIR": cache}
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(ROOT / "sources"),
                                                      env.get("PYTHONPATH")]))
    return env


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    repeat = parser.parse_args().repeat
    with tempfile.TemporaryDirectory() as tmp:
        cache = Path(tmp, "cache")
        cache.mkdir(mode=0o700)
        env = environment(str(cache))
        runs = [subprocess.run([sys.executable, "-c", CATALOG, tmp], env=env, check=True,
                               capture_output=True, text=True).stdout.split()
                for _ in range(repeat)]
        builds, compilers = (statistics.median(float(r[k]) for r in runs) for k in (0, 1))
        print(f"(a) the catalog's 18 FMUs in one process: median {builds:.2f} s of CPU "
              f"building, {compilers:.2f} s in the C compiler ({repeat} runs)")
        subprocess.run([sys.executable, "-c", ONE, str(Path(tmp, "warm"))], env=env, check=True)
        kept, compiled = [], []
        for k in range(repeat):
            kept.append(timed([sys.executable, "-c", ONE, str(Path(tmp, f"k{k}"))], env)[1])
            compiled.append(timed([sys.executable, "-c", ONE, str(Path(tmp, f"c{k}"))],
                                  environment(""))[1])
        a, b = statistics.median(kept), statistics.median(compiled)
        print(f"(b) DcServoMotor in a fresh process: median CPU {a:.2f} s with the launcher "
              f"kept, {b:.2f} s compiling it; ratio {a / b:.2f} ({repeat} runs each)")


if __name__ == "__main__":
    main()
