"""A belt-drive FMU built by another tool (pythonfmu) for tests that need a third party's drive.

``build_belt_fmu(out_dir)`` runs ``pythonfmu build`` on the model script
``tests/fmus/lag_belt.py`` (class ``LagBelt``: the belt speed is a first-order lag of its
setpoint) and returns the path of ``LagBelt.fmu``, an FMI 2.0 co-simulation FMU. Its variables
have other names than ours; :data:`LAG_BELT_MAPPING` maps them onto the drive's roles (the keys
are the fields of ``twin.belt_drive.VariableMapping`` and of the cell file's ``drive.mapping``),
and the drive has no perturbation parameters. :func:`lag_belt_state` is its exact solution.

pythonfmu is a test dependency (``pip install pythonfmu``; it installs from its wheel, which
carries the prebuilt FMI export library, and builds offline). The FMU runs the model in the
Python of the process that loads it (fmpy in the test process), through that library.

In a conftest::

    from tests.fmus.pythonfmu_belt import lag_belt_fmu  # noqa: F401 (a session fixture)

or in a fixture of one's own: ``path = build_belt_fmu(tmp_path_factory.mktemp("lag_belt"))``
after ``skip_reason = pythonfmu_unavailable()``.
"""

from __future__ import annotations

import importlib.util
import math
import os
import platform
import subprocess
import sys
from pathlib import Path

import pytest

MODEL_SCRIPT = Path(__file__).resolve().with_name("lag_belt.py")
"""The pythonfmu model script (class ``LagBelt``)."""
FMU_NAME = "LagBelt.fmu"

LAG_BELT_MAPPING: dict[str, str | None] = {
    "speed_setpoint": "v_set",
    "load_mass": "m_load",
    "belt_speed": "v_belt",
    "belt_position": "x_belt",
    "motor_torque": None,
    "motor_current": None,
}
"""The drive's roles (``VariableMapping`` / cell ``drive.mapping`` fields) -> LagBelt's names."""

LAG_BELT_PARAMETERS: dict[str, float] = {"T_lag": 0.25, "m_belt": 50.0}
"""LagBelt's parameters and their start values: lag (s) without load, belt mass (kg)."""


def pythonfmu_unavailable() -> str:
    """Why ``pythonfmu build`` cannot make a working FMU here ("" when it can)."""
    spec = importlib.util.find_spec("pythonfmu")
    if spec is None or spec.origin is None:
        return "pythonfmu is not installed (a test dependency: pip install pythonfmu)"
    system, machine = platform.system(), platform.machine().lower()
    folders = {"Linux": ("linux64", "so"), "Windows": ("win64", "dll")}
    if system not in folders or machine not in {"x86_64", "amd64"}:
        return (
            "pythonfmu ships its FMI export library for x86-64 Linux and Windows only, "
            f"not {system} {machine}"
        )
    folder, suffix = folders[system]
    library = Path(spec.origin).parent / "resources" / "binaries" / folder
    if not any(library.glob(f"*.{suffix}")):
        return f"pythonfmu's FMI export library is missing from {library}"
    return ""


def build_belt_fmu(out_dir: Path) -> Path:
    """Build ``LagBelt.fmu`` into ``out_dir`` with ``pythonfmu build``; return its path.

    Raises RuntimeError with pythonfmu's output when the build fails (call
    :func:`pythonfmu_unavailable` first to skip where pythonfmu cannot work).
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    command = [
        sys.executable,
        "-m",
        "pythonfmu",
        "build",
        "-f",
        str(MODEL_SCRIPT),
        "-d",
        str(out_dir),
    ]
    env = {**os.environ, "PYTHONDONTWRITEBYTECODE": "1"}  # no __pycache__ next to the script
    result = subprocess.run(
        command, capture_output=True, text=True, check=False, timeout=120, env=env, cwd=out_dir
    )
    path = out_dir / FMU_NAME
    if result.returncode != 0 or not path.is_file():
        msg = (
            f"pythonfmu build of {MODEL_SCRIPT.name} failed (exit {result.returncode}): "
            f"{(result.stderr or result.stdout).strip()}"
        )
        raise RuntimeError(msg)
    return path


@pytest.fixture(scope="session")
def lag_belt_fmu(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """``LagBelt.fmu``, built once per session; the test is skipped where pythonfmu can't work."""
    reason = pythonfmu_unavailable()
    if reason:
        pytest.skip(reason)
    return build_belt_fmu(tmp_path_factory.mktemp("lag_belt"))


def lag_belt_state(
    t_s: float, v_set_mps: float, *, v0_mps: float = 0.0, lag_s: float = 0.25
) -> tuple[float, float]:
    """LagBelt's exact ``(speed m/s, distance travelled m)`` after ``t_s`` at a held setpoint.

    From speed ``v0_mps``; ``lag_s`` is ``T_lag * (1 + m_load / m_belt)``.
    """
    decay = math.exp(-t_s / lag_s)
    speed = v_set_mps + (v0_mps - v_set_mps) * decay
    distance = v_set_mps * t_s + (v0_mps - v_set_mps) * lag_s * (1.0 - decay)
    return speed, distance
