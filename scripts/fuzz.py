"""The full fuzz campaign of issues #16 and #27: hostile scene files, SSP archives, `--set`
values and output folders, each case run as `crankfmu run CASE` with a time limit, and the
tally; and Ctrl-C at random moments.

    python scripts/fuzz.py [--seed 16] [--scenes 1000] [--ssp 300] [--set all|N|0]
                           [--out-cases 160] [--timeout 60] [--ctrl-c 20] [--work DIR]
                           [--fmus DIR]

Each case runs inside a worker process (`crankfmu.cli.main` in-process, so the interpreter and
FMU start-up are paid once per worker, not per case), with its own folder as working directory
and no --out (results go to results/<scene name>.csv, so a name that is a path would show).
A worker that does not report a case within --timeout seconds is killed (a hang) and replaced;
one that dies is a crash, and the case is run again alone in a fresh process (as a user runs
it): if it then ends cleanly, it counts as "crash in worker only". A worker is also replaced
after a case in which an FMU call failed: a Python exception inside a pythonfmu 0.7.0 FMU damages
the shared interpreter (a later garbage collection crashes), so one case's damage would
otherwise be counted against the next. Per case the tally counts:
    ok          exit 0                  error   exit 2 with "error: ..." (a clear refusal)
    traceback   any other exception     crash   the worker died (signal)    hang   timed out
    nonfinite   a written CSV holds nan or inf, or a sidecar NaN or Infinity
    outside     a file appeared outside the case's results/ folder, or at an evil path
The "out" family (tests/support/fuzz/outputs.py) runs with hostile output folders: files may
appear only under the case's output folder, and the files it keeps (a FIFO, a link, a user's
file) must stay as they were ("outside" counts both).
--ctrl-c N sends SIGINT N times at a random moment of crankfmu's imports, run or exit handlers
(tests/support/fuzz/ctrl_c.py): each must exit 130, say "interrupted", print no traceback, and
leave whatever it wrote whole.
"""
from __future__ import annotations

import argparse
import collections
import json
import os
import random
import select
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import traceback
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # a script of the checkout: its case generators are tests.support.fuzz
MARK = "@@fuzz@@ "


# -- worker: runs cases read from stdin, one JSON line each, reports on stdout -------------------
def worker() -> None:
    import contextlib
    import io
    import warnings

    import faulthandler

    from crankfmu.cli import main
    warnings.simplefilter("ignore")
    if os.environ.get("CRANKFMU_FUZZ_FAULTS"):  # where a crash happened: a file to read later
        faulthandler.enable(open(os.environ["CRANKFMU_FUZZ_FAULTS"], "a"), all_threads=False)
    report = os.fdopen(os.dup(1), "w", buffering=1)
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, 1)  # what the FMUs print at C level
    for line in sys.stdin:
        case = json.loads(line)
        os.chdir(case["cwd"])
        err = io.StringIO()
        outcome, detail = "ok", ""
        try:
            with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
                status = main(case["argv"])
            outcome = {0: "ok", 2: "error", 130: "interrupted"}.get(status, f"status {status}")
            detail = err.getvalue().strip()[-300:]
        except SystemExit as exc:  # argparse: a usage error, exit 2
            outcome = "error" if exc.code == 2 else f"exit {exc.code}"
            detail = err.getvalue().strip()[-300:]
        except BaseException:  # noqa: BLE001  (that is what is counted)
            outcome, detail = "traceback", traceback.format_exc()[-1500:]
        report.write(MARK + json.dumps({"id": case["id"], "outcome": outcome,
                                        "detail": detail}) + "\n")


class Worker:
    tmp: Path | None = None  # the workers' TMPDIR: what a killed worker leaves goes with --work

    def __init__(self):
        env = dict(os.environ, **({"TMPDIR": str(self.tmp)} if self.tmp else {}))
        self.proc = subprocess.Popen([sys.executable, __file__, "--worker"], stdin=subprocess.PIPE,
                                     stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
                                     bufsize=1, cwd=ROOT, start_new_session=True, env=env)

    def run(self, case: dict, timeout: float) -> dict:
        self.proc.stdin.write(json.dumps(case) + "\n")
        self.proc.stdin.flush()
        deadline = time.monotonic() + timeout
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                self.kill()
                return {"outcome": "hang", "detail": f"no answer in {timeout} s"}
            ready, _, _ = select.select([self.proc.stdout], [], [], left)
            if not ready:
                continue
            line = self.proc.stdout.readline()
            if not line:
                code = self.proc.wait()
                return {"outcome": "crash", "detail": f"worker died: status {code}"}
            if line.startswith(MARK):
                return json.loads(line[len(MARK):])

    def retire(self) -> None:
        """End of input: the worker exits and its atexit handlers remove its unpacked FMUs."""
        try:
            self.proc.stdin.close()
            self.proc.wait(timeout=20)
        except (OSError, subprocess.TimeoutExpired):
            self.kill()

    def kill(self) -> None:
        try:
            os.killpg(self.proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        self.proc.wait()

    def alive(self) -> bool:
        return self.proc.poll() is None


# -- checks after a case -------------------------------------------------------------------------
def _regular(path: Path) -> bool:
    """A regular file itself (not a FIFO a case made, not a link): safe to open and read."""
    return path.is_file() and not path.is_symlink()


def _nonfinite(folder: Path, kept: set[Path] = frozenset()) -> list[str]:
    """Written CSVs holding nan or inf, sidecars that are not strict JSON (the files a case
    made and keeps are the user's, not results)."""
    bad = []
    def written(path: Path) -> bool:
        return _regular(path) and path not in kept
    for csv in filter(written, folder.rglob("*.csv")):
        with open(csv, errors="replace") as f:
            f.readline()
            for line in f:
                low = line.lower()
                if "nan" in low or "inf" in low:
                    bad.append(str(csv))
                    break
    def refuse(constant):
        raise ValueError(constant)
    for sidecar in filter(written, folder.rglob("*.json")):
        try:  # strict JSON: NaN, Infinity and -Infinity are not numbers there
            json.loads(sidecar.read_text(errors="replace"), parse_constant=refuse)
        except ValueError:
            bad.append(str(sidecar))
    return bad


def _outside(case_dir: Path, before: set[str], case: dict, kept_before: dict) -> list[str]:
    """Files that appeared outside the case's output folder (default work/results), evil paths
    that exist, and kept files that changed (kind, inode or bytes)."""
    from tests.support.fuzz.scenes import snapshot
    work = case_dir / "work"
    allowed = os.path.normpath(work / case.get("out", "results")) + os.sep
    now = {str(p.relative_to(case_dir)) for p in case_dir.rglob("*")}
    new = [p for p in now - before  # under the output folder, or a folder on the way to it
           if not ((os.path.normpath(case_dir / p) + os.sep).startswith(allowed) or
                   allowed.startswith(os.path.normpath(case_dir / p) + os.sep))]
    for e in case.get("evil", []):
        path = Path(e) if os.path.isabs(e) else work / e
        try:
            if path.exists() and not str(path.resolve()).startswith(str((work / "results")
                                                                         .resolve())):
                new.append(str(path))
        except OSError:
            pass
    after = snapshot(work, case.get("kept", []))
    new += [f"changed: {name}" for name in after if after[name] != kept_before[name]]
    return new


outcomes: list[dict] = []


def run_cases(cases: list[dict], work: Path, fmus: Path, timeout: float, tally, failures,
              label: str) -> None:
    w = None
    start = time.monotonic()
    for k, case in enumerate(cases):
        case_dir = work / case["id"]
        from tests.support.fuzz.scenes import snapshot, write_case
        write_case({**case, "files": {f"work/{n}": d for n, d in case["files"].items()}},
                   case_dir)
        before = {str(p.relative_to(case_dir)) for p in case_dir.rglob("*")}
        kept_before = snapshot(case_dir / "work", case.get("kept", []))
        argv = ["run", case["scene"], "--fmus", str(fmus), "--no-progress", *case.get("args", [])]
        if w is None or not w.alive():
            w = Worker()
        result = w.run({"id": case["id"], "argv": argv, "cwd": str(case_dir / "work")}, timeout)
        outcome = result["outcome"]
        if outcome in ("hang", "crash"):
            w = None
        if outcome == "crash":  # the same case alone, as a user runs it: one process
            fresh = subprocess.run([sys.executable, "-m", "crankfmu", *argv], cwd=case_dir / "work",
                                   capture_output=True, text=True, timeout=timeout)
            result["detail"] += f"; alone in a fresh process: status {fresh.returncode}: " \
                                f"{fresh.stderr.strip()[-200:]}"
            if fresh.returncode in (0, 2) and "Traceback" not in fresh.stderr:
                outcome = "crash in worker only"
        elif w is not None and "FMU call failed" in result.get("detail", ""):
            w.retire()  # pythonfmu 0.7.0's error path damaged this interpreter: a fresh worker
            w = None
        checks = []
        if _nonfinite(case_dir, {case_dir / "work" / k for k in case.get("kept", [])}):
            checks.append("nonfinite")
        if _outside(case_dir, before, case, kept_before):
            checks.append("outside")
        tally[case["family"]][outcome] += 1
        for c in checks:
            tally[case["family"]][c] += 1
        outcomes.append({"id": case["id"], "kind": case["kind"], "outcome": outcome,
                         "detail": result.get("detail", "")[-300:]})
        if outcome not in ("ok", "error") or checks:
            failures.append({"id": case["id"], "kind": case["kind"], "outcome": outcome,
                             "checks": checks, "detail": result.get("detail", "")[-600:]})
        shutil.rmtree(case_dir, ignore_errors=True)
        if (k + 1) % 50 == 0:
            print(f"  {label}: {k + 1}/{len(cases)} in {time.monotonic() - start:.0f} s",
                  flush=True)
    if w is not None:
        w.retire()


# -- Ctrl-C ----------------------------------------------------------------------------------------
def ctrl_c_campaign(n: int, fmus: Path, work: Path, seed: int) -> dict:
    """n Ctrl-Cs at random moments of crankfmu's imports, run and exit handlers, in turn
    (tests/support/fuzz/ctrl_c.py): how many were clean, per phase."""
    from tests.support.fuzz.ctrl_c import campaign
    folder = work / "ctrl_c"
    folder.mkdir(exist_ok=True)
    results = collections.Counter()
    for t in campaign(n, seed, folder, fmus, ROOT):
        results[f"{t['phase']} {'clean' if t['clean'] else 'NOT clean'}"] += 1
        results["clean"] += t["clean"]
        if not t["clean"]:
            print(f"  ctrl-c in {t['phase']} after {t['delay']:.3f} s: status {t['status']}: "
                  f"{t['stderr'][-300:]}", flush=True)
    return dict(results)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--seed", type=int, default=16)
    ap.add_argument("--scenes", type=int, default=1000)
    ap.add_argument("--ssp", type=int, default=300)
    ap.add_argument("--set", dest="sets", default="all",
                    help="'all' (every parameter x 6 values), a number (a seeded sample), or 0")
    ap.add_argument("--timeout", type=float, default=60.0)
    ap.add_argument("--out-cases", type=int, default=160,
                    help="hostile output folders (tests/support/fuzz/outputs.py)")
    ap.add_argument("--ctrl-c", type=int, default=0)
    ap.add_argument("--work", type=Path, help="scratch folder (default: a new temp folder)")
    ap.add_argument("--fmus", type=Path, help="built FMUs (default: build all into --work)")
    ap.add_argument("--json", type=Path, help="write the tally and failures here")
    ap.add_argument("--models", help="comma list of FMU models for the --set family (default all)")
    args = ap.parse_args()
    if args.worker:
        worker()
        return 0
    if args.models:
        from crankfmu.models.catalog import FMU_MODELS
        unknown = [m for m in args.models.split(",") if m not in FMU_MODELS]
        if unknown:
            ap.error(f"--models: {', '.join(unknown)} not a catalog model; allowed: "
                     f"{', '.join(FMU_MODELS)}")
    work = args.work or Path(tempfile.mkdtemp(prefix="crankfmu-fuzz-"))
    work.mkdir(parents=True, exist_ok=True)
    fmus = args.fmus
    if fmus is None:
        from crankfmu.fmu.build import build_all
        fmus = work / "fmus"
        build_all(fmus)
    fmus = fmus.resolve()
    Worker.tmp = work / "tmp"
    Worker.tmp.mkdir(exist_ok=True)
    from tests.support.fuzz.overrides import override_cases
    from tests.support.fuzz.scenes import scene_cases
    from tests.support.fuzz.ssp import ssp_cases
    groups = []
    if args.scenes:
        groups.append(("scenes", scene_cases(args.seed, args.scenes)))
    if args.ssp:
        from crankfmu.system.load import load_scene
        from crankfmu.system.ssp_export import export_ssp
        from tests.support.fuzz.scenes import ROTOR
        (work / "rotor.toml").write_text(ROTOR)
        base = export_ssp(load_scene(work / "rotor.toml"), work / "rotor.ssp", fmus).read_bytes()
        groups.append(("ssp", ssp_cases(args.seed, args.ssp, base)))
    if args.out_cases:
        from tests.support.fuzz.outputs import output_cases
        groups.append(("out", output_cases(args.seed, args.out_cases)))
    if args.sets != "0":
        cases = override_cases(fmus, models=args.models.split(",") if args.models else None)
        if args.sets != "all":
            cases = random.Random(args.seed).sample(cases, min(int(args.sets), len(cases)))
        groups.append(("set", cases))
    tally = collections.defaultdict(collections.Counter)
    failures: list[dict] = []
    start = time.monotonic()
    for label, cases in groups:
        kinds = len({c["kind"].split("=")[0] if label != "set" else c["kind"] for c in cases})
        print(f"{label}: {len(cases)} cases, {kinds} kinds", flush=True)
        run_cases(cases, work / "cases", fmus, args.timeout, tally, failures, label)
    ctrl = ctrl_c_campaign(args.ctrl_c, fmus, work, args.seed) if args.ctrl_c else None
    print(f"\ntally (seed {args.seed}, {time.monotonic() - start:.0f} s, timeout "
          f"{args.timeout:g} s per case):")
    columns = ["ok", "error", "traceback", "crash", "hang", "nonfinite", "outside"]
    print(f"  {'family':8}" + "".join(f"{c:>11}" for c in columns) + f"{'other':>8}")
    for family, counts in tally.items():
        other = sum(v for k, v in counts.items() if k not in columns)
        print(f"  {family:8}" + "".join(f"{counts[c]:>11}" for c in columns) + f"{other:>8}")
    if ctrl:
        print(f"  ctrl-c x{args.ctrl_c}: {ctrl}")
    for f in failures[:40]:
        print(f"FAIL {f['id']} [{f['kind']}] {f['outcome']} {f['checks']}: "
              f"{f['detail'].strip().splitlines()[-1] if f['detail'].strip() else ''}")
    if args.json:
        args.json.write_text(json.dumps({"tally": tally, "ctrl_c": ctrl, "failures": failures,
                                         "outcomes": outcomes},
                                        indent=1))
    if not args.work:
        shutil.rmtree(work, ignore_errors=True)
    bad = sum(tally[f][c] for f in tally for c in ("traceback", "crash", "hang", "nonfinite",
                                                    "outside"))
    if ctrl and ctrl.get("clean", 0) < args.ctrl_c:
        bad += 1
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
