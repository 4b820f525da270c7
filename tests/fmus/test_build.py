"""The build produces valid, self-describing FMUs, idempotently and atomically."""

from __future__ import annotations

import subprocess
import sys
import zipfile
from pathlib import Path

import pytest
from fmpy.validation import validate_fmu

from fmus.build import MODEL_DIR, build_fmus, default_fmu_path, fmi2_model_description


@pytest.mark.parametrize("version", [3, 2])
def test_fmu_passes_fmpy_validation(fmus: dict[int, Path], version: int) -> None:
    assert validate_fmu(str(fmus[version])) == []


def test_fmus_carry_sources_and_build_description(fmus: dict[int, Path]) -> None:
    with zipfile.ZipFile(fmus[3]) as fmu3:
        names3 = set(fmu3.namelist())
        build_xml = fmu3.read("sources/buildDescription.xml").decode()
    with zipfile.ZipFile(fmus[2]) as fmu2:
        names2 = set(fmu2.namelist())
        description2 = fmu2.read("modelDescription.xml").decode()
    assert {"sources/model.c", "sources/config.h", "sources/fmi3Functions.c"} <= names3
    assert "binaries/x86_64-linux/BeltDrive.so" in names3
    assert "binaries/linux64/BeltDrive.so" in names2
    assert '<SourceFile name="model.c"/>' in build_xml
    assert '<File name="fmi2Functions.c"' in description2
    assert "sources/fmi2Functions.c" in names2


def test_fmi2_description_mirrors_fmi3() -> None:
    xml3 = (MODEL_DIR / "FMI3.xml").read_text()
    xml2 = fmi2_model_description(xml3, ["model.c"])
    assert xml3.count("<Float64 ") + xml3.count("<Int32 ") == xml2.count("<ScalarVariable ")
    assert xml2.count("<Unknown ") == 8


def test_build_is_idempotent_and_force_rebuilds(tmp_path: Path) -> None:
    first = build_fmus(tmp_path)
    mtimes = [p.stat().st_mtime_ns for p in first]
    second = build_fmus(tmp_path)
    assert second == first
    assert [p.stat().st_mtime_ns for p in second] == mtimes
    build_fmus(tmp_path, force=True)
    assert [p.stat().st_mtime_ns for p in first] != mtimes
    assert sorted(p.name for p in tmp_path.iterdir()) == ["BeltDrive.fmu", "BeltDrive_fmi2.fmu"]


def test_default_paths() -> None:
    assert default_fmu_path().name == "BeltDrive.fmu"
    assert default_fmu_path(2).name == "BeltDrive_fmi2.fmu"
    with pytest.raises(ValueError, match="fmi_version = 1"):
        default_fmu_path(1)


@pytest.mark.parametrize("version", [3, 2])
def test_fmpy_simulate_runs_standalone(fmus: dict[int, Path], version: int, tmp_path: Path) -> None:
    out = tmp_path / "result.csv"
    fmpy_cli = Path(sys.executable).parent / "fmpy"
    subprocess.run(
        [str(fmpy_cli), "simulate", str(fmus[version]), "--start-values", "speed_setpoint_mps",
         "0.6", "--output-file", str(out)],
        check=True, capture_output=True, timeout=60,
    )  # fmt: skip
    last = out.read_text().strip().splitlines()[-1].split(",")
    assert abs(float(last[1]) - 0.6) < 1e-3
