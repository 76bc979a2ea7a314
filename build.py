"""Build every crankfmu FMU and check each with fmpy validate: python build.py

FMI 2.0 Co-Simulation into fmus/, FMI 3.0 Co-Simulation + Model Exchange into fmus/fmi3/
(`--fmi 2|3|both`, `--effects` for FMI 3.0's Model Exchange states, `--portable`: see
`python build.py --help`).

Builds from this tree's sources/ (and says so). If another crankfmu is installed (pip install .,
not -e), `crankfmu run` would rebuild the FMUs from that installed copy ("sources changed"):
this script warns when the two differ, so a source edit is not silently thrown away."""
import importlib.util
import sys
from pathlib import Path

TREE = Path(__file__).resolve().parent
_installed = importlib.util.find_spec("crankfmu")  # before this tree goes on sys.path
sys.path.insert(0, str(TREE / "sources"))

from crankfmu.system.wiring import tree_differences  # noqa: E402
from crankfmu.fmu.build_fmi3 import main  # noqa: E402

if __name__ == "__main__":
    print(f"building from the sources at {TREE / 'sources' / 'crankfmu'}")
    if _installed is not None and _installed.origin:
        package = Path(_installed.origin).resolve().parent
        differ = tree_differences(package)
        if differ:
            print(f"warning: the installed crankfmu at {package} differs from this tree "
                  f"({', '.join(differ[:3])}{' ...' if len(differ) > 3 else ''}): `crankfmu run` "
                  f"will rebuild the FMUs from the installed copy; install this tree editable: "
                  f"pip install -e {TREE}", file=sys.stderr)
    main()
