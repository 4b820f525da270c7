"""``cdw-twin report`` on a real closed-loop run: figures, tables, offline HTML in chromium."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from experiments.report import FIGURES, write_report
from experiments.report_data import ReportError, load_runs

CHROMIUM = Path("/usr/bin/chromium")
PROBE_SCRIPT = (
    "<script>window.addEventListener('load', () => {"
    " for (const img of document.images) img.setAttribute('data-natural-width', img.naturalWidth);"
    "});</script>"
)


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory: pytest.TempPathFactory, builtin_meshes: Path) -> Path:
    """One 5 s lockstep episode at 0.4 m/s, twin node and controller as real processes."""
    pytest.importorskip("rclpy")
    pytest.importorskip("cdw_interfaces")
    out = tmp_path_factory.mktemp("runs") / "run_a"
    cmd = [sys.executable, "-m", "twin.cli", "run", "--duration", "5", "--speed", "0.4"]
    cmd += ["--episodes", "1", "--dataset", str(builtin_meshes), "--out", str(out), "--json"]
    subprocess.run(cmd, check=True, timeout=180, capture_output=True)
    return out


def _img_sources(page: str) -> list[str]:
    return re.findall(r'<img [^>]*src="([^"]+)"', page)


def test_the_run_leaves_telemetry_with_matched_round_trips(run_dir: Path) -> None:
    twin = run_dir / "ep000" / "twin"
    telemetry = json.loads((twin / "telemetry.json").read_text(encoding="utf-8"))
    summary = json.loads((twin / "summary.json").read_text(encoding="utf-8"))
    rtt = telemetry["rtt"]["rtt_ms"]
    assert len(rtt) > 100
    assert min(rtt) > 0.0
    assert summary["latency"]["samples"] == len(rtt)
    assert summary["latency"]["unmatched_commands"] == 0
    assert 0 < summary["latency"]["rtt_ms_p50"] <= summary["latency"]["rtt_ms_p99"]
    assert summary["step_rate_hz_mean"] > 0
    belt = telemetry["belt"]
    assert belt["sim_s"][-1] == pytest.approx(5.0, abs=0.2)
    assert belt["speed_mps"][-1] == pytest.approx(0.4, abs=0.05)
    assert set(belt["setpoint_mps"]) == {0.4}


def test_report_has_every_figure_and_opens_offline_in_chromium(
    run_dir: Path, tmp_path: Path
) -> None:
    out = tmp_path / "report"
    html_path = write_report([run_dir], out)
    page = html_path.read_text(encoding="utf-8")
    sources = _img_sources(page)
    assert sources == [f"{stem}.png" for stem, _, _ in FIGURES]
    assert "not available" not in page
    assert "http://" not in page
    assert "https://" not in page
    for src in sources:
        assert (out / src).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert not list(out.glob(".*.tmp"))
    assert "RTT p50 (ms)" in page
    assert "RTT p99 (ms)" in page
    assert 'id="perception"' not in page  # the oracle has nothing to score: no empty section
    if not CHROMIUM.is_file():
        pytest.skip(f"no chromium at {CHROMIUM}: `apt-get install chromium` to run this check")
    probe = out / "probe.html"
    probe.write_text(page.replace("</body>", PROBE_SCRIPT + "</body>"), encoding="utf-8")
    flags = ["--headless", "--disable-gpu", "--no-sandbox", "--virtual-time-budget=5000"]
    flags.append("--host-resolver-rules=MAP * ~NOTFOUND")
    dom = subprocess.run(
        [str(CHROMIUM), *flags, "--dump-dom", probe.as_uri()],
        check=True,
        capture_output=True,
        text=True,
        timeout=120,
    ).stdout
    widths = dict(re.findall(r'<img [^>]*src="([^"]+)"[^>]*data-natural-width="(\d+)"', dom))
    assert set(widths) == set(sources)
    assert all(int(w) > 0 for w in widths.values()), widths
    shot = tmp_path / "shot.png"
    subprocess.run(
        [
            str(CHROMIUM),
            *flags,
            "--window-size=1200,3000",
            f"--screenshot={shot}",
            html_path.as_uri(),
        ],
        check=True,
        capture_output=True,
        timeout=120,
    )
    assert shot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_missing_telemetry_gives_not_available_panels(run_dir: Path, tmp_path: Path) -> None:
    old = tmp_path / "old_run"
    shutil.copytree(run_dir, old)
    (old / "ep000" / "twin" / "telemetry.json").unlink()
    out = tmp_path / "report"
    page = write_report([old], out).read_text(encoding="utf-8")
    for stem in ("step_rate", "belt", "rtt_time", "rtt_hist"):
        assert f'id="na-{stem}">not available: no episode has telemetry' in page
        assert not (out / f"{stem}.png").exists()
    for stem in ("rates", "meshgen", "footprints"):
        assert f'src="{stem}.png"' in page


def test_a_folder_of_runs_is_accepted(run_dir: Path, tmp_path: Path) -> None:
    parent = tmp_path / "runs"
    shutil.copytree(run_dir, parent / "a")
    shutil.copytree(run_dir, parent / "b")
    page = write_report([parent], tmp_path / "report").read_text(encoding="utf-8")
    assert "a/ep000" in page
    assert "b/ep000" in page
    assert len(_img_sources(page)) == len(FIGURES)


def test_folder_without_run_json_is_a_clear_error(tmp_path: Path) -> None:
    empty = tmp_path / "not_a_run"
    empty.mkdir()
    with pytest.raises(ReportError, match=r"not_a_run: has no run\.json"):
        write_report([empty], tmp_path / "report")
    with pytest.raises(ReportError, match=r"missing: does not exist"):
        write_report([tmp_path / "missing"], tmp_path / "report")


def test_cli_reports_a_bad_folder_and_exits_2(tmp_path: Path) -> None:
    result = subprocess.run(
        [sys.executable, "-m", "twin.cli", "report", str(tmp_path)],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert result.returncode == 2
    assert f"{tmp_path}: has no run.json" in result.stderr


def test_an_episode_that_did_not_finish_is_left_out_with_a_note(
    run_dir: Path, tmp_path: Path
) -> None:
    """A failed or stopped episode (``complete: false``) never enters the report's numbers."""
    copy = tmp_path / "run_copy"
    shutil.copytree(run_dir, copy)
    shutil.copytree(copy / "ep000", copy / "ep001")
    summary_path = copy / "ep001" / "twin" / "summary.json"
    summary = json.loads(summary_path.read_text(encoding="utf-8"))
    summary["complete"] = False
    summary_path.write_text(json.dumps(summary), encoding="utf-8")
    data = load_runs([copy])
    assert [ep.folder.name for ep in data.episodes] == ["ep000"]
    assert any("ep001" in note and "did not finish" in note for note in data.notes)


def _event(kind: str, oid: int, **data: object) -> str:
    raw = {"time_s": 1.0, "step": 240, "type": kind, "object_id": oid, "class_name": "brick"}
    return json.dumps({**raw, "data": data})


def _score(run: Path) -> None:
    """Write the run's ``episodes.json`` as ``cdw-twin run`` does once its episodes finish."""
    from experiments.scoring import score_episode
    from interfaces.run_folder import RunFolder
    from interfaces.run_records import write_rows

    folder = RunFolder(run)
    rows = [score_episode(e.path, "lockstep") for e in folder.episodes()]
    write_rows(folder.episodes_json, rows)


def _two_station_run(folder: Path) -> Path:
    """A run folder of the two-Panda cell, written by hand: object 4 was released downstream
    and is still falling into its bin at the end; the upstream controller was restarted."""
    from interfaces.cell import load_cell

    up, down = {"station": "upstream"}, {"station": "downstream"}
    events = [_event("spawned", i) for i in range(1, 6)]
    for oid in (1, 2, 3):
        events += [
            _event("pick_success", oid, **up),
            _event("placed_in_bin", oid, correct=True, **up),
        ]
    events += [_event("missed", 4, **up), _event("missed", 5, **up), _event("missed", 5, **down)]
    events.append(_event("pick_success", 4, **down))
    folder.mkdir(parents=True)
    load_cell("two_pandas").save(folder / "cell.yaml")
    (folder / "run.json").write_text(json.dumps({"dataset": str(folder / "none")}))
    episode = folder / "ep000"
    (episode / "twin").mkdir(parents=True)
    summary: dict[str, object] = {"belt_speed_mps": 0.3, "seed": 1, "sim_seconds": 60.0}
    summary["complete"] = True
    summary |= {"real_time_factor": 1.0, "landing_in_bins": [4]}
    (episode / "twin" / "summary.json").write_text(json.dumps(summary))
    (episode / "twin" / "events.jsonl").write_text("\n".join(events) + "\n")
    for name, completed in (("upstream", 2), ("upstream_1", 1), ("downstream", 1)):
        pick = {"completed": completed, "aborted": {}, "untargeted": {}}
        (episode / f"controller-{name}.json").write_text(json.dumps({"pick": pick}))
    _score(folder)
    return folder


def test_the_report_counts_as_the_run_does_and_adds_a_table_per_station(tmp_path: Path) -> None:
    """Targeted objects come from every controller of every station, less the objects still
    landing (``interfaces.metrics.targeted_objects``), exactly as in ``episodes.json``."""
    from experiments.report import episode_rows, station_rows
    from interfaces.run_records import EpisodeMetrics, read_rows

    run = _two_station_run(tmp_path / "run")
    data = load_runs([run])
    (row,) = episode_rows(data)
    (expected,) = read_rows(run / "episodes.json")
    assert isinstance(expected, EpisodeMetrics)
    assert (row.targeted, row.picked, row.missed) == (3, 4, 1)
    for key in ("targeted", "picked", "missed", "processed", "placed_correct", "success_rate"):
        assert getattr(row, key) == expected.metric(key), key
    by_station = {r.station: r for r in station_rows(data)}
    assert (by_station["upstream"].targeted, by_station["downstream"].targeted) == (3, 0)
    assert by_station["upstream"].success_rate == 1.0
    assert by_station["downstream"].miss_rate == 0.5
    page = write_report([run], tmp_path / "report").read_text(encoding="utf-8")
    assert 'id="per-station"' in page
    assert "<td>downstream</td>" in page


def _line_sweep(root: Path) -> Path:
    """A sweep folder written by hand: the first 1 and 2 stations of a line at 0.2 and
    0.4 m/s, two seeds each. Episode (k stations, speed, seed): 10 bricks and 1 wood enter;
    ``k + seed`` bricks come to rest in the last station's brick bin, the other bricks are
    missed by it, and the wood comes to rest in the first station's brick bin; a 12th object, a
    brick, is still on the belt at the end: undecided, out of the complete cohort (recovery
    (k + seed) / 11)."""
    from experiments.sweep_grid import first_stations
    from interfaces.cell import load_cell

    line = load_cell(Path(__file__).resolve().parent / "cells" / "line_standin.yaml")
    for k in (1, 2):
        cell = first_stations(line, k, "grid")
        names = [s.name for s in cell.stations]
        for speed in (0.2, 0.4):
            run = root / f"line-speed{speed}-stations{k}"
            run.mkdir(parents=True)
            cell.save(run / "cell.yaml")
            info = {"dataset": str(root / "none"), "cell": cell.name, "stations": names}
            (run / "run.json").write_text(json.dumps(info))
            for seed in (1, 2):
                events = [_event("spawned", i) for i in range(1, 11)]
                events.append(_event("spawned", 11).replace('"brick"', '"wood"'))
                for oid in range(1, k + seed + 1):
                    events.append(_event("pick_success", oid, station=names[-1]))
                    events.append(
                        _event("placed_in_bin", oid, bin="brick", correct=True, station=names[-1])
                    )
                events += [
                    _event("missed", oid, station=names[-1]) for oid in range(k + seed + 1, 11)
                ]
                wood = _event("pick_success", 11, station=names[0])
                wrong = _event("placed_in_bin", 11, bin="brick", correct=False, station=names[0])
                events += [
                    raw.replace('"brick", "data"', '"wood", "data"') for raw in (wood, wrong)
                ]
                events.append(_event("spawned", 12))
                episode = run / f"ep{seed - 1:03d}"
                (episode / "twin").mkdir(parents=True)
                summary: dict[str, object] = {"belt_speed_mps": speed, "seed": seed}
                summary["sim_seconds"] = 60.0
                summary |= {"complete": True, "real_time_factor": 0.5, "landing_in_bins": []}
                (episode / "twin" / "summary.json").write_text(json.dumps(summary))
                (episode / "twin" / "events.jsonl").write_text("\n".join(events) + "\n")
                for name in names:
                    pick = {"completed": k + seed, "aborted": {}, "untargeted": {}}
                    stem = "controller" if len(names) == 1 else f"controller-{name}"
                    (episode / f"{stem}.json").write_text(json.dumps({"pick": pick}))
            _score(run)
    return root


def test_the_report_of_a_line_sweep_draws_recovery_against_stations_and_purity_tables(
    tmp_path: Path,
) -> None:
    """``cdw-twin report`` on a sweep over ``stations`` x speed: a table and a figure of the
    mean recovery over the seeds with its 95 % t interval per number of stations, one line per
    speed; recovery and purity per class and purity per bin."""
    from scipy import stats as scipy_stats

    from experiments.report import bin_rows, class_rows, recovery_by_stations, speed_rows

    sweep = _line_sweep(tmp_path / "sweep")
    data = load_runs([sweep])
    rows = recovery_by_stations(data)
    assert [(r.stations, r.speed_mps, r.episodes) for r in rows] == [
        (1, 0.2, 2),
        (1, 0.4, 2),
        (2, 0.2, 2),
        (2, 0.4, 2),
    ]
    for row in rows:
        k = row.stations
        values = [(k + 1) / 11, (k + 2) / 11]
        half = scipy_stats.t.ppf(0.975, 1) * scipy_stats.tstd(values) / 2**0.5
        assert row.recovery_mean == pytest.approx((2 * k + 3) / 22)
        assert row.recovery_ci95 == pytest.approx(
            (row.recovery_mean - half, row.recovery_mean + half)
        )
        assert row.recovery_pooled == pytest.approx((2 * k + 3) / 22)
    speeds = speed_rows(data)
    assert [(r.cell, r.stations) for r in speeds] == [
        ("line_standin_first1", 1),
        ("line_standin_first1", 1),
        ("line_standin_first2", 2),
        ("line_standin_first2", 2),
    ]
    # two episodes of 12 spawned objects, 11 of each in the complete cohort, 3 + 4 recovered
    assert (speeds[-1].totals["spawned"], speeds[-1].totals["entered"]) == (24, 22)
    assert speeds[-1].recovery_rate == pytest.approx(7 / 22)
    by_class = {(r.cell, r.speed_mps, r.class_name): r for r in class_rows(data)}
    brick = by_class[("line_standin_first2", 0.4, "brick")]
    assert (brick.entered, brick.recovered) == (20, 7)
    assert (brick.placed_correct, brick.binned) == (7, 9)
    assert brick.recovery_rate == pytest.approx(7 / 20)
    assert brick.purity == pytest.approx(7 / 9)
    assert by_class[("line_standin_first2", 0.4, "wood")].recovery_rate == 0.0
    bins = {(r.cell, r.speed_mps, r.station, r.bin): r for r in bin_rows(data)}
    first = bins[("line_standin_first2", 0.4, "first", "brick")]
    second = bins[("line_standin_first2", 0.4, "second", "brick")]
    assert (first.binned, first.placed_correct, first.purity) == (2, 0, 0.0)
    assert (second.binned, second.purity) == (7, 1.0)
    out = tmp_path / "report"
    page = write_report([sweep], out).read_text(encoding="utf-8")
    assert 'id="fig-recovery_stations"' in page
    assert (out / "recovery_stations.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    for anchor in ("recovery-stations", "per-class", "per-bin", "per-station"):
        assert f'id="{anchor}"' in page
    assert "<td>line_standin_first2</td>" in page


def test_a_run_without_its_rows_is_a_note_and_its_episodes_have_no_numbers(
    tmp_path: Path,
) -> None:
    """The report reads the rows the run wrote and scores nothing itself: without
    ``episodes.json``, or with a row that is not a record, the episode is listed without
    numbers and the notes say why."""
    from experiments.report import episode_rows

    missing = _two_station_run(tmp_path / "missing")
    (missing / "episodes.json").unlink()
    broken = _two_station_run(tmp_path / "broken")
    (broken / "episodes.json").write_text(json.dumps([{"episode": 0, "seed": "one"}]))
    for run, why in ((missing, "No such file"), (broken, "episodes.json[0].seed")):
        data = load_runs([run])
        (row,) = episode_rows(data)
        assert (row.picked, row.targeted, row.success_rate) == (None, None, None)
        assert data.episodes[0].metrics is None
        assert any(note.startswith(f"{run}: no metrics") and why in note for note in data.notes)
        assert any("ep000: no metrics (no row of episodes.json)" in note for note in data.notes)
        page = write_report([run], tmp_path / f"report_{run.name}").read_text(encoding="utf-8")
        assert f"{run}: no metrics" in page


def test_the_rows_the_run_wrote_are_the_numbers_even_when_the_events_say_otherwise(
    tmp_path: Path,
) -> None:
    """Scored once: the report's numbers are the written row's, not a new scoring of the
    episode's events (here the events are changed after the run wrote its row)."""
    from experiments.report import episode_rows

    run = _two_station_run(tmp_path / "run")
    events = run / "ep000" / "twin" / "events.jsonl"
    events.write_text(events.read_text() + _event("pick_success", 5, station="downstream") + "\n")
    (row,) = episode_rows(load_runs([run]))
    assert row.picked == 4


def test_a_player_is_rewritten_when_its_code_or_any_asset_is_newer(
    run_dir: Path, tmp_path: Path
) -> None:
    """The report refreshes an episode's player when the player's module or any file of
    ``experiments/player_assets/`` is newer than the page (a change to the script or the style
    alone must reach every page), and leaves an up-to-date page alone."""
    import os

    from experiments import player
    from experiments.report_players import is_stale, player_inputs

    copy = tmp_path / "run"
    shutil.copytree(run_dir, copy)
    inputs = player_inputs(copy / "ep000")
    assets = sorted(p for p in player.ASSETS.rglob("*") if p.is_file())
    assert {"player.css", "player.js", "player_body.html"} <= {p.name for p in assets}
    assert set(assets) <= set(inputs)
    assert Path(player.__file__).resolve() in inputs
    page = copy / "ep000" / player.PAGE_NAME
    write_report([copy], tmp_path / "first")
    assert page.is_file()
    assert not is_stale(page, inputs)
    newest = max(p.stat().st_mtime for p in inputs if p.is_file())
    os.utime(page, (newest + 10, newest + 10))
    write_report([copy], tmp_path / "second")
    assert page.stat().st_mtime == newest + 10  # up to date: left alone
    for asset in assets:
        os.utime(page, (asset.stat().st_mtime - 1, asset.stat().st_mtime - 1))
        assert is_stale(page, inputs), asset
    write_report([copy], tmp_path / "third")
    assert page.stat().st_mtime > newest  # older than an asset: rewritten


def test_a_page_is_stale_when_missing_or_older_than_an_input_that_exists(tmp_path: Path) -> None:
    import os

    from experiments.report_players import is_stale

    page, source, gone = tmp_path / "player.html", tmp_path / "player.js", tmp_path / "gone.css"
    source.write_text("script")
    assert is_stale(page, [source, gone])
    page.write_text("page")
    os.utime(source, (100.0, 100.0))
    os.utime(page, (200.0, 200.0))
    assert not is_stale(page, [source, gone])
    os.utime(source, (300.0, 300.0))
    assert is_stale(page, [source, gone])
