"""A table of bad inputs per command (``run``, ``twin-node``, ``sweep``, ``report``): each is
refused before anything starts with exit status 2 and one line naming the file, key or value;
no traceback, and nothing written."""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import pytest

from twin.cli import main

SCENARIOS = Path(__file__).resolve().parents[2] / "experiments" / "scenarios"
BIG_SEED = str(2**64)

LOL = '["lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol"]'
BOMB = "\n".join(
    [f"a0: &a0 {LOL}"]
    + [f"a{i}: &a{i} [{', '.join([f'*a{i - 1}'] * 9)}]" for i in range(1, 9)]
    + ["stations: [*a8]", ""]
)
"""A 700-byte YAML alias bomb under ``stations:`` (9**9 strings expanded)."""

GRAVITY_UP = (
    (SCENARIOS.parent.parent / "interfaces" / "cells" / "default.yaml")
    .read_text(encoding="utf-8")
    .replace("gravity_mps2: 9.81", "gravity_mps2: -9.81")
)


@dataclass(frozen=True)
class Case:
    """One bad input: the command line (``{tmp}`` the test's folder, ``{data}`` the dataset),
    files to write first, and what stderr must say."""

    argv: tuple[str, ...]
    says: str
    files: tuple[tuple[str, bytes], ...] = ()


def _files(**named: str | bytes) -> tuple[tuple[str, bytes], ...]:
    return tuple(
        (k.replace("__", "."), v if isinstance(v, bytes) else v.encode()) for k, v in named.items()
    )


CASES: dict[str, Case] = {
    # -- run ------------------------------------------------------------------------------
    "run: a seed above 2**64": Case(("run", "--seed", BIG_SEED), "must be in [0, 2**64 - 1]"),
    "run: a negative seed": Case(("run", "--seed", "-1"), "must be in [0, 2**64 - 1]"),
    "run: a seed whose last episode passes 2**64": Case(
        ("run", "--seed", str(2**64 - 1), "--episodes", "2", "--dataset", "{data}"),
        "the last episode's seed 18446744073709551616 exceeds 2**64 - 1",
    ),
    "run: --foxglove 99999": Case(
        ("run", "--foxglove", "99999"), "a TCP port is in [0, 65535] (0: any free one), not 99999"
    ),
    "run: no episodes": Case(("run", "--episodes", "0"), "must be in [1, 100000], not 0"),
    "run: an empty scenario": Case(
        ("run", "{tmp}/empty.yaml"), "empty.yaml: the scenario is empty", _files(empty__yaml="")
    ),
    "run: a NUL byte in the scenario": Case(
        ("run", "{tmp}/nul.yaml"),
        "nul.yaml:1:8: scenario holds a NUL character",
        _files(nul__yaml=b"name: a\x00b\n"),
    ),
    "run: invalid UTF-8 in the scenario": Case(
        ("run", "{tmp}/latin.yaml"),
        "latin.yaml:2:4: scenario is not UTF-8 text (byte 0xe9)",
        _files(latin__yaml=b"name: a\nx: \xe9\n"),
    ),
    "run: an alias bomb in the cell": Case(
        ("run", "--cell", "{tmp}/bomb.yaml", "--dataset", "{data}"),
        "bomb.yaml: more than 100000 YAML nodes with every alias expanded: refused",
        _files(bomb__yaml=BOMB),
    ),
    "run: gravity pointing up": Case(
        ("run", "--cell", "{tmp}/up.yaml", "--dataset", "{data}"),
        "physics.gravity_mps2 = -9.81: must be in (0, 100] m/s^2",
        _files(up__yaml=GRAVITY_UP),
    ),
    "run: a non-zip FMU": Case(
        ("run", "--cell", "{tmp}/fmu.yaml", "--dataset", "{data}"),
        "drive: {tmp}/belt.fmu: not a valid FMU: not a zip archive",
        _files(
            fmu__yaml=GRAVITY_UP.replace("gravity_mps2: -9.81", "gravity_mps2: 9.81").replace(
                "fmu: builtin", "fmu: belt.fmu"
            ),
            belt__fmu="no zip",
        ),
    ),
    "run: --out an existing file": Case(
        ("run", "--out", "{tmp}/file.txt", "--dataset", "{data}"),
        "file.txt: exists and is not a folder",
        _files(file__txt="x"),
    ),
    "run: --out a folder that is not empty": Case(
        ("run", "--out", "{tmp}/full", "--dataset", "{data}"),
        "full: exists and is not empty; choose another --out, or pass --replace",
        (("full/notes.txt", b"mine"),),
    ),
    "run: --replace on a folder no run wrote": Case(
        ("run", "--out", "{tmp}/full", "--replace", "--dataset", "{data}"),
        "refusing to replace a folder that is not a `cdw-twin run` output (it has no .cdw-run",
        (("full/notes.txt", b"mine"),),
    ),
    "run: --out under a file": Case(
        ("run", "--out", "{tmp}/file.txt/run", "--dataset", "{data}"),
        "cannot create it: {tmp}/file.txt is not a folder",
        _files(file__txt="x"),
    ),
    "run: --out where nothing can be created": Case(
        ("run", "--out", "/proc/cdw-twin-no-such/run", "--dataset", "{data}"),
        "--out /proc/cdw-twin-no-such/run: cannot create the output folder",
    ),
    # -- twin-node ------------------------------------------------------------------------
    "twin-node: --foxglove 99999": Case(("twin-node", "--foxglove", "99999"), "not 99999"),
    "twin-node: --record-images -1": Case(
        ("twin-node", "--record-images", "-1"), "must be in [0, 120] Hz (0: no images), not -1"
    ),
    "run: --record-images fast": Case(
        ("run", "--record-images", "fast"), "invalid float value: 'fast'"
    ),
    "twin-node: a seed above 2**64": Case(("twin-node", "--seed", BIG_SEED), "2**64 - 1"),
    "twin-node: a NaN ack timeout": Case(("twin-node", "--ack-timeout", "nan"), "not nan"),
    # -- sweep ----------------------------------------------------------------------------
    "sweep: a seed above 2**64": Case(
        ("sweep", "{tmp}/grid.yaml", "--out", "{tmp}/sweep"),
        "grid.yaml: seeds[0] = 18446744073709551616: must be in [0, 2**64 - 1]",
        _files(grid__yaml=f"scenarios: [{SCENARIOS}/default.yaml]\nseeds: [{BIG_SEED}]\n"),
    ),
    "sweep: an alias bomb": Case(
        ("sweep", "{tmp}/bomb.yaml", "--out", "{tmp}/sweep"),
        "bomb.yaml: more than 100000 YAML nodes",
        _files(bomb__yaml=BOMB),
    ),
    "sweep: a key given twice": Case(
        ("sweep", "{tmp}/grid.yaml", "--out", "{tmp}/sweep"),
        "grid.yaml:2: duplicate key 'seeds' (first on line 1)",
        _files(grid__yaml="seeds: [1]\nseeds: [2]\n"),
    ),
    "sweep: no workers": Case(("sweep", "g.yaml", "--workers", "0"), "must be in [1, 256], not 0"),
    "sweep: --out an existing file": Case(
        ("sweep", f"{SCENARIOS.parent}/grids/line_success.yaml", "--out", "{tmp}/file.txt"),
        "file.txt: exists and is not a folder",
        _files(file__txt="x"),
    ),
    "sweep: --out a folder that is not empty": Case(
        ("sweep", f"{SCENARIOS.parent}/grids/line_success.yaml", "--out", "{tmp}/full"),
        "full: exists and is not empty",
        (("full/notes.txt", b"mine"),),
    ),
    "sweep: --connect-timeout without Ray": Case(
        ("sweep", "g.yaml", "--connect-timeout", "5"), "--connect-timeout needs --backend ray"
    ),
    "sweep: a Ray address that refuses": Case(
        ("sweep", "{tmp}/grid.yaml", "--backend", "ray", "--address", "127.0.0.1:1",
         "--out", "{tmp}/sweep", "--dataset", "{data}", "--transport", "inproc"),
        "--backend ray: cannot connect to the cluster at 127.0.0.1:1: Connection refused",
        _files(grid__yaml=f"scenarios: [{SCENARIOS}/default.yaml]\nseeds: [1]\n"),
    ),
    "sweep: a Ray address that is no address": Case(
        ("sweep", "{tmp}/grid.yaml", "--backend", "ray", "--address", "nowhere",
         "--out", "{tmp}/sweep", "--dataset", "{data}", "--transport", "inproc"),
        "--address 'nowhere': expected HOST:PORT",
        _files(grid__yaml=f"scenarios: [{SCENARIOS}/default.yaml]\nseeds: [1]\n"),
    ),
    # -- report ---------------------------------------------------------------------------
    "report: a binary run.json": Case(
        ("report", "{tmp}/run", "--out", "{tmp}/report"),
        "run.json:1:1: JSON file holds a NUL character",
        (("run/run.json", b"\x00\x01"),),
    ),
    "report: --out an existing file": Case(
        ("report", "{tmp}/run", "--out", "{tmp}/file.txt"),
        "file.txt: exists and is not a folder",
        (("run/run.json", b"{}"), ("file.txt", b"x")),
    ),
    "report: --out a folder that is not empty": Case(
        ("report", "{tmp}/run", "--out", "{tmp}/full"),
        "full: exists and is not empty; choose another --out, or pass --replace",
        (("run/run.json", b"{}"), ("full/notes.txt", b"mine")),
    ),
    "report: --replace on a folder no report wrote": Case(
        ("report", "{tmp}/run", "--out", "{tmp}/full", "--replace"),
        "no .cdw-report marker file",
        (("run/run.json", b"{}"), ("full/notes.txt", b"mine")),
    ),
}  # fmt: skip


def _tree(folder: Path) -> set[str]:
    return {str(p.relative_to(folder)) for p in folder.rglob("*")}


@pytest.mark.parametrize("name", list(CASES))
def test_a_bad_input_is_one_line_exit_2_and_writes_nothing(
    name: str,
    tmp_path: Path,
    builtin_meshes: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    case = CASES[name]
    for relative, data in case.files:
        path = tmp_path / relative
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(data)
    monkeypatch.chdir(tmp_path)  # where a default runs/... folder would go
    before = _tree(tmp_path)
    fill: Callable[[str], str] = lambda s: s.format(tmp=tmp_path, data=builtin_meshes)  # noqa: E731
    try:
        code = main([fill(a) for a in case.argv])
    except SystemExit as exc:  # argparse's refusal of a bad option
        code = int(exc.code or 0)
    err = capsys.readouterr().err
    assert code == 2, err
    assert "Traceback" not in err
    lines = [line for line in err.splitlines() if line and not line.startswith(("usage:", " "))]
    assert len(lines) == 1, err
    assert fill(case.says) in lines[0], err
    assert len(lines[0]) < 600
    assert _tree(tmp_path) == before, "something was written"
    assert not os.path.exists("/proc/cdw-twin-no-such")
