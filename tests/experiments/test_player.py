"""The episode player on a real closed-loop episode, drawn by a real headless Chromium.

Ground truth is read here independently of the player (the ``mcap`` library and its ROS 2
decoder), each object's top view is rebuilt from its mesh (the union of its triangles projected
on the belt, shapely), and the page's documented world-to-pixel mapping (``#scene``'s
``data-px-per-m``, ``data-origin-x``, ``data-origin-y``) says where it must be drawn.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from experiments.player import (
    HIGHLIGHT_HEX,
    STATION_HEX,
    player_data,
    write_player,
)
from experiments.player_footprints import footprint_outline
from experiments.report import write_report

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser") or "chromium"
WINDOW = (1300, 900)


@pytest.fixture
def needs_chromium() -> None:
    """Skip without Chromium; under CI (``CI`` set) fail instead: there the test must run."""
    if shutil.which(CHROMIUM) is None:
        reason = "Chromium is not installed (`.ci/run` installs the chromium package)"
        if os.environ.get("CI"):
            pytest.fail(f"{reason}; CI is set, so the browser test may not be skipped")
        pytest.skip(reason)


# -- fixtures and helpers -----------------------------------------------------------------------
def _run(out: Path, dataset: Path, *extra: str, duration: str = "8") -> Path:
    pytest.importorskip("rclpy")
    pytest.importorskip("cdw_interfaces")
    cmd = [sys.executable, "-m", "twin.cli", "run", "--duration", duration, "--speed", "0.4"]
    cmd += ["--episodes", "1", "--dataset", str(dataset), "--out", str(out), *extra]
    done = subprocess.run(cmd, check=False, timeout=240, capture_output=True, text=True)
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    return out


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory: pytest.TempPathFactory, builtin_meshes: Path) -> Path:
    """One 8 s lockstep episode of the reference cell at 0.4 m/s (real twin and controller)."""
    run = _run(tmp_path_factory.mktemp("player") / "run", builtin_meshes)
    write_player(run / "ep000")
    return run


def _chromium(url: str, *, screenshot: Path | None = None) -> str:
    """Load ``url`` in headless Chromium: its DOM after the scripts ran, or a screenshot."""
    with tempfile.TemporaryDirectory(prefix="chromium-") as profile:
        cmd = [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic"]
        cmd += ["--no-first-run", "--disable-background-networking", "--disable-sync"]
        cmd += ["--disable-component-update", f"--user-data-dir={profile}"]
        cmd += ["--force-device-scale-factor=1", "--hide-scrollbars"]
        cmd += [f"--window-size={WINDOW[0]},{WINDOW[1]}", "--virtual-time-budget=3000"]
        cmd += [f"--screenshot={screenshot}"] if screenshot else ["--dump-dom"]
        done = subprocess.run([*cmd, url], check=True, capture_output=True, text=True, timeout=120)
    return done.stdout


def _screenshot(url: str, path: Path) -> np.ndarray:
    from PIL import Image

    _chromium(url, screenshot=path)
    with Image.open(path) as image:
        return np.asarray(image.convert("RGB")).astype(int)


def _attr(dom: str, name: str) -> str:
    found = re.search(rf'<canvas id="scene"[^>]*\s{name}="([^"]*)"', dom)
    assert found, f"{name} not on #scene"
    return found.group(1)


class Mapping:
    """The page's world-to-page-pixel mapping, read from its DOM."""

    def __init__(self, dom: str) -> None:
        self.s = float(_attr(dom, "data-px-per-m"))
        self.ox = float(_attr(dom, "data-origin-x"))
        self.oy = float(_attr(dom, "data-origin-y"))

    def __call__(self, x: float, y: float) -> tuple[float, float]:
        return self.ox + self.s * x, self.oy - self.s * y


def _ground_truth(recording: Path) -> Iterator[tuple[float, dict[int, Any]]]:
    """``(stamp s, {id: ObjectState})`` of every ground-truth message (mcap + mcap_ros2)."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    with recording.open("rb") as handle:
        reader = make_reader(handle, decoder_factories=[DecoderFactory()])
        for _, _, _, msg in reader.iter_decoded_messages(topics=["/objects/ground_truth"]):
            stamp = msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec
            yield stamp, {int(o.id): o for o in msg.objects}


def _frame_at(frames: list[tuple[float, dict[int, Any]]], t: float) -> tuple[float, dict]:
    """The last ground truth stamped at or before ``t`` (what the page documents to show)."""
    return [f for f in frames if f[0] <= t + 1e-6][-1]


def _mesh_of(run: Path, object_id: int) -> Path:
    events = (run / "ep000" / "twin" / "events.jsonl").read_text(encoding="utf-8")
    spawned = [json.loads(line) for line in events.splitlines() if '"spawned"' in line]
    (source,) = [e["data"]["source_id"] for e in spawned if e["object_id"] == object_id]
    dataset = Path(json.loads((run / "run.json").read_text(encoding="utf-8"))["dataset"])
    (mesh,) = dataset.glob(f"*/{source}.obj")
    return mesh


def _top_view(mesh: Path, state: Any) -> Any:
    """The object's silhouette seen from above (world xy, shapely): every mesh triangle
    stretched to the recorded height, turned and moved by the recorded pose, projected."""
    import shapely
    from scipy.spatial.transform import Rotation

    from meshgen.objfile import read_obj

    obj = read_obj(mesh)
    vertices = obj.vertices.copy()
    vertices[:, 2] *= state.height_m / np.ptp(vertices[:, 2])
    q = state.pose.orientation
    p = state.pose.position
    world = Rotation.from_quat([q.x, q.y, q.z, q.w]).apply(vertices) + np.array([p.x, p.y, p.z])
    triangles = [shapely.Polygon(world[list(face), :2]) for face in obj.faces]
    return shapely.union_all([t for t in triangles if t.area > 0])


def _pixels(image: np.ndarray, hex_colour: str) -> np.ndarray:
    """``(n, 2)`` page-pixel centres (x, y) of the pixels exactly of ``hex_colour``."""
    rgb = [int(hex_colour[i : i + 2], 16) for i in (1, 3, 5)]
    rows, cols = np.nonzero(np.all(image == rgb, axis=2))
    return np.column_stack([cols + 0.5, rows + 0.5])


def _alone(run: Path, states: dict[int, Any], min_area_m2: float = 0.0) -> list[int]:
    """Objects whose top view overlaps no other object's (none drawn over them)."""
    shapes = {oid: _top_view(_mesh_of(run, oid), state) for oid, state in states.items()}
    return [
        oid
        for oid, shape in shapes.items()
        if shape.area > min_area_m2
        and not any(shape.intersects(o) for k, o in shapes.items() if k != oid)
    ]


def _moving_object(run: Path, frames: list, t1: float, t2: float) -> int:
    """An object on the belt at both times, alone at both, that moved 0.3 m in between."""
    _, a = _frame_at(frames, t1)
    _, b = _frame_at(frames, t2)
    alone = set(_alone(run, a)) & set(_alone(run, b))
    for oid in sorted(alone):
        if a[oid].on_belt and b[oid].pose.position.x - a[oid].pose.position.x > 0.3:
            return oid
    pytest.fail(f"no lone object on the belt moved 0.3 m between {t1} s and {t2} s")


def _assert_same_shape(drawn: np.ndarray, shape: Any, to_px: Mapping) -> None:
    """Every drawn pixel lies within 1 px of the expected top view, and every pixel 1 px
    inside it is drawn (so a turned, mirrored or resized footprint fails)."""
    import shapely

    def world(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return (points[:, 0] - to_px.ox) / to_px.s, (to_px.oy - points[:, 1]) / to_px.s

    outer = shape.buffer(1.0 / to_px.s)
    assert shapely.contains_xy(outer, *world(drawn)).all()
    inner = shape.buffer(-1.0 / to_px.s)
    lo_x, hi_y = to_px(inner.bounds[0], inner.bounds[1])
    hi_x, lo_y = to_px(inner.bounds[2], inner.bounds[3])
    cols, rows = np.meshgrid(
        np.arange(int(lo_x), int(hi_x) + 1), np.arange(int(lo_y), int(hi_y) + 1)
    )
    centres = np.column_stack([cols.ravel() + 0.5, rows.ravel() + 0.5])
    wanted = centres[shapely.contains_xy(inner, *world(centres))]
    assert len(wanted) > 50
    have = {(round(x - 0.5), round(y - 0.5)) for x, y in drawn}
    missing = [p for p in wanted if (round(p[0] - 0.5), round(p[1] - 0.5)) not in have]
    assert not missing, f"{len(missing)} of {len(wanted)} pixels inside the footprint not drawn"


# -- the page in a browser ----------------------------------------------------------------------
@pytest.mark.usefixtures("needs_chromium")
def test_drawn_footprints_match_the_recorded_ground_truth_within_a_pixel(
    run_dir: Path, tmp_path: Path
) -> None:
    """With ``#t=T&highlight=ID`` the object is drawn in the highlight colour where the
    recorded pose puts its mesh: centroid of its drawn pixels within 1 px of the projected
    centroid of its top view, at two times."""
    frames = list(_ground_truth(run_dir / "ep000" / "recording.mcap"))
    page = (run_dir / "ep000" / "player.html").as_uri()
    t1, t2 = 2.0 + 1 / 60, 4.5 + 1 / 60
    oid = _moving_object(run_dir, frames, t1, t2)
    mesh = _mesh_of(run_dir, oid)
    for n, t in enumerate((t1, t2)):
        stamp, states = _frame_at(frames, t)
        url = f"{page}#t={t}&highlight={oid}"
        dom = _chromium(url)
        assert float(_attr(dom, "data-frame-t")) == pytest.approx(stamp, abs=1e-4)
        to_px = Mapping(dom)
        shape = _top_view(mesh, states[oid])
        expected = np.array(to_px(shape.centroid.x, shape.centroid.y))
        drawn = _pixels(_screenshot(url, tmp_path / f"hi{n}.png"), HIGHLIGHT_HEX)
        error = np.linalg.norm(drawn.mean(axis=0) - expected)
        assert error <= 1.0, f"object {oid} at t={t}: drawn {drawn.mean(axis=0)}, {expected}"
        _assert_same_shape(drawn, shape, to_px)


@pytest.mark.usefixtures("needs_chromium")
def test_screenshots_at_two_times_differ_where_objects_moved(run_dir: Path, tmp_path: Path) -> None:
    """Where an object lay at t1 the page shows its class colour at t1 and no longer at t2;
    the bins, where nothing arrived in between, look the same."""
    from interfaces.class_colours import class_rgb, dataset_class_rgb, rgb_hex

    frames = list(_ground_truth(run_dir / "ep000" / "recording.mcap"))
    page = (run_dir / "ep000" / "player.html").as_uri()
    t1, t2 = 2.0 + 1 / 60, 4.5 + 1 / 60
    oid = _moving_object(run_dir, frames, t1, t2)
    state = _frame_at(frames, t1)[1][oid]
    to_px = Mapping(_chromium(f"{page}#t={t1}"))
    shape = _top_view(_mesh_of(run_dir, oid), state).buffer(-3.0 / to_px.s)  # off the edges
    a = _screenshot(f"{page}#t={t1}", tmp_path / "a.png")
    b = _screenshot(f"{page}#t={t2}", tmp_path / "b.png")
    minx, miny, maxx, maxy = shape.bounds
    x0, y1 = (round(v) for v in to_px(minx, miny))
    x1, y0 = (round(v) for v in to_px(maxx, maxy))
    import shapely

    def world(x: int, y: int) -> Any:
        return shapely.Point((x + 0.5 - to_px.ox) / to_px.s, (to_px.oy - y - 0.5) / to_px.s)

    inside = [
        (x, y) for x in range(x0, x1 + 1) for y in range(y0, y1 + 1) if shape.contains(world(x, y))
    ]
    assert len(inside) > 20
    dataset = Path(json.loads((run_dir / "run.json").read_text(encoding="utf-8"))["dataset"])
    colour = rgb_hex(class_rgb(state.class_name, dataset_class_rgb(dataset)))
    rgb = np.array([int(colour[i : i + 2], 16) for i in (1, 3, 5)])
    at_t1 = np.mean([np.all(a[y, x] == rgb) for x, y in inside])
    at_t2 = np.mean([np.all(b[y, x] == rgb) for x, y in inside])
    assert at_t1 > 0.9, at_t1
    assert at_t2 < 0.5, at_t2
    assert np.any(a != b)


@pytest.mark.usefixtures("needs_chromium")
def test_clicking_an_object_shows_its_ground_truth_and_its_events(run_dir: Path) -> None:
    """``#click=X,Y`` dispatches a click at the page pixel where the object is drawn: the
    panel names that object, its recorded position and every event it had."""
    frames = list(_ground_truth(run_dir / "ep000" / "recording.mcap"))
    page = (run_dir / "ep000" / "player.html").as_uri()
    t = 2.0 + 1 / 60
    _, states = _frame_at(frames, t)
    to_px = Mapping(_chromium(f"{page}#t={t}"))
    alone = _alone(run_dir, states, min_area_m2=100 / to_px.s**2)
    assert alone
    oid = alone[0]
    point = _top_view(_mesh_of(run_dir, oid), states[oid]).representative_point()
    x, y = to_px(point.x, point.y)
    dom = _chromium(f"{page}#t={t}&click={x},{y}")
    assert f'<table id="gt" data-object="{oid}">' in dom
    p = states[oid].pose.position
    assert f"{p.x:.3f}, {p.y:.3f}, {p.z:.3f}" in dom
    events = (run_dir / "ep000" / "twin" / "events.jsonl").read_text(encoding="utf-8")
    mine = [e for e in map(json.loads, events.splitlines()) if e["object_id"] == oid]
    listed = re.search(r'<ol id="object-events">(.*?)</ol>', dom, re.S)
    assert listed
    items = re.findall(r"<li data-t=\"([^\"]+)\">[^<]* s (\w+) ", listed.group(1))
    assert [(float(t), kind) for t, kind in items] == [
        (pytest.approx(e["time_s"], abs=1e-4), e["type"]) for e in mine
    ]
    assert mine[0]["type"] == "spawned"


@pytest.mark.slow
@pytest.mark.usefixtures("needs_chromium")
def test_a_two_station_line_draws_each_station_tcp_from_its_own_topics(
    tmp_path: Path, builtin_meshes: Path
) -> None:
    """On the two-Panda cell each station's TCP comes from its namespace's ``tcp_pose``
    and is drawn, in the station's colour, where that topic puts it."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    from interfaces.cell import load_cell

    run = _run(tmp_path / "two", builtin_meshes, "--cell", "two_pandas", duration="3")
    write_player(run / "ep000")
    cell = load_cell(run / "cell.yaml")
    assert [s.namespace for s in cell.stations] == ["s1", "s2"]
    page = (run / "ep000" / "player.html").as_uri()
    t = 2.0
    to_px = Mapping(_chromium(f"{page}#t={t}"))
    image = _screenshot(f"{page}#t={t}", tmp_path / "two.png")
    positions = []
    for n, station in enumerate(cell.stations):
        with (run / "ep000" / "recording.mcap").open("rb") as handle:
            reader = make_reader(handle, decoder_factories=[DecoderFactory()])
            poses = [
                (m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec, m.pose.position)
                for _, _, _, m in reader.iter_decoded_messages(topics=[f"/s{n + 1}/tcp_pose"])
            ]
        p = [pos for stamp, pos in poses if stamp <= t + 1e-6][-1]
        positions.append((p.x, p.y))
        x, y = to_px(p.x, p.y)
        rgb = [int(STATION_HEX[n][i : i + 2], 16) for i in (1, 3, 5)]
        for dx, dy in ((0, 0), (2, 0), (-2, 0), (0, 2), (0, -2)):
            pixel = image[round(y - 0.5) + dy, round(x - 0.5) + dx]
            assert list(pixel) == rgb, (station.name, (x, y), pixel)
    assert abs(positions[0][0] - positions[1][0]) > 0.5
    data, _ = player_data(run / "ep000")
    assert [len(tcp["t"]) for tcp in data["tcp"]] == [pytest.approx(90, abs=2)] * 2


# -- footprints ----------------------------------------------------------------------------------
def test_the_footprint_of_a_concave_mesh_is_its_outline_seen_from_above(
    mesh_polygons: Any,
) -> None:
    """An L-shaped object keeps its notch: the outline encloses exactly the area its mesh
    covers seen along its z axis (less than its convex hull), and spans its height."""
    import shapely

    from meshgen.objfile import read_obj

    ell = [(300, 300), (700, 300), (700, 420), (420, 420), (420, 700), (300, 700)]
    out = mesh_polygons({"img": [(1, ell)]})
    (mesh,) = [p for p in out.glob("img/*.obj") if not p.stem.endswith("_convex")]
    footprint = footprint_outline(mesh)
    outline = shapely.Polygon(footprint.ring)
    obj = read_obj(mesh)
    seen = shapely.union_all([shapely.Polygon(t[:, :2]) for t in obj.triangles()])
    assert outline.is_valid
    assert outline.area == pytest.approx(seen.area, rel=1e-6)
    assert outline.symmetric_difference(seen).area < 1e-6 * seen.area
    assert outline.area < 0.8 * outline.convex_hull.area
    z = obj.vertices[:, 2]
    assert (footprint.z_low_m, footprint.z_high_m) == (z.min(), z.max())
    taller = footprint.scaled_z(2 * (z.max() - z.min()))
    assert taller.z_high_m - taller.z_low_m == pytest.approx(2 * (z.max() - z.min()))


# -- the report links a player for every episode ------------------------------------------------
def test_every_episode_row_of_the_report_links_an_existing_player(
    run_dir: Path, tmp_path: Path
) -> None:
    """An episode without a recording still gets a player (belt, bins and events, with a note
    saying what is missing); every link of the page resolves to the episode's player."""
    run = tmp_path / "run"
    shutil.copytree(run_dir, run)
    shutil.copytree(run / "ep000", run / "ep001")
    (run / "ep001" / "recording.mcap").unlink()
    for page in run.glob("ep*/player.html"):
        page.unlink()
    out = tmp_path / "report"
    html = write_report([run], out).read_text(encoding="utf-8")
    links = re.findall(r'<a class="player" href="([^"]+)">', html)
    assert [(out / link).resolve() for link in links] == [
        run / "ep000" / "player.html",
        run / "ep001" / "player.html",
    ]
    second = (run / "ep001" / "player.html").read_text(encoding="utf-8")
    assert "recording.mcap: missing" in second
    for page in (run / "ep000" / "player.html", run / "ep001" / "player.html"):
        text = page.read_text(encoding="utf-8")
        assert not re.search(r"<link|<img|\ssrc=|fetch\(|XMLHttpRequest|import\(", text)
    assert "recording.mcap: missing" in html
    data, _ = player_data(run / "ep001")
    assert data["objects"] == []
    assert data["cell"] is not None
    assert data["cell"]["stations"][0]["bins"]
    assert len(data["events"]) == len(
        (run / "ep001" / "twin" / "events.jsonl").read_text(encoding="utf-8").splitlines()
    )


def test_without_the_dataset_objects_are_their_recorded_boxes(
    run_dir: Path, tmp_path: Path
) -> None:
    """A run whose dataset is gone still plays: every object a length x width x height box of
    its recorded extents, and the page says why."""
    run = tmp_path / "run"
    shutil.copytree(run_dir, run)
    info = json.loads((run / "run.json").read_text(encoding="utf-8"))
    info["dataset"] = str(tmp_path / "gone")
    (run / "run.json").write_text(json.dumps(info), encoding="utf-8")
    data, notes = player_data(run / "ep000")
    assert any("gone not found" in note for note in notes)
    frames = list(_ground_truth(run / "ep000" / "recording.mcap"))
    first = {}
    for _, states in frames:
        for oid, state in states.items():
            first.setdefault(oid, state)
    assert [o["id"] for o in data["objects"]] == sorted(first)
    for o in data["objects"]:
        state = first[o["id"]]
        assert o["outline_from"] == "box"
        xs = [x * 1e-4 for x, _ in o["outline"]]
        ys = [y * 1e-4 for _, y in o["outline"]]
        assert max(xs) - min(xs) == pytest.approx(state.length_m, abs=2e-4)
        assert max(ys) - min(ys) == pytest.approx(state.width_m, abs=2e-4)
        assert (o["zspan"][1] - o["zspan"][0]) * 1e-4 == pytest.approx(state.height_m, abs=2e-4)


def test_a_page_is_made_from_the_player_modules_and_every_asset() -> None:
    """The report refreshes a player older than any of these files (its frames, footprints and
    assets included: a change to the script or the style alone must reach every page)."""
    from experiments import player, player_footprints, player_frames
    from experiments.player import ASSETS, page_sources

    sources = page_sources()
    assets = sorted(p for p in ASSETS.rglob("*") if p.is_file())
    assert {"player.css", "player.js", "player_body.html"} <= {p.name for p in assets}
    assert set(assets) <= set(sources)
    for module in (player, player_frames, player_footprints):
        assert Path(str(module.__file__)).resolve() in sources
    assert all(path.is_file() for path in sources)
