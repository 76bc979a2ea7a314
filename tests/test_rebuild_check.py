"""rebuild_reason remembers the FMU files it found whole and current (fmu.build._CURRENT_BUILDS):
a file unchanged since is not read again; one written, replaced or damaged since is."""
from __future__ import annotations

import os
import shutil
from pathlib import Path

from crankfmu.fmu import archive, build


def _counting_reads(monkeypatch) -> list:
    reads: list = []
    read_fmu = archive.read_fmu

    def counted(path, *args, **kwargs):
        reads.append(Path(path))
        return read_fmu(path, *args, **kwargs)
    monkeypatch.setattr(archive, "read_fmu", counted)
    return reads


def test_an_unchanged_current_fmu_is_checked_once_and_a_changed_one_again(fmu_dir, tmp_path,
                                                                          monkeypatch):
    reads = _counting_reads(monkeypatch)
    fmu = Path(shutil.copy(fmu_dir / "DcServoMotor.fmu", tmp_path / "DcServoMotor.fmu"))
    assert build.rebuild_reason(fmu, "DcServoMotor") is None
    assert build.rebuild_reason(fmu, "DcServoMotor") is None
    assert reads == [fmu]  # the second check took the remembered answer
    # damaged in place, same size, its times set back to the checked ones: the status-change
    # time still moves (set by the kernel), and the check reads the file again
    data, st = bytearray(fmu.read_bytes()), fmu.stat()
    data[-22] ^= 0xFF  # the zip's end-of-directory record: no longer a zip
    fmu.write_bytes(bytes(data))
    os.utime(fmu, ns=(st.st_atime_ns, st.st_mtime_ns))
    damaged = build.rebuild_reason(fmu, "DcServoMotor")
    assert damaged is not None and damaged.damaged and len(reads) == 2
    # replaced by another model's whole build under the same name: another inode
    other = Path(shutil.copy(fmu_dir / "StephensonPress.fmu", tmp_path / "other.fmu"))
    os.replace(other, fmu)
    assert build.rebuild_reason(fmu, "DcServoMotor").reason == "sources changed"
    assert len(reads) == 3
