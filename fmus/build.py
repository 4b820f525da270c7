"""Compile the belt-drive model into FMI 3.0 and FMI 2.0 co-simulation FMUs with gcc.

Both FMUs come from the same C source (``fmus/framework`` + ``fmus/belt_drive``); the FMI 2.0
model description is derived from the hand-written FMI 3.0 one so the two can never disagree.
The FMI headers come from the installed fmpy package. Each FMU carries its ``sources/`` so other
tools can rebuild it.

Example::

    cdw-twin fmu build            # skips when the FMUs are newer than every source
    cdw-twin fmu build --force
"""

from __future__ import annotations

import os
import platform
import shutil
import subprocess
import tempfile
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path
from typing import TYPE_CHECKING

from fmus.errors import FmuBuildError

if TYPE_CHECKING:
    import argparse

MODEL_IDENTIFIER = "BeltDrive"
PACKAGE_DIR = Path(__file__).resolve().parent
FRAMEWORK_DIR = PACKAGE_DIR / "framework"
MODEL_DIR = PACKAGE_DIR / "belt_drive"
DEFAULT_OUT_DIR = PACKAGE_DIR / "build"

_FRAMEWORK_SOURCES = ("model.h", "cosimulation.c")
_MODEL_SOURCES = ("config.h", "model.c")
_FMU_NAMES = {3: f"{MODEL_IDENTIFIER}.fmu", 2: f"{MODEL_IDENTIFIER}_fmi2.fmu"}


def default_fmu_path(fmi_version: int = 3) -> Path:
    """Path of the built belt-drive FMU for ``fmi_version`` 2 or 3 (may not exist yet)."""
    if fmi_version not in _FMU_NAMES:
        msg = f"fmi_version = {fmi_version!r} is not supported; use 2 or 3"
        raise ValueError(msg)
    return DEFAULT_OUT_DIR / _FMU_NAMES[fmi_version]


def fmi_headers_dir() -> Path:
    """Folder with the FMI 2.0 and 3.0 C headers shipped by the installed fmpy."""
    import fmpy

    path = Path(fmpy.__file__).parent / "c-code"
    if not (path / "fmi3Functions.h").is_file():
        msg = f"FMI headers not found in {path}; reinstall fmpy"
        raise FmuBuildError(msg)
    return path


def _platform_dir(fmi_version: int) -> str:
    machine = platform.machine().lower()
    system = platform.system().lower()
    if system != "linux":
        msg = f"building FMUs is only supported on Linux, not {platform.system()}"
        raise FmuBuildError(msg)
    if fmi_version == 3:
        return f"{'x86_64' if machine in {'x86_64', 'amd64'} else machine}-linux"
    return "linux64" if machine in {"x86_64", "amd64", "aarch64"} else "linux32"


def _source_files(fmi_version: int) -> list[Path]:
    framework = [
        FRAMEWORK_DIR / name for name in (*_FRAMEWORK_SOURCES, f"fmi{fmi_version}Functions.c")
    ]
    return framework + [MODEL_DIR / name for name in _MODEL_SOURCES]


def _inputs() -> list[Path]:
    return [
        *(
            FRAMEWORK_DIR / name
            for name in (*_FRAMEWORK_SOURCES, "fmi2Functions.c", "fmi3Functions.c")
        ),
        *(MODEL_DIR / name for name in (*_MODEL_SOURCES, "FMI3.xml", "readme.md")),
        Path(__file__).resolve(),
    ]


_FMI2_TYPES = {"Float64": "Real", "Int32": "Integer"}
"""FMI 3.0 variable elements and their FMI 2.0 type elements (the subset the belt drive uses)."""


def _fmi2_root(root3: ET.Element, source_files: list[str]) -> ET.Element:
    """The FMI 2.0 root element with its attributes, CoSimulation, units and experiment."""
    root2 = ET.Element("fmiModelDescription")
    root2.set("fmiVersion", "2.0")
    for key in ("modelName", "description", "generationTool", "variableNamingConvention"):
        if key in root3.attrib:
            root2.set(key, root3.attrib[key])
    root2.set("guid", root3.attrib["instantiationToken"])
    root2.set("numberOfEventIndicators", "0")
    cs3 = root3.find("CoSimulation")
    if cs3 is None:
        msg = "FMI3.xml: missing CoSimulation element"
        raise FmuBuildError(msg)
    cs2 = ET.SubElement(root2, "CoSimulation")
    cs2.set("modelIdentifier", cs3.attrib["modelIdentifier"])
    cs2.set("canHandleVariableCommunicationStepSize", "true")
    cs2.set("canNotUseMemoryManagementFunctions", "true")
    files = ET.SubElement(cs2, "SourceFiles")
    for name in source_files:
        ET.SubElement(files, "File").set("name", name)
    for tag in ("UnitDefinitions", "DefaultExperiment"):
        element = root3.find(tag)
        if element is not None:
            root2.append(element)
    return root2


def _fmi2_variables(root3: ET.Element, root2: ET.Element) -> dict[str, int]:
    """Add the ``ModelVariables`` of ``root3`` to ``root2`` as FMI 2.0 ``ScalarVariable`` s.

    Returns each value reference's 1-based variable index (FMI 2.0's ``ModelStructure`` refers
    to variables by index, FMI 3.0's by value reference).
    """
    variables2 = ET.SubElement(root2, "ModelVariables")
    index_of: dict[str, int] = {}
    variables3 = root3.find("ModelVariables")
    for index, var3 in enumerate(variables3 if variables3 is not None else [], start=1):
        if var3.tag not in _FMI2_TYPES:
            msg = f"FMI3.xml: variable type {var3.tag} has no FMI 2.0 equivalent here"
            raise FmuBuildError(msg)
        scalar = ET.SubElement(variables2, "ScalarVariable")
        for key in ("name", "valueReference", "description", "causality", "variability", "initial"):
            if key in var3.attrib:
                scalar.set(key, var3.attrib[key])
        typed = ET.SubElement(scalar, _FMI2_TYPES[var3.tag])
        for key in ("start", "unit", "min", "max"):
            if key in var3.attrib:
                typed.set(key, var3.attrib[key])
        index_of[var3.attrib["valueReference"]] = index
    return index_of


def _fmi2_structure(root3: ET.Element, root2: ET.Element, index_of: dict[str, int]) -> None:
    """Add the ``ModelStructure`` (outputs, initial unknowns) of ``root3`` to ``root2``."""
    structure3 = root3.find("ModelStructure")
    structure2 = ET.SubElement(root2, "ModelStructure")
    for tag3, tag2 in (("Output", "Outputs"), ("InitialUnknown", "InitialUnknowns")):
        entries = [] if structure3 is None else structure3.findall(tag3)
        if entries:
            group = ET.SubElement(structure2, tag2)
            for index in sorted(index_of[entry.attrib["valueReference"]] for entry in entries):
                ET.SubElement(group, "Unknown").set("index", str(index))


def fmi2_model_description(fmi3_xml: str, source_files: list[str]) -> str:
    """Translate our FMI 3.0 model description into the equivalent FMI 2.0 one.

    Handles the subset the belt drive uses: Float64 and Int32 variables, units, a
    CoSimulation element and outputs/initial unknowns. ``source_files`` are listed in the
    FMI 2.0 ``SourceFiles`` element.
    """
    root3 = ET.fromstring(fmi3_xml)
    root2 = _fmi2_root(root3, source_files)
    index_of = _fmi2_variables(root3, root2)
    _fmi2_structure(root3, root2, index_of)
    ET.indent(root2, space="  ")
    return (
        '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root2, encoding="unicode") + "\n"
    )


def _build_description(source_files: list[str]) -> str:
    lines = [
        '<?xml version="1.0" encoding="UTF-8"?>',
        '<fmiBuildDescription fmiVersion="3.0">',
        f'  <BuildConfiguration modelIdentifier="{MODEL_IDENTIFIER}">',
        '    <SourceFileSet language="C99">',
        *(f'      <SourceFile name="{name}"/>' for name in source_files),
        "    </SourceFileSet>",
        '    <Library name="m"/>',
        "  </BuildConfiguration>",
        "</fmiBuildDescription>",
        "",
    ]
    return "\n".join(lines)


def _compile(fmi_version: int, library: Path) -> None:
    gcc = shutil.which("gcc")
    if gcc is None:
        msg = "gcc not found on PATH; install gcc to build the FMUs"
        raise FmuBuildError(msg)
    sources = [str(p) for p in _source_files(fmi_version) if p.suffix == ".c"]
    command = [
        gcc, "-std=c99", "-O2", "-Wall", "-Wextra", "-fPIC", "-shared", "-fvisibility=hidden",
        f"-I{fmi_headers_dir()}", f"-I{FRAMEWORK_DIR}", f"-I{MODEL_DIR}",
        *sources, "-o", str(library), "-lm",
    ]  # fmt: skip
    result = subprocess.run(command, capture_output=True, text=True, check=False)
    if result.returncode != 0:
        msg = f"gcc failed building FMI {fmi_version}.0 {library.name}:\n{result.stderr.strip()}"
        raise FmuBuildError(msg)


def _package(fmi_version: int, out_path: Path) -> None:
    source_names = [p.name for p in _source_files(fmi_version)]
    fmi3_xml = (MODEL_DIR / "FMI3.xml").read_text(encoding="utf-8")
    if fmi_version == 3:
        description = fmi3_xml
    else:
        description = fmi2_model_description(
            fmi3_xml, [n for n in source_names if n.endswith(".c")]
        )
    with tempfile.TemporaryDirectory(prefix="fmu-build-") as tmp:
        library = Path(tmp) / f"{MODEL_IDENTIFIER}.so"
        _compile(fmi_version, library)
        fd, tmp_name = tempfile.mkstemp(
            prefix=f".{out_path.name}.", suffix=".tmp", dir=out_path.parent
        )
        os.close(fd)
        try:
            with zipfile.ZipFile(tmp_name, "w", zipfile.ZIP_DEFLATED) as fmu:
                fmu.writestr("modelDescription.xml", description)
                fmu.write(library, f"binaries/{_platform_dir(fmi_version)}/{library.name}")
                for path in _source_files(fmi_version):
                    fmu.write(path, f"sources/{path.name}")
                if fmi_version == 3:
                    c_sources = [n for n in source_names if n.endswith(".c")]
                    fmu.writestr("sources/buildDescription.xml", _build_description(c_sources))
                fmu.write(MODEL_DIR / "readme.md", "documentation/readme.md")
            os.replace(tmp_name, out_path)
        except BaseException:
            Path(tmp_name).unlink(missing_ok=True)
            raise


def _up_to_date(outputs: tuple[Path, Path]) -> bool:
    if not all(p.is_file() for p in outputs):
        return False
    newest_input = max(p.stat().st_mtime for p in _inputs())
    return min(p.stat().st_mtime for p in outputs) > newest_input


def build_fmus(out_dir: Path | None = None, force: bool = False) -> tuple[Path, Path]:
    """Build ``BeltDrive.fmu`` (FMI 3.0) and ``BeltDrive_fmi2.fmu`` (FMI 2.0) into ``out_dir``.

    Skips the work when both outputs are newer than every source unless ``force``. Each FMU is
    zipped to a temporary file and moved into place, so a half-written FMU never appears.
    Returns ``(fmi3_path, fmi2_path)``; raises :class:`fmus.errors.FmuBuildError` on failure.
    """
    target = DEFAULT_OUT_DIR if out_dir is None else Path(out_dir)
    target.mkdir(parents=True, exist_ok=True)
    outputs = (target / _FMU_NAMES[3], target / _FMU_NAMES[2])
    if not force and _up_to_date(outputs):
        return outputs
    _package(3, outputs[0])
    _package(2, outputs[1])
    return outputs


def configure(parser: argparse.ArgumentParser) -> None:
    """Add the ``fmu build`` options."""
    parser.add_argument(
        "--out", type=Path, default=None, help=f"output folder (default {DEFAULT_OUT_DIR})"
    )
    parser.add_argument("--force", action="store_true", help="rebuild even when up to date")


def run(args: argparse.Namespace) -> int:
    """Build both FMUs and print their paths."""
    for path in build_fmus(args.out, force=args.force):
        print(path)
    return 0
