"""SSP export and import: the archive is valid SSP 1.0 for fmpy's schemas, fmpy/libcosim/ecos
load and run it with the scene's parameters, and `crankfmu run X.ssp` reproduces the TOML run bit
for bit.
"""
from __future__ import annotations

import copy
import csv
import math
import zipfile
from pathlib import Path

import pytest
from lxml import etree

from crankfmu.cosim.runner import RunOptions, run_scene
from crankfmu.system.scene import SceneError
from crankfmu.system.load import load_scene
from crankfmu.system.scene import InputSignal
from crankfmu.system.ssp_export import export_ssp, fmpy_parameter_set
from crankfmu.system.ssp_load import load_ssp
from crankfmu.system.ssp_export import NS, SSD_NAME

from tests.conftest import SCENARIOS

STOP = 0.05  # s: 50 steps of 1 ms, enough to pass the start-up transient's first 2 rad of motor


@pytest.fixture(scope="module")
def scene():
    """The servo press scene, cut short, with one parameter off its FMU default (J_rotor) so a
    tool that ignored the bindings would show it."""
    s = load_scene(SCENARIOS / "servo_press.toml")
    s.stop_time = STOP
    s.components["motor"].parameters["J_rotor"] = 0.08
    return s


@pytest.fixture(scope="module")
def ssp(scene, fmu_dir, tmp_path_factory) -> Path:
    return export_ssp(scene, tmp_path_factory.mktemp("ssp") / "servo.ssp", fmu_dir)


def _ssd(path: Path):
    with zipfile.ZipFile(path) as zf:
        return etree.fromstring(zf.read(SSD_NAME))


def _csv_rows(path: Path) -> list[list[str]]:
    with open(path, newline="") as f:
        return list(csv.reader(f))


# -- the file ------------------------------------------------------------------------------------
def test_fmpy_reads_and_validates_against_the_ssp_schemas(ssp, tmp_path):
    from fmpy.ssp import ssd as fmpy_ssd
    schema_dir = Path(fmpy_ssd.__file__).parent / "schema"
    assert (schema_dir / "SystemStructureDescription.xsd").is_file()
    system = fmpy_ssd.read_ssd(str(ssp), validate=True).system
    assert [(c.name, c.source) for c in system.elements] == [
        ("motor", "resources/DcServoMotor.fmu"), ("press", "resources/StephensonPress.fmu")]
    # the validation has teeth: the same archive with one bad connector kind is rejected
    bad = _rewrite(ssp, tmp_path / "bad.ssp", 'kind="output"', 'kind="outlet"', count=1)
    with pytest.raises(Exception, match="kind"):
        fmpy_ssd.read_ssd(str(bad), validate=True)
    # the 1.0 SSD schema skips inline parameter sets (processContents lax): check them with
    # the parameter-values schema fmpy also ships
    schema = etree.XMLSchema(file=str(schema_dir / "SystemStructureParameterValues.xsd"))
    psets = list(_ssd(ssp).iter(f"{{{NS['ssv']}}}ParameterSet"))
    assert len(psets) == 2
    for pset in psets:
        schema.assertValid(etree.fromstring(etree.tostring(pset)))


def test_ssd_holds_the_scene(scene, ssp):
    root = _ssd(ssp)
    experiment = root.find("ssd:DefaultExperiment", NS)
    assert (float(experiment.get("startTime")), float(experiment.get("stopTime"))) == (0.0, STOP)
    links = [(c.get("startElement") + "." + c.get("startConnector"),
              c.get("endElement") + "." + c.get("endConnector"))
             for c in root.iterfind("ssd:System/ssd:Connections/ssd:Connection", NS)]
    assert links == [(c.source, c.target) for c in scene.connections]
    for comp in root.iterfind("ssd:System/ssd:Elements/ssd:Component", NS):
        name = comp.get("name")
        bound = {p.get("name"): p[0].get("value")
                 for p in comp.iterfind(".//ssv:Parameter", NS)}
        for pname, value in scene.components[name].parameters.items():
            assert float(bound[pname]) == value  # repr text reads back to the same float
        effects = {k[len("effect_"):]: v == "true" for k, v in bound.items()
                   if k.startswith("effect_")}
        assert {e for e, on in effects.items() if on} == set(scene.components[name].effects)
        assert len(effects) > len(scene.components[name].effects)  # the off ones are bound too
        kinds = {c.get("name"): c.get("kind") for c in comp.iterfind(".//ssd:Connector", NS)}
        assert "u" not in kinds  # unconnected input: bound, no connector (see export.py)
    motor = root.find("ssd:System/ssd:Elements/ssd:Component[@name='motor']", NS)
    u = motor.find(".//ssv:Parameter[@name='u']/ssv:Real", NS)
    assert (float(u.get("value")), u.get("unit")) == (220.0, "V")


def test_export_of_the_loaded_archive_gives_the_same_bytes(ssp, fmu_dir, tmp_path):
    again = export_ssp(load_ssp(ssp), tmp_path / "again.ssp", fmu_dir)
    assert again.read_bytes() == ssp.read_bytes()


def test_time_table_input_goes_to_the_annotation(scene, fmu_dir, tmp_path):
    s = copy.deepcopy(scene)
    s.inputs["motor.u"] = InputSignal("motor.u", [0.0, 0.02, 0.05], [100.0, 220.0, 200.0], "step")
    loaded = load_ssp(export_ssp(s, tmp_path / "table.ssp", fmu_dir))
    signal = loaded.inputs["motor.u"]
    assert (signal.times, signal.values, signal.interpolation) == \
        ([0.0, 0.02, 0.05], [100.0, 220.0, 200.0], "step")
    u = _ssd(tmp_path / "table.ssp").find(".//ssv:Parameter[@name='u']/ssv:Real", NS)
    assert float(u.get("value")) == 100.0  # what other tools hold it at: the value at t = 0


def test_cli_export_matches_the_function(ssp, fmu_dir, tmp_path, capsys):
    from crankfmu.cli import main
    out = tmp_path / "servo_press.ssp"  # --out DIR: <scene name>.ssp
    assert main(["export-ssp", str(SCENARIOS / "servo_press.toml"), "--out", str(tmp_path),
                 "--fmus", str(fmu_dir), "--stop-time", str(STOP),
                 "--set", "motor.J_rotor=0.08"]) == 0
    assert out.read_bytes() == ssp.read_bytes()
    assert "note: master settings" in capsys.readouterr().out


def test_ssp_without_crankfmu_annotation(ssp, tmp_path):
    """An SSP from another tool: crankfmu's default master at the OSP step, and every output
    that has a connector recorded."""
    with zipfile.ZipFile(ssp) as zf:
        root = etree.fromstring(zf.read(SSD_NAME))
    annotation = root.find("ssd:DefaultExperiment/ssd:Annotations/ssc:Annotation"
                           "[@type='org.crankfmu.scene']", NS)
    annotation.getparent().remove(annotation)
    text = etree.tostring(root).decode()
    foreign = _with_ssd(ssp, tmp_path / "foreign.ssp", text)
    scene = load_scene(foreign)
    assert scene.master.step == 1e-3 and scene.master.algorithm == "gauss-seidel"
    assert scene.master.order == [] and scene.record_interval is None
    assert scene.record == ["motor.flange_tau", "motor.flange_J", "motor.i_a", "press.flange_w",
                            "press.flange_phi", "press.phi", "press.w_crank", "press.slider_s",
                            "press.F5"]
    assert scene.components["motor"].parameters["J_rotor"] == 0.08


# -- crankfmu runs it back -----------------------------------------------------------------------
def test_run_ssp_is_bit_identical_to_run_toml(scene, ssp, fmu_dir, tmp_path):
    from crankfmu.cli import main
    toml_csv = run_scene(copy.deepcopy(scene), RunOptions(out=tmp_path / "toml.csv",
                                                          fmu_dir=fmu_dir, progress=False)).csv
    assert main(["run", str(ssp), "--out", str(tmp_path / "ssp"), "--no-progress"]) == 0
    rows = _csv_rows(tmp_path / "ssp" / f"{scene.name}.csv")
    assert rows == _csv_rows(toml_csv)  # same text: same doubles, same record list and times
    assert len(rows) == 1 + round(STOP / scene.master.step) + 1
    assert rows[0][1:] == scene.record


def test_loaded_scene_keeps_master_and_record(scene, ssp):
    loaded = load_ssp(ssp)
    assert loaded.master == scene.master
    assert (loaded.record, loaded.record_interval) == (scene.record, scene.record_interval)
    assert (loaded.name, loaded.description) == (scene.name, scene.description)


# -- other tools load it -------------------------------------------------------------------------
@pytest.fixture(scope="module")
def jacobi_reference(scene, fmu_dir, tmp_path_factory):
    """crankfmu's Jacobi master on the scene: the algorithm libcosim's and ecos's fixed-step
    masters implement, so they must give the same numbers."""
    s = copy.deepcopy(scene)
    s.master.algorithm = "jacobi"
    s.record = ["press.flange_w", "press.phi", "motor.flange_tau", "motor.i_a", "motor.flange_J"]
    out = tmp_path_factory.mktemp("jacobi") / "jacobi.csv"
    rows = _csv_rows(run_scene(s, RunOptions(out=out, fmu_dir=fmu_dir, progress=False)).csv)
    assert float(rows[-1][0]) == pytest.approx(STOP, abs=1e-12)
    return dict(zip(rows[0][1:], map(float, rows[-1][1:])))


def _agree(values: dict, reference: dict) -> None:
    # 1e-9 relative: same algorithm on the same FMUs; what remains is the last bits of time
    # accumulation in the host (the cross-importer criterion)
    for name, ref in reference.items():
        assert math.isclose(values[name], ref, rel_tol=1e-9), (name, values[name], ref)


def test_libcosim_runs_the_archive_with_its_bindings(ssp, jacobi_reference):
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimObserver import CosimObserver

    execution = CosimExecution.from_ssp_file(str(ssp))  # step from the OSP annotation
    observer = CosimObserver.create_last_value()
    execution.add_observer(observer)
    assert execution.simulate_until(round(STOP * 1e9))
    slaves = {s.name.decode(): s.index for s in execution.slave_infos()}

    def real(ref: str) -> float:
        comp, var = ref.split(".")
        refs = {v.name.decode(): v.reference for v in execution.slave_variables(slaves[comp])}
        return observer.last_real_values(slaves[comp], [refs[var]])[0]

    values = {ref: real(ref) for ref in jacobi_reference}
    assert values["motor.flange_J"] == 0.08  # J_rotor bound (FMU default 0.05)
    _agree(values, jacobi_reference)


def test_ecos_runs_the_archive_with_its_bindings(scene, ssp, jacobi_reference):
    from tests.support.importer_support import require_ecospy
    require_ecospy()
    from ecospy.EcosSimulation import EcosSimulation

    sim = EcosSimulation(step_size=scene.master.step, ssp_path=str(ssp))
    try:
        sim.init(0.0, scene.name)  # ecos applies a parameter set only when named
        assert sim.get_bool("press::effect_gravity")  # FMU default false
        # step(n), not step_until(STOP): ecos's step_until stops one step short when the
        # accumulated time lands a few ulps above STOP
        sim.step(round(STOP / scene.master.step))
        values = {ref: sim.get_real(ref.replace(".", "::")) for ref in jacobi_reference}
        _agree(values, jacobi_reference)
    finally:
        sim.terminate()
        sim.free()


def test_fmpy_simulate_ssp_runs_with_the_bindings(ssp):
    from fmpy.ssp.simulation import simulate_ssp

    # fmpy's runner ignores the SSD's bindings: they are passed as its parameter_set
    result = simulate_ssp(str(ssp), stop_time=0.01, step_size=1e-3,
                          parameter_set=fmpy_parameter_set(ssp))
    assert len(result) == 10
    assert result["motor.flange_J"][-1] == 0.08  # J_rotor + J_flywheel (0): the bound value
    assert result["press.flange_w"][-1] > 0  # 220 V accelerates the press from rest


# -- errors name the file and the element --------------------------------------------------------
def _with_ssd(src: Path, dst: Path, ssd_text: str) -> Path:
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dst, "w") as zout:
        for item in zin.infolist():
            zout.writestr(item, ssd_text.encode() if item.filename == SSD_NAME else zin.read(item))
    return dst


def _rewrite(src: Path, dst: Path, old: str, new: str, count: int = -1,
             drop: str | None = None) -> Path:
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dst, "w") as zout:
        for item in zin.infolist():
            if item.filename == drop:
                continue
            data = zin.read(item)
            if item.filename == SSD_NAME:
                text = data.decode()
                assert old in text
                data = text.replace(old, new, count).encode()
            zout.writestr(item, data)
    return dst


@pytest.mark.parametrize("old, new, drop, key, message", [
    ('kind="output"', 'kind="outlet"', None, "SystemStructure.ssd line", "not a valid SSP 1.0"),
    ('<ssv:Parameter name="k_phi">', '<ssv:Parameter name="k_fi">', None,
     '<ssv:Parameter name="k_fi">', "motor has no variable 'k_fi'"),
    ('endConnector="flange_tau"', 'endConnector="flange_torque"', None, "<ssd:Connection>",
     "endConnector 'flange_torque' is not a connector of press"),
    ('stopTime="0.05"', "", None, "stopTime", "required"),
    ('unit="V"/>', 'unit="kV"/>', None, '<ssv:Parameter name="u">', "no unit conversion"),
    ("<ssd:System ", "<ssd:System ", "resources/StephensonPress.fmu",
     '<ssd:Component name="press">', "not in the archive"),
    ("<ssd:Connections>", "<ssd:Connections", None, "SystemStructure.ssd line",
     "not well-formed XML"),
])
def test_malformed_ssp_errors(ssp, tmp_path, old, new, drop, key, message):
    bad = _rewrite(ssp, tmp_path / "bad.ssp", old, new, count=1, drop=drop)
    with pytest.raises(SceneError) as err:
        load_scene(bad)
    assert str(err.value).startswith(f"{bad}: ")
    assert key in err.value.key and message in str(err.value), str(err.value)


def test_not_an_archive_and_no_ssd(tmp_path):
    text = tmp_path / "scene.ssp"
    text.write_text("[scene]\n")
    with pytest.raises(SceneError, match="not a zip archive"):
        load_scene(text)
    empty = tmp_path / "empty.ssp"
    with zipfile.ZipFile(empty, "w") as zf:
        zf.writestr("resources/x.txt", "")
    with pytest.raises(SceneError, match=f"{SSD_NAME}: missing from the archive"):
        load_scene(empty)
