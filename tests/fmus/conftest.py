"""Session fixtures: both belt-drive FMUs built once, and the pythonfmu-built LagBelt FMU."""

from __future__ import annotations

from pathlib import Path

import pytest

from fmus.build import build_fmus
from tests.fmus.pythonfmu_belt import lag_belt_fmu

__all__ = ["fmus", "lag_belt_fmu"]


@pytest.fixture(scope="session")
def fmus(tmp_path_factory: pytest.TempPathFactory) -> dict[int, Path]:
    """Freshly built FMUs keyed by FMI version (3 and 2)."""
    fmi3, fmi2 = build_fmus(tmp_path_factory.mktemp("fmus"), force=True)
    return {3: fmi3, 2: fmi2}
