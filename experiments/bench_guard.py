"""``cdw-twin bench guard``: the headline figure of every shipped scenario family and bench,
compared with a committed baseline, so a regression cannot pass unseen.

Each family runs as a subprocess of the public CLI (the same commands a user types), two at a
time on two cores: the reference cell at 0.2 / 0.4 / 0.6 m/s, the throughput scenario, one
station with the suction cup and one with the wide gripper, the line on the built-in sample (all
lockstep, in process, seed 1), and the meshgen, FMU, twin and round-trip benches. Episode
figures are deterministic for the same code and seed, so their tolerances are narrow (a change
that moves one is a change to argue); speed figures drift by +-30 % on a shared two-core
machine, so theirs are wide and only a slowdown counts.

The baseline (``experiments/guard_baseline.json``) holds per figure its value, which direction
is better and its tolerance: ``max(tolerance_abs, tolerance_rel * |value|)``. ``--update``
rewrites it from the run (atomically); a figure that could not be measured is a failure with
the command's last lines of stderr, never skipped.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

from twin.errors import CdwTwinError

BASELINE_PATH = Path(__file__).with_name("guard_baseline.json")
"""The committed baseline, beside this module."""

STDERR_TAIL_CHARS = 1500
"""How much of a failed command's stderr the report keeps."""

JsonObject = dict[str, object]


@dataclass(frozen=True, kw_only=True)
class Rule:
    """How one figure is judged: ``better`` is ``higher`` or ``lower``; the tolerance is the
    larger of ``tolerance_abs`` and ``tolerance_rel`` times the baseline's magnitude."""

    better: str
    tolerance_abs: float = 0.0
    tolerance_rel: float = 0.0

    def tolerance(self, baseline: float) -> float:
        """The allowed move against the better direction from ``baseline``."""
        return max(self.tolerance_abs, self.tolerance_rel * abs(baseline))


SUCCESS = Rule(better="higher", tolerance_abs=0.02)
RECOVERY = Rule(better="higher", tolerance_abs=0.02)
PICKS_PER_MIN = Rule(better="higher", tolerance_abs=0.5)
TRACKING_S = Rule(better="lower", tolerance_abs=0.03)
SPEED_HIGHER = Rule(better="higher", tolerance_rel=0.5)
SPEED_LOWER = Rule(better="lower", tolerance_rel=1.0)


@dataclass(frozen=True, kw_only=True)
class Family:
    """One command and the figures read from its JSON output (key -> rule)."""

    name: str
    argv: Callable[[Path], list[str]]
    figures: dict[str, Rule]


def _episode(*args: str, duration_s: float) -> Callable[[Path], list[str]]:
    def argv(out: Path) -> list[str]:
        return [
            "run",
            *args,
            "--transport",
            "inproc",
            "--seed",
            "1",
            "--duration",
            f"{duration_s:g}",
            "--json",
            "--no-record",
            "--out",
            str(out),
        ]

    return argv


_REFERENCE = {
    "success_rate": SUCCESS,
    "tracking_time_4mm_mean_s": TRACKING_S,
    "pick_throughput_per_min": PICKS_PER_MIN,
}
_STATION = {"success_rate": SUCCESS, "recovery_rate": RECOVERY}
_SCENARIOS = Path(__file__).with_name("scenarios")

FAMILIES: tuple[Family, ...] = (
    Family(
        name="line", argv=_episode(str(_SCENARIOS / "line.yaml"), duration_s=20), figures=_STATION
    ),
    *(
        Family(
            name=f"reference_{speed}",
            argv=_episode("--speed", speed, duration_s=30),
            figures=_REFERENCE,
        )
        for speed in ("0.2", "0.4", "0.6")
    ),
    Family(
        name="throughput",
        argv=_episode(str(_SCENARIOS / "throughput.yaml"), duration_s=30),
        figures={"pick_throughput_per_min": PICKS_PER_MIN, "success_rate": SUCCESS},
    ),
    Family(
        name="suction",
        argv=_episode(str(_SCENARIOS / "suction.yaml"), duration_s=30),
        figures=_STATION,
    ),
    Family(
        name="wide_gripper",
        argv=_episode(str(_SCENARIOS / "wide_gripper.yaml"), duration_s=30),
        figures=_STATION,
    ),
    Family(
        name="meshgen",
        argv=lambda out: ["bench", "meshgen", "--json", "--repeats", "1"],
        figures={"ms_per_object": SPEED_LOWER},
    ),
    Family(
        name="fmu",
        argv=lambda out: ["bench", "fmu", "--json", "--steps", "20000"],
        figures={"us_per_step": SPEED_LOWER},
    ),
    Family(
        name="twin",
        argv=lambda out: ["bench", "twin", "--json", "--seconds", "5", "--repeats", "2"],
        figures={"real_time_factor": SPEED_HIGHER},
    ),
    Family(
        name="rtt",
        argv=lambda out: ["bench", "rtt", "--json", "--count", "500", "--rate", "100"],
        figures={"p50_ms": SPEED_LOWER},
    ),
)
"""Every family, longest first (two run at a time). Headline of each bench: meshgen's
milliseconds per object in RAM (its own headline), the FMU's microseconds per step, the
twin's real-time factor with 40 objects (best of two), the round trip's median (its p99 is
dominated by the machine's other load)."""


@dataclass(frozen=True, kw_only=True)
class Measured:
    """What one family gave: its figures, or the error that kept it from giving them."""

    family: str
    figures: dict[str, float]
    error: str | None
    wall_s: float


def _cli() -> list[str]:
    return [sys.executable, "-m", "twin.cli"]


def _measure(family: Family, work: Path) -> Measured:
    out = work / family.name
    cmd = [*_cli(), *family.argv(out)]
    start = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, check=False, env=os.environ.copy())
    wall_s = time.perf_counter() - start
    if proc.returncode != 0:
        error = (
            f"`{' '.join(cmd[2:])}` exited {proc.returncode}: {proc.stderr[-STDERR_TAIL_CHARS:]}"
        )
        return Measured(family=family.name, figures={}, error=error, wall_s=wall_s)
    try:
        data = json.loads(proc.stdout[proc.stdout.index("{") :])
    except (ValueError, json.JSONDecodeError) as exc:
        error = f"`{' '.join(cmd[2:])}` printed no JSON object ({exc}): {proc.stdout[-300:]}"
        return Measured(family=family.name, figures={}, error=error, wall_s=wall_s)
    figures: dict[str, float] = {}
    for key in family.figures:
        value = data.get(key)
        if isinstance(value, int | float) and math.isfinite(value):
            figures[key] = float(value)
    return Measured(family=family.name, figures=figures, error=None, wall_s=wall_s)


def compare(baseline: JsonObject, measured: Mapping[str, float | None]) -> list[JsonObject]:
    """One row per baseline figure (``family.key``): baseline, measured, delta and whether it
    holds; a figure missing from ``measured`` (None) fails. Pure: the tests call it."""
    rows: list[JsonObject] = []
    for name, entry in sorted(_figures(baseline).items()):
        try:
            rule = Rule(
                better=str(entry["better"]),
                tolerance_abs=float(entry.get("tolerance_abs", 0.0)),  # type: ignore[arg-type]
                tolerance_rel=float(entry.get("tolerance_rel", 0.0)),  # type: ignore[arg-type]
            )
            base = float(entry["value"])  # type: ignore[arg-type]
        except (KeyError, TypeError, ValueError) as exc:
            raise CdwTwinError(f"guard baseline: figure {name!r}: bad entry ({exc})") from None
        value = measured.get(name)
        row: JsonObject = {"figure": name, "baseline": base, "better": rule.better}
        if value is None:
            row.update(measured=None, delta=None, ok=False, why="not measured")
        else:
            delta = value - base
            worse = -delta if rule.better == "higher" else delta
            ok = worse <= rule.tolerance(base) + 1e-12
            row.update(measured=value, delta=delta, ok=ok, tolerance=rule.tolerance(base))
            if not ok:
                allowed = rule.tolerance(base)
                row["why"] = (
                    f"{rule.better} is better: moved {delta:+.4g} (tolerance {allowed:.4g})"
                )
        rows.append(row)
    return rows


def _baseline_of(runs: Sequence[Measured]) -> JsonObject:
    rules = {f.name: f.figures for f in FAMILIES}
    figures: JsonObject = {}
    for run in runs:
        for key, value in run.figures.items():
            rule = rules[run.family][key]
            figures[f"{run.family}.{key}"] = {
                "value": value,
                "better": rule.better,
                "tolerance_abs": rule.tolerance_abs,
                "tolerance_rel": rule.tolerance_rel,
            }
    return {"version": 1, "figures": figures}


def _write_atomic(path: Path, text: str) -> None:
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(text)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def _selected(only: str | None) -> tuple[Family, ...]:
    if not only:
        return FAMILIES
    names = [n.strip() for n in only.split(",") if n.strip()]
    known = {f.name for f in FAMILIES}
    unknown = [n for n in names if n not in known]
    if unknown:
        msg = f"--only: unknown {', '.join(unknown)}; families: {', '.join(sorted(known))}"
        raise CdwTwinError(msg)
    return tuple(f for f in FAMILIES if f.name in names)


def configure(parser: argparse.ArgumentParser) -> None:
    """``cdw-twin bench guard`` options."""
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument("--update", action="store_true", help="rewrite the baseline from this run")
    parser.add_argument("--only", default=None, help="families to run, comma-separated")
    parser.add_argument(
        "--baseline", type=Path, default=BASELINE_PATH, help="baseline file (default: shipped)"
    )


def _figures(baseline: JsonObject) -> dict[str, JsonObject]:
    """The baseline's figures by name, checked to be a mapping of mappings."""
    figures = baseline.get("figures")
    if not isinstance(figures, dict) or not all(isinstance(v, dict) for v in figures.values()):
        raise CdwTwinError("guard baseline: 'figures' must map each figure to its entry")
    return {str(k): v for k, v in figures.items()}


def _load_baseline(path: Path) -> JsonObject:
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError) as exc:
        raise CdwTwinError(f"{path}: cannot read the guard baseline: {exc}") from None
    if not isinstance(data, dict):
        raise CdwTwinError(f"{path}: the guard baseline must be a JSON object")
    return data


def run(args: argparse.Namespace) -> int:
    """Run the families two at a time, compare, print; 1 on any regression."""
    families = _selected(args.only)
    start = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="cdw-guard-") as tmp, ThreadPoolExecutor(2) as pool:
        runs = list(pool.map(lambda f: _measure(f, Path(tmp)), families))
    wall_s = time.perf_counter() - start
    errors = {r.family: r.error for r in runs if r.error is not None}
    if args.update:
        if errors:
            raise CdwTwinError(f"not updating the baseline: {json.dumps(errors)}")
        kept = (
            _figures(_load_baseline(args.baseline)) if args.only and args.baseline.exists() else {}
        )
        kept.update(_figures(_baseline_of(runs)))
        text = json.dumps({"version": 1, "figures": kept}, indent=2, sort_keys=True)
        _write_atomic(args.baseline, text + "\n")
    names = {f.name for f in families}
    every = _figures(_load_baseline(args.baseline))
    scoped: JsonObject = {
        "figures": {k: v for k, v in every.items() if k.rsplit(".", 1)[0] in names}
    }
    measured = {f"{r.family}.{k}": v for r in runs for k, v in r.figures.items()}
    rows = compare(scoped, measured)
    failed = [row for row in rows if not row["ok"]]
    report: JsonObject = {
        "ok": not failed and not errors,
        "updated": bool(args.update),
        "wall_s": round(wall_s, 1),
        "figures": rows,
        "regressions": [row["figure"] for row in failed],
        "errors": errors,
        "family_wall_s": {r.family: round(r.wall_s, 1) for r in runs},
    }
    if args.json:
        print(json.dumps(report, indent=2))
    else:
        for row in rows:
            mark = "ok " if row["ok"] else "BAD"
            print(f"{mark} {row['figure']}: {row['measured']} (baseline {row['baseline']})")
        for family, error in errors.items():
            print(f"ERR {family}: {error}")
        if args.update:
            print(f"baseline written: {args.baseline}")
        print(f"{'no regression' if report['ok'] else 'REGRESSION'} ({wall_s:.0f} s)")
    return 0 if report["ok"] else 1
