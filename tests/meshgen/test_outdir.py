"""The output folder: meshgen replaces only its own earlier output and says why it refuses."""

from __future__ import annotations

import os
import shutil
from collections.abc import Iterator
from pathlib import Path

import pytest

from meshgen.config import MeshgenConfig
from meshgen.errors import OutputError
from meshgen.outdir import MARKER_NAME, MARKER_SIGNATURE, is_meshgen_output
from meshgen.pipeline import mesh_dataset
from twin.cli import main


def _snapshot(folder: Path) -> dict[str, bytes | None]:
    """Every entry under ``folder``: file bytes, or None for a folder."""
    return {
        p.relative_to(folder).as_posix(): (p.read_bytes() if p.is_file() else None)
        for p in sorted(folder.rglob("*"))
    }


def _one_line_error(err: str, *needles: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("cdw-twin: error: ")
    assert "Traceback" not in err
    for needle in needles:
        assert needle in lines[0]
    return lines[0]


@pytest.fixture
def dataset(sample_dir: Path, tmp_path: Path) -> Path:
    """A private copy of the built-in sample (the tests try to make meshgen overwrite it)."""
    copy = tmp_path / "v"
    shutil.copytree(sample_dir, copy)
    return copy


def test_out_equal_to_the_dataset_with_an_index_csv_is_refused(
    dataset: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The issue's case: ``echo x > v/index.csv; cdw-twin meshgen v --out v`` deleted v/labels."""
    (dataset / "index.csv").write_text("x\n")
    before = _snapshot(dataset)
    assert main(["meshgen", str(dataset), "--out", str(dataset)]) == 2
    _one_line_error(capsys.readouterr().err, str(dataset), "dataset folder itself")
    assert _snapshot(dataset) == before
    assert not list(dataset.parent.glob(".v.*"))


@pytest.mark.parametrize(
    ("where", "words"),
    [
        ("labels", "inside the dataset"),
        ("meshes", "inside the dataset"),
        ("labels/new/deeper", "inside the dataset"),
        ("..", "contains the dataset"),
    ],
)
def test_out_inside_or_containing_the_dataset_is_refused(
    dataset: Path, where: str, words: str, capsys: pytest.CaptureFixture[str]
) -> None:
    parent_before = _snapshot(dataset.parent)
    out = dataset / where
    assert main(["meshgen", str(dataset), "--out", str(out)]) == 2
    _one_line_error(capsys.readouterr().err, words)
    assert _snapshot(dataset.parent) == parent_before


def test_out_that_resolves_to_the_dataset_is_refused(dataset: Path, tmp_path: Path) -> None:
    link = tmp_path / "link"
    link.symlink_to(dataset, target_is_directory=True)
    before = _snapshot(dataset)
    with pytest.raises(OutputError, match="dataset folder itself"):
        mesh_dataset(dataset, link, MeshgenConfig())
    with pytest.raises(OutputError, match="dataset folder itself"):
        mesh_dataset(link, dataset / "." / ".." / "v", MeshgenConfig())
    assert _snapshot(dataset) == before


def test_a_folder_that_only_looks_like_an_output_is_refused(
    sample_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "results"
    out.mkdir()
    (out / "index.csv").write_text("image,objects\n")
    (out / "summary.json").write_text("{}\n")
    (out / "notes.txt").write_text("my notes")
    before = _snapshot(out)
    assert main(["meshgen", str(sample_dir), "--out", str(out)]) == 2
    _one_line_error(capsys.readouterr().err, str(out), "not a meshgen output", MARKER_NAME)
    assert _snapshot(out) == before


def test_marker_is_written_and_marks_the_only_replaceable_folders(
    sample_dir: Path, tmp_path: Path
) -> None:
    empty = tmp_path / "empty"
    empty.mkdir()
    summary = mesh_dataset(sample_dir, empty, MeshgenConfig())
    marker = (summary.out / MARKER_NAME).read_text(encoding="utf-8")
    assert marker.splitlines()[0] == MARKER_SIGNATURE
    assert "marker_version 1" in marker
    assert is_meshgen_output(summary.out)
    (summary.out / "extra.txt").write_text("added by a user")
    mesh_dataset(sample_dir, empty, MeshgenConfig())  # an earlier output: replaced whole
    assert not (empty / "extra.txt").exists()
    assert (empty / "index.csv").is_file()
    (empty / MARKER_NAME).write_text("something else\n")
    with pytest.raises(OutputError, match="not a meshgen output"):
        mesh_dataset(sample_dir, empty, MeshgenConfig())
    assert (empty / "index.csv").is_file()


@pytest.mark.parametrize("kind", ["under_a_file", "file_itself", "proc", "proc_deeper"])
def test_unwritable_out_is_a_one_line_error(
    sample_dir: Path, tmp_path: Path, kind: str, capsys: pytest.CaptureFixture[str]
) -> None:
    regular = tmp_path / "file"
    regular.write_text("a regular file\n")
    out = {
        "under_a_file": regular / "out",
        "file_itself": regular,
        "proc": Path("/proc/cdw-twin-meshgen-test"),
        "proc_deeper": Path("/proc/cdw-twin-meshgen-test/out"),
    }[kind]
    if kind.startswith("proc") and not Path("/proc/self").is_dir():
        pytest.skip("no /proc file system")
    assert main(["meshgen", str(sample_dir), "--out", str(out)]) == 2
    line = _one_line_error(capsys.readouterr().err, str(out))
    if kind == "under_a_file":
        assert f"{regular} is not a folder" in line
    assert regular.read_text() == "a regular file\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file"]


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into read-only folders")
def test_read_only_parent_is_a_one_line_error(
    sample_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o555)
    try:
        assert main(["meshgen", str(sample_dir), "--out", str(locked / "out")]) == 2
        _one_line_error(capsys.readouterr().err, str(locked / "out"), "ermission denied")
        assert not list(locked.iterdir())
    finally:
        locked.chmod(0o755)


@pytest.fixture
def umask_002() -> Iterator[int]:
    """Run with umask 002 (group-writable files), restoring the previous umask after."""
    previous = os.umask(0o002)
    try:
        yield 0o002
    finally:
        os.umask(previous)


@pytest.mark.parametrize("workers", [1, 2])
def test_every_output_file_has_the_mode_of_an_ordinary_open(
    sample_dir: Path, tmp_path: Path, umask_002: int, workers: int
) -> None:
    summary = mesh_dataset(sample_dir, tmp_path / "out", MeshgenConfig(), workers=workers)
    files = [p for p in summary.out.rglob("*") if p.is_file()]
    assert len(files) > summary.objects
    modes = {p.relative_to(summary.out).as_posix(): p.stat().st_mode & 0o777 for p in files}
    assert set(modes.values()) == {0o666 & ~umask_002}, modes
    names = {p.name for p in files}
    assert {MARKER_NAME, "index.csv", "summary.json", "materials.mtl", "scene.csv"} <= names
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]  # no temporary leftovers
