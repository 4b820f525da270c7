"""Fixtures shared by the whole suite: built FMUs, meshed datasets, small synthetic datasets."""

from __future__ import annotations

import signal
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path

import pytest

SHARED_SAMPLE = Path(__file__).resolve().parents[2] / "shared" / "datasets" / "cdw_stacked_sample"

_STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)
_SESSION_HANDLERS = {sig: signal.getsignal(sig) for sig in _STOP_SIGNALS}
CHANGED_HANDLERS: list[str] = []
"""Tests after which SIGINT or SIGTERM was no longer handled as at the session's start."""


@pytest.fixture(autouse=True)
def _stop_signals_as_at_start(request: pytest.FixtureRequest) -> Iterator[None]:
    """Every test starts with SIGINT and SIGTERM handled as when the session started (a
    library that installs its own handlers in this process, or ignores SIGINT, would otherwise
    change what later tests and the processes they start, which inherit an ignored signal, do
    on Ctrl-C); the tests that changed them are listed at the end of the session."""
    for sig, handler in _SESSION_HANDLERS.items():
        if signal.getsignal(sig) is not handler:
            signal.signal(sig, handler)
    yield
    if any(signal.getsignal(sig) is not h for sig, h in _SESSION_HANDLERS.items()):
        CHANGED_HANDLERS.append(request.node.nodeid)


def pytest_terminal_summary(terminalreporter: pytest.TerminalReporter) -> None:
    """Name the tests that left SIGINT or SIGTERM handled otherwise (they were reset)."""
    if CHANGED_HANDLERS:
        terminalreporter.write_line(
            "stop-signal handlers changed (and reset) by: " + ", ".join(CHANGED_HANDLERS[:5])
        )


Polygon = tuple[int, Sequence[tuple[float, float]]]


@pytest.fixture(scope="session")
def built_fmus() -> tuple[Path, Path]:
    """The FMI 3.0 and FMI 2.0 belt-drive FMUs, built if needed."""
    from fmus.build import build_fmus

    return build_fmus()


@pytest.fixture(scope="session")
def builtin_meshes(tmp_path_factory: pytest.TempPathFactory, built_fmus: tuple[Path, Path]) -> Path:
    """A small meshed built-in sample (8 images), private to this test session."""
    from twin.builtin import builtin_dataset

    return builtin_dataset(tmp_path_factory.mktemp("builtin"), images=8, seed=0)


def write_yolo(
    folder: Path, labels: dict[str, Sequence[Polygon]], size_px: tuple[int, int] = (1000, 1000)
) -> Path:
    """Write a YOLO-seg dataset of pixel polygons (normalised on writing)."""
    w, h = size_px
    (folder / "labels").mkdir(parents=True, exist_ok=True)
    (folder / "data.yaml").write_text(
        "names:\n  0: concrete\n  1: brick\n  2: wood\n  3: rubber\n", encoding="utf-8"
    )
    for stem, polygons in labels.items():
        lines = []
        for class_id, points in polygons:
            coords = " ".join(f"{u / w:.6f} {v / h:.6f}" for u, v in points)
            lines.append(f"{class_id} {coords}")
        (folder / "labels" / f"{stem}.txt").write_text("\n".join(lines) + "\n", encoding="utf-8")
    return folder


@pytest.fixture
def mesh_polygons(tmp_path: Path) -> Callable[..., Path]:
    """Mesh given pixel polygons (1000x1000 px image on a 0.6 m belt) and return the output."""
    from meshgen.config import MeshgenConfig
    from meshgen.pipeline import mesh_dataset

    def make(labels: dict[str, Sequence[Polygon]], seed: int = 0) -> Path:
        data = write_yolo(tmp_path / "data", labels)
        out = tmp_path / "meshes"
        mesh_dataset(data, out, MeshgenConfig(image_size_px=(1000, 1000), seed=seed))
        return out

    return make
