"""The message build script: up-to-date check and clear errors (no compilation here)."""

from __future__ import annotations

import importlib.util
import os
import sys
import time
from pathlib import Path
from types import ModuleType

import pytest

SCRIPT = Path(__file__).parents[2] / "interfaces" / "build_interfaces.py"


@pytest.fixture(scope="module")
def build_script() -> ModuleType:
    """``interfaces/build_interfaces.py`` imported as a module."""
    spec = importlib.util.spec_from_file_location("cdw_build_interfaces", SCRIPT)
    assert spec is not None
    assert spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_every_message_of_the_contract_is_defined(build_script: ModuleType) -> None:
    assert build_script.message_names() == [
        "BeltState",
        "Claim",
        "ClaimArray",
        "Detection",
        "DetectionArray",
        "LockstepTick",
        "ObjectState",
        "ObjectStateArray",
        "PickTarget",
        "Ping",
        "SortingBin",
        "SortingBins",
        "SortingEvent",
        "SortingPriorities",
        "StepAck",
    ]


def test_every_msg_field_documents_itself(build_script: ModuleType) -> None:
    for msg_file in sorted((build_script.SOURCE_DIR / "msg").glob("*.msg")):
        lines = msg_file.read_text(encoding="utf-8").splitlines()
        for number, line in enumerate(lines):
            if line and not line.startswith("#"):
                assert number > 0, f"{msg_file.name}:{number + 1} has no comment above it"
                assert lines[number - 1].startswith("#"), (
                    f"{msg_file.name}:{number + 1} field {line!r} has no comment above it"
                )


def test_stamp_decides_whether_to_rebuild(build_script: ModuleType, tmp_path: Path) -> None:
    assert not build_script.is_up_to_date(tmp_path)
    stamp = build_script.stamp_path(tmp_path)
    stamp.parent.mkdir(parents=True)
    stamp.write_text("x", encoding="utf-8")
    assert build_script.is_up_to_date(tmp_path)
    old_s = time.time() - 10 * 365 * 86400
    os.utime(stamp, (old_s, old_s))
    assert not build_script.is_up_to_date(tmp_path)


def test_missing_build_tools_are_named_with_their_pip_package(
    build_script: ModuleType, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(build_script.InterfaceBuildError, match=r"ros-jazzy-ament-cmake\)"):
        build_script.check_prerequisites(tmp_path)
    status = build_script.main(["--prefix", str(tmp_path), "--build-dir", str(tmp_path / "b")])
    assert status == 1
    assert "missing build dependencies" in capsys.readouterr().out
    assert not build_script.stamp_path(tmp_path).exists()


def test_installed_package_matches_its_sources(build_script: ModuleType) -> None:
    spec = importlib.util.find_spec("cdw_interfaces")
    if spec is None:
        pytest.skip(
            "cdw_interfaces is not built; run `.venv/bin/python interfaces/build_interfaces.py`"
        )

    for source_dir in build_script.PACKAGE_DIRS:
        assert build_script.is_up_to_date(Path(sys.prefix), source_dir), (
            f"{source_dir.name}: sources changed since the last build"
        )
