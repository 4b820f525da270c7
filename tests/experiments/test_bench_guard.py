"""``cdw-twin bench guard``: the comparison's rules on hand-made baselines, and one cheap family
end to end through the CLI."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from experiments.bench_guard import FAMILIES, compare
from twin.errors import CdwTwinError


def _baseline(**figures: tuple[float, str, float]) -> dict[str, object]:
    return {
        "version": 1,
        "figures": {
            name.replace("__", "."): {"value": v, "better": better, "tolerance_abs": tol}
            for name, (v, better, tol) in figures.items()
        },
    }


def test_a_drop_beyond_its_tolerance_fails_and_names_the_figure() -> None:
    base = _baseline(line__success_rate=(0.95, "higher", 0.02))
    (row,) = compare(base, {"line.success_rate": 0.90})
    assert row["figure"] == "line.success_rate"
    assert row["ok"] is False
    assert "higher is better" in str(row["why"])
    (within,) = compare(base, {"line.success_rate": 0.935})
    assert within["ok"] is True


def test_an_improvement_passes_in_either_direction() -> None:
    base = _baseline(
        reference_0__4__tracking=(1.0, "lower", 0.03), throughput__ppm=(19.0, "higher", 0.5)
    )
    rows = compare(base, {"reference_0.4.tracking": 0.8, "throughput.ppm": 25.0})
    assert [r["ok"] for r in rows] == [True, True]
    worse = compare(base, {"reference_0.4.tracking": 1.2, "throughput.ppm": 19.0})
    assert {r["figure"]: r["ok"] for r in worse} == {
        "reference_0.4.tracking": False,
        "throughput.ppm": True,
    }


def test_a_figure_not_measured_fails() -> None:
    (row,) = compare(_baseline(fmu__us_per_step=(12.0, "lower", 5.0)), {})
    assert row["ok"] is False
    assert row["why"] == "not measured"


def test_a_relative_tolerance_scales_with_the_baseline() -> None:
    base = {"figures": {"twin.rtf": {"value": 10.0, "better": "higher", "tolerance_rel": 0.5}}}
    assert compare(base, {"twin.rtf": 5.5})[0]["ok"] is True
    assert compare(base, {"twin.rtf": 4.5})[0]["ok"] is False


def test_a_broken_baseline_entry_is_named() -> None:
    with pytest.raises(CdwTwinError, match=r"'line\.success_rate'"):
        compare({"figures": {"line.success_rate": {"better": "higher"}}}, {})


def test_the_shipped_baseline_covers_every_family() -> None:
    shipped = json.loads(
        (Path(__file__).parents[2] / "experiments" / "guard_baseline.json").read_text("utf-8")
    )
    families = {name.rsplit(".", 1)[0] for name in shipped["figures"]}
    assert families == {f.name for f in FAMILIES}


def _guard(*args: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "twin.cli", "bench", "guard", *args],
        capture_output=True,
        text=True,
        check=False,
        cwd=cwd,
        timeout=120,
    )


def test_one_family_end_to_end_update_then_check(tmp_path: Path) -> None:
    baseline = tmp_path / "baseline.json"
    first = _guard("--only", "fmu", "--update", "--json", "--baseline", str(baseline), cwd=tmp_path)
    assert first.returncode == 0, first.stderr
    report = json.loads(first.stdout)
    assert report["updated"] is True
    (row,) = report["figures"]
    assert row["figure"] == "fmu.us_per_step"
    assert row["measured"] > 0
    assert (
        json.loads(baseline.read_text("utf-8"))["figures"]["fmu.us_per_step"]["better"] == "lower"
    )
    # a baseline 100x faster than anything this machine does: the check fails and says which
    entry = json.loads(baseline.read_text("utf-8"))
    entry["figures"]["fmu.us_per_step"]["value"] = row["measured"] / 100
    baseline.write_text(json.dumps(entry), encoding="utf-8")
    second = _guard("--only", "fmu", "--baseline", str(baseline), cwd=tmp_path)
    assert second.returncode == 1
    assert "BAD fmu.us_per_step" in second.stdout
    unknown = _guard("--only", "nope", cwd=tmp_path)
    assert unknown.returncode != 0
    assert "nope" in unknown.stderr
