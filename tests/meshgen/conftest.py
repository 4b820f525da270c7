"""Shared fixtures: the built-in sample, meshed once per session."""

from __future__ import annotations

from pathlib import Path

import pytest

from meshgen.config import MeshgenConfig
from meshgen.pipeline import DatasetSummary, mesh_dataset
from meshgen.sample import write_sample

REAL_SAMPLE = Path(__file__).resolve().parents[3] / "shared" / "datasets" / "cdw_stacked_sample"
if not REAL_SAMPLE.is_dir():
    REAL_SAMPLE = Path("/work/shared/datasets/cdw_stacked_sample")


@pytest.fixture(scope="session")
def real_sample() -> Path:
    """The real annotated sample; the test is skipped when it is not present."""
    if not REAL_SAMPLE.is_dir():
        pytest.skip("real sample not present")
    return REAL_SAMPLE


@pytest.fixture(scope="session")
def sample_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A small built-in sample (8 images)."""
    out = tmp_path_factory.mktemp("sample")
    write_sample(out, images=8, seed=3)
    return out


@pytest.fixture(scope="session")
def meshed(sample_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> DatasetSummary:
    """The sample meshed with the default configuration."""
    out = tmp_path_factory.mktemp("meshed") / "out"
    return mesh_dataset(sample_dir, out, MeshgenConfig(seed=7))


@pytest.fixture(scope="session")
def default_sample_meshed(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The default built-in sample (``cdw-twin sample``'s defaults, without its photos: the
    outlines are the same), meshed by default."""
    root = tmp_path_factory.mktemp("default_sample")
    write_sample(root / "sample", photos=False)
    return mesh_dataset(root / "sample", root / "meshes", MeshgenConfig()).out


@pytest.fixture(scope="session")
def real_meshed(real_sample: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The real sample meshed by default (skipped when the real sample is not present)."""
    out = tmp_path_factory.mktemp("real_meshed") / "out"
    return mesh_dataset(real_sample, out, MeshgenConfig()).out
