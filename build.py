"""Build every crankfmu FMU into fmus/ and check each with fmpy validate: python build.py"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent / "sources"))

from crankfmu.fmi.build import main  # noqa: E402

if __name__ == "__main__":
    main()
