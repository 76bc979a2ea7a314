"""Hostile SSP archives: seeded mutations of a small exported archive (the rotor scene), of 40
kinds. `ssp_cases(seed, n, base)` gives n cases (kinds in turn), each a dict with `files`
({relative path: bytes | None (a folder)}) and `scene` (the archive to run)."""
from __future__ import annotations

import io
import random
import re
import zipfile

SSD = "SystemStructure.ssd"
SSV_NS = "http://ssp-standard.org/SSP1/SystemStructureParameterValues"


def _members(base: bytes) -> dict[str, bytes]:
    with zipfile.ZipFile(io.BytesIO(base)) as zf:
        return {n: zf.read(n) for n in zf.namelist()}


def _zip(members: dict[str, bytes], store_fmus: bool = True) -> bytes:
    """The members deflated, but for the FMUs, stored as export-ssp stores them (an FMU is a
    zip already: deflating its 400 kB again took 20 ms a case)."""
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as zf:
        for name, data in members.items():
            stored = store_fmus and name.endswith(".fmu")
            zf.writestr(name, data, zipfile.ZIP_STORED if stored else zipfile.ZIP_DEFLATED)
    return buf.getvalue()


def _ssd_edit(base: bytes, change) -> bytes:
    m = _members(base)
    m[SSD] = change(m[SSD].decode()).encode()
    return _zip(m)


def _fmu_with(fmu: bytes, change) -> bytes:
    m = _members(fmu)
    m["modelDescription.xml"] = change(m["modelDescription.xml"].decode()).encode()
    return _zip(m)


def _external_ssv(base: bytes, ssv: bytes | None, size_pad: int = 0) -> bytes:
    m = _members(base)
    text = m[SSD].decode()
    start = text.index('<ssd:ParameterBinding type="application/x-ssp-parameter-set">')
    end = text.index("</ssd:ParameterBinding>", start) + len("</ssd:ParameterBinding>")
    m[SSD] = (text[:start] + '<ssd:ParameterBinding type="application/x-ssp-parameter-set" '
              'source="resources/p.ssv"/>' + text[end:]).encode()
    if ssv is not None:
        m["resources/p.ssv"] = ssv + b"<!--" + b"x" * size_pad + b"-->" if size_pad else ssv
    return _zip(m)


def _ssv(value: str, doctype: str = "") -> bytes:
    return (f'<?xml version="1.0"?>\n{doctype}<ssv:ParameterSet xmlns:ssv="{SSV_NS}" '
            f'version="1.0" name="p"><ssv:Parameters><ssv:Parameter name="J"><ssv:Real '
            f'value="{value}"/></ssv:Parameter></ssv:Parameters></ssv:ParameterSet>').encode()


def _sub(pattern, repl, count=1):
    return lambda t: re.sub(pattern, repl, t, count=count)


LAUGHS = ('<!DOCTYPE lolz [<!ENTITY lol "lol"><!ENTITY lol1 "&lol;&lol;&lol;&lol;&lol;&lol;'
          '&lol;&lol;&lol;&lol;"><!ENTITY lol2 "&lol1;&lol1;&lol1;&lol1;&lol1;&lol1;&lol1;'
          '&lol1;&lol1;&lol1;"><!ENTITY lol3 "&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;'
          '&lol2;&lol2;">]>\n')


def ssp_cases(seed: int, n: int, base: bytes, skip=()) -> list[dict]:
    rng = random.Random(seed)
    members = _members(base)
    fmu_name = "resources/Rotor.fmu"
    fmu = members[fmu_name]

    def with_fmu(data: bytes, store: bool = True) -> bytes:
        m = dict(members)
        m[fmu_name] = data
        return _zip(m, store)

    kinds = {
        "not_zip": lambda: bytes(rng.randrange(256) for _ in range(rng.randrange(0, 4096))),
        "truncated_zip": lambda: base[:rng.randrange(1, len(base))],
        "empty_zip": lambda: _zip({}),
        "missing_ssd": lambda: _zip({k: v for k, v in members.items() if k != SSD}),
        "ssd_garbage": lambda: _zip({**members, SSD: bytes(rng.randrange(256)
                                                           for _ in range(2000))}),
        "ssd_non_utf8": lambda: _zip({**members, SSD: members[SSD].replace(
            b'name="rotor"', b'name="r\xff\xfer"', 1)}),
        "ssd_billion_laughs": lambda: _ssd_edit(base, lambda t: t.replace(
            "<ssd:SystemStructureDescription", LAUGHS + "<ssd:SystemStructureDescription", 1)
            .replace('name="rotor"', 'name="&lol3;"', 1)),
        "ssd_external_entity": lambda: _ssd_edit(base, lambda t: t.replace(
            "<ssd:SystemStructureDescription",
            '<!DOCTYPE x [<!ENTITY e SYSTEM "file:///etc/passwd">]>\n'
            "<ssd:SystemStructureDescription", 1).replace('name="rotor"', 'name="&e;"', 1)),
        "ssd_huge": lambda: _ssd_edit(base, lambda t: t.replace(
            "</ssd:SystemStructureDescription>", "<!--" + "x" * (20 << 20) + "-->"
            "</ssd:SystemStructureDescription>")),
        "fmu_entry_huge": lambda: with_fmu(fmu + b"\0" * (300 << 20), store=False),  # deflated
        "fmu_not_zip": lambda: with_fmu(b"not an fmu"),
        "fmu_md_doctype": lambda: with_fmu(_fmu_with(fmu, lambda t: t.replace(
            "<fmiModelDescription", '<!DOCTYPE x [<!ENTITY e "e">]>\n<fmiModelDescription', 1))),
        "fmu_md_missing": lambda: with_fmu(_zip({k: v for k, v in _members(fmu).items()
                                                 if k != "modelDescription.xml"})),
        "fmu_md_garbage": lambda: with_fmu(_fmu_with(fmu, lambda t: t[:len(t) // 2])),
        "source_traversal": lambda: _ssd_edit(base, lambda t: t.replace(
            'source="resources/Rotor.fmu"', 'source="%s"' % rng.choice(
                ["../../etc/passwd", "/etc/passwd", "http://example.invalid/x.fmu",
                 "resources/../../x.fmu", "file:///etc/passwd", "resources/"]), 1)),
        "source_missing": lambda: _ssd_edit(base, lambda t: t.replace(
            'source="resources/Rotor.fmu"', 'source="resources/Nope.fmu"', 1)),
        "ssd_name_path": lambda: _ssd_edit(base, lambda t: t.replace(
            'name="rotor"', 'name="%s"' % rng.choice(
                ["/tmp/crankfmu-fuzz-evil-ssp", "../evil-ssp", "x" * 5000, ".hidden"]), 1)),
        "component_name_bad": lambda: _ssd_edit(base, lambda t: t.replace(
            '"r1"', '"%s"' % rng.choice(["a.b", "../x", "", "r 1"]))),
        "duplicate_component": lambda: _ssd_edit(base, lambda t: t.replace(
            '<ssd:Component name="r2"', '<ssd:Component name="r1"', 1)),
        "connection_unknown_element": lambda: _ssd_edit(base, _sub(
            'endElement="r2"', 'endElement="ghost"')),
        "connection_unknown_connector": lambda: _ssd_edit(base, _sub(
            'endConnector="flange_w"', 'endConnector="nope"')),
        "parameter_nonfinite": lambda: _ssd_edit(base, _sub(
            r'<ssv:Real value="[^"]*"', '<ssv:Real value="%s"' % rng.choice(
                ["NaN", "INF", "-INF", "1e999", "-0"]))),
        "parameter_text": lambda: _ssd_edit(base, _sub(
            r'<ssv:Real value="[^"]*"', '<ssv:Real value="abc"')),
        "parameter_hostile_number": lambda: _ssd_edit(base, _sub(
            r'<ssv:Real value="[^"]*"', '<ssv:Real value="%s"' % rng.choice(
                ["0", "-1", "1e300", "-1e300", "1e-300"]))),
        "boolean_bad": lambda: _ssd_edit(base, _sub(
            r'<ssv:Real value="[^"]*"[^/]*/>', '<ssv:Boolean value="maybe"/>')),
        "unit_mismatch": lambda: _ssd_edit(base, _sub(r'unit="kg.m2"', 'unit="g"')),
        "stop_time_bad": lambda: _ssd_edit(base, _sub(
            r'stopTime="[^"]*"', rng.choice(['stopTime="INF"', 'stopTime="NaN"',
                                            'stopTime="-1"', 'stopTime="1e308"', '']))),
        "master_bad": lambda: _ssd_edit(base, _sub(
            'step="0.001"', 'step="%s"' % rng.choice(["-1", "1e-300", "NaN", "abc", "INF"]))),
        "master_limits_bad": lambda: _ssd_edit(base, _sub(
            "<crankfmu:Master ", "<crankfmu:Master %s " % rng.choice(
                ['max_steps="99999999999999999999999"', 'max_steps="0"',
                 'max_iterations="1000000000"']))),
        "master_algorithm_bad": lambda: _ssd_edit(base, _sub(
            'algorithm="gauss-seidel"', 'algorithm="%s"' % rng.choice(["rk4", "", "../x"]))),
        "master_int_bad": lambda: _ssd_edit(base, _sub(
            'extrapolation="0"', 'extrapolation="%s"' % rng.choice(
                ["99999999999999999999", "-1", "1.5", "x"]))),
        "order_duplicate": lambda: _ssd_edit(base, _sub(
            '<crankfmu:Order component="r2"/>', '<crankfmu:Order component="r1"/>')),
        "record_duplicate": lambda: _ssd_edit(base, _sub(
            '<crankfmu:Variable name="r2.w"/>', '<crankfmu:Variable name="r1.flange_w"/>')),
        "external_ssv_entity": lambda: _external_ssv(base, _ssv(
            "&v;", '<!DOCTYPE x [<!ENTITY v "1.0">]>\n')),
        "external_ssv_missing": lambda: _external_ssv(base, None),
        "external_ssv_huge": lambda: _external_ssv(base, _ssv("1.0"), size_pad=20 << 20),
        "many_entries": lambda: _zip({**members, **{f"junk/{k}": b"" for k in range(20_000)}}),
        "nested_system": lambda: _ssd_edit(base, _sub(
            "<ssd:Elements>", '<ssd:Elements><ssd:System name="inner"/>')),
        "corrupt_member": lambda: _corrupt(base),
        "ssp_directory": lambda: None,
    }
    names = [k for k in kinds if k not in skip]
    cases = []
    for i in range(n):
        kind = names[i % len(names)]
        cases.append({"id": f"ssp-{seed}-{i}", "family": "ssp", "kind": kind,
                      "files": {"scene.ssp": kinds[kind]()}, "scene": "scene.ssp",
                      "evil": ["/tmp/crankfmu-fuzz-evil-ssp.csv", "../evil-ssp.csv",
                               "results/../evil-ssp.csv"]})
    return cases


def _corrupt(base: bytes) -> bytes:
    """The SSD's compressed bytes damaged (CRC or zlib error on reading)."""
    data = bytearray(base)
    at = data.find(b"PK\x03\x04") + 30 + len(SSD) + 50
    for k in range(at, min(at + 64, len(data))):
        data[k] ^= 0x5A
    return bytes(data)
