"""Each unit string has one spelling, FMI's (as in the modelDescriptions): `N.m`, `kg.m2`,
`rad/s`, `N(2/3)/m`; products with '.', powers as trailing digits, no spaces, no '^'. Collected
from every FMU's variable table, a run's and a reference's sidecar, the plots' axis labels and
the terminal output of compare and of the command-line help."""
from __future__ import annotations

import io
import json
import re
from contextlib import redirect_stdout

import numpy as np
import pytest

from tests.conftest import SCENARIOS

FACTOR = r"([A-Za-z]+[0-9.]*|1)(\([0-9/]+\))?"
FMI_UNIT = re.compile(rf"^(%|{FACTOR}([./]{FACTOR})*)$")
BRACKETED = re.compile(r"\[([^\[\]]*)\]")


def bad_units(units) -> list[str]:
    return sorted({u for u in units if not FMI_UNIT.match(u)})


def label_units(text: str) -> list[str]:
    """The [unit] parts of an axis label or a help text (`[master].step`: a table's key, and
    argparse's usage brackets are not units)."""
    return [u for u in BRACKETED.findall(text)
            if u and not u.startswith(("master", "analysis", "record", "inputs", "scene", "-"))
            and not u.endswith(" ...")]  # argparse's usage: [--opt V], [K_N ...]


def test_the_regex_itself():
    assert bad_units(["N.m", "kg.m2", "rad/s", "N(2/3)/m", "1", "kg/m3", "N.m.s/rad"]) == []
    assert bad_units(["N m", "kg m^2", "kg m$^2$", "N^(2/3)/m", "N/m^1.5"]) == \
        sorted(["N m", "kg m^2", "kg m$^2$", "N^(2/3)/m", "N/m^1.5"])


def test_units_in_the_fmus():
    from crankfmu.models.catalog import FMU_MODELS, physics_class
    from crankfmu.runtime.slave import variable_table
    units = [v.unit for m in FMU_MODELS for v in variable_table(physics_class(m)) if v.unit]
    assert len(units) > 100 and bad_units(units) == []


def test_units_in_sidecars_plots_and_terminal_output(tmp_path, fmu_dir):
    import crankfmu
    from crankfmu.commands.analyze import hammer_figure
    from crankfmu.studies.compare import Series, format_table, compare_table, overlay_figure

    run = crankfmu.simulate(SCENARIOS / "servo_press.toml", stop_time=0.05,
                            out=tmp_path, fmu_dir=fmu_dir)  # out: the folder
    ref = crankfmu.reference(SCENARIOS / "servo_press.toml", stop_time=0.05, rtol=1e-6,
                             out=tmp_path)
    found = []
    for sidecar in ("servo_press.json", "servo_press_reference.json"):
        units = json.loads((tmp_path / sidecar).read_text())["units"]
        assert set(units) == set(run.units)
        found += units.values()
    figures = [run.plot(), ref.plot()]
    t = np.linspace(0, 1, 200)
    s = {"crank_angle": 20 * t, "crank_speed": 20 + np.sin(9 * t), "drive_torque": np.cos(t),
         "drive_power": np.ones_like(t), "load_torque": t}
    a, b = Series("A", t, s, 0.1), Series("B", t, dict(s, crank_speed=s["crank_speed"] + 1), 0.1)
    figures.append(overlay_figure(a, b, "x"))
    col = {"time": t, "motor.flange_tau": t, "hammer.M_load": t, "hammer.w_crank": t,
           "hammer.n_impacts": np.floor(3 * t), "hammer.V_impact": t, "hammer.P_peak": t + 1,
           "hammer.T_peak": t, "hammer.phi": t}
    figures.append(hammer_figure({"run": col}))
    labels = [ax.get_xlabel() for f in figures for ax in f.axes] + \
        [ax.get_ylabel() for f in figures for ax in f.axes]
    for text in labels:
        found += label_units(text)
    table = format_table(compare_table(a, b), "A", "B")
    found += [line[28:35].strip() for line in table.splitlines()[2:]]
    from crankfmu.cli import build_parser
    parser = build_parser()
    with redirect_stdout(io.StringIO()) as out:
        for command in ("run", "reference", "accuracy", "compare", "sweep", "analyze impact"):
            with pytest.raises(SystemExit):
                parser.parse_args(command.split() + ["--help"])
    found += label_units(out.getvalue())
    assert "N.m" in found and "rad/s" in found and "kg.m2" in found
    assert bad_units(found) == [], bad_units(found)
