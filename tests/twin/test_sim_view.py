"""The layers of the twin's perception: the sim steps its perception source, the source drives the
cameras, and neither reaches back into the sim (they read it through :mod:`twin.sim_view`)."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import twin.sim_view

# from a module, not the package: pytest's pythonpath holds tests/, whose tests/twin folder would
# otherwise be found as a namespace package named twin with no __file__
TWIN_DIR = Path(twin.sim_view.__file__).resolve().parent


def imported_modules(path: Path) -> set[str]:
    """Every module ``path`` imports, at its top, inside a function or for type checking."""
    out: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), filename=str(path))):
        if isinstance(node, ast.Import):
            out.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module is not None and node.level == 0:
            out.add(node.module)
            out.update(f"{node.module}.{alias.name}" for alias in node.names)
    return out


def test_the_cameras_and_the_perception_source_never_import_the_sim() -> None:
    below_sim = [*sorted((TWIN_DIR / "camera").glob("*.py")), TWIN_DIR / "perception_source.py"]
    below_sim.append(TWIN_DIR / "sim_view.py")
    offenders = {
        str(path.relative_to(TWIN_DIR.parent)): sorted(
            m for m in imported_modules(path) if m == "twin.sim" or m.startswith("twin.sim.")
        )
        for path in below_sim
    }
    assert {path: found for path, found in offenders.items() if found} == {}
    assert len(offenders) >= 10  # every camera module was read


def test_the_cameras_do_not_import_the_perception_source_that_drives_them() -> None:
    for path in sorted((TWIN_DIR / "camera").glob("*.py")):
        found = {m for m in imported_modules(path) if m.startswith("twin.perception_source")}
        assert found == set(), path.name


def test_importing_the_perception_source_and_cameras_leaves_the_sim_unloaded() -> None:
    code = (
        "import sys\n"
        "import twin.perception_source, twin.camera.rig, twin.camera.overlay\n"
        "print(sorted(m for m in sys.modules if m == 'twin.sim'))\n"
    )
    result = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=120
    )
    assert result.stdout.strip().splitlines()[-1] == "[]"
