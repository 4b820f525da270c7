"""Same seed, same bytes; workers do not change the output; reruns replace the output."""

from __future__ import annotations

import zlib
from pathlib import Path

import numpy as np
import pytest

from meshgen.config import MeshgenConfig
from meshgen.errors import OutputError
from meshgen.pipeline import mesh_dataset, object_height_m


def _files(out: Path) -> dict[str, bytes]:
    return {
        p.relative_to(out).as_posix(): p.read_bytes()
        for p in sorted(out.rglob("*"))
        if p.is_file() and p.name != "summary.json"
    }


def test_same_seed_byte_identical_any_workers(sample_dir: Path, tmp_path: Path) -> None:
    one = mesh_dataset(sample_dir, tmp_path / "a", MeshgenConfig(seed=5))
    two = mesh_dataset(sample_dir, tmp_path / "b", MeshgenConfig(seed=5), workers=2)
    files_a, files_b = _files(one.out), _files(two.out)
    assert len(files_a) > 3 * one.objects // 2
    assert files_a == files_b


def test_other_seed_changes_heights_only(sample_dir: Path, tmp_path: Path) -> None:
    a = _files(mesh_dataset(sample_dir, tmp_path / "a", MeshgenConfig(seed=1)).out)
    b = _files(mesh_dataset(sample_dir, tmp_path / "b", MeshgenConfig(seed=2)).out)
    assert a.keys() == b.keys()
    assert a["index.csv"] == b["index.csv"]
    assert any(a[k] != b[k] for k in a if k.endswith(".obj"))


def test_rerun_replaces_old_output(sample_dir: Path, tmp_path: Path) -> None:
    out = tmp_path / "out"
    mesh_dataset(sample_dir, out, MeshgenConfig())
    stale = out / "stale_image"
    stale.mkdir()
    (stale / "scene.csv").write_text("old\n")
    mesh_dataset(sample_dir, out, MeshgenConfig())
    assert not stale.exists()
    assert not list(tmp_path.glob(".out.*"))


def test_refuses_to_replace_foreign_folder(sample_dir: Path, tmp_path: Path) -> None:
    out = tmp_path / "precious"
    out.mkdir()
    (out / "thesis.tex").write_text("keep me")
    with pytest.raises(OutputError, match="not a meshgen output"):
        mesh_dataset(sample_dir, out, MeshgenConfig())
    assert (out / "thesis.tex").read_text() == "keep me"


def test_heights_follow_numpy_default_rng() -> None:
    spec = MeshgenConfig().classes.classes[0]
    for seed, stem, index in [(0, "a", 0), (5, "Bauto_222372.000000", 17), (2**31, "x" * 40, 999)]:
        for k in range(index, index + 20):
            rng = np.random.default_rng([seed, zlib.crc32(stem.encode()), k])
            expected = rng.uniform(spec.height_min_m, spec.height_max_m)
            assert object_height_m(seed, stem, k, spec) == expected
