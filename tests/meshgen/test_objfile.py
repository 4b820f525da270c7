"""The OBJ reader gives back exactly what meshgen wrote, and names the line of a malformed file."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from meshgen.errors import ObjFileError
from meshgen.footprint import Footprint, build_footprints
from meshgen.mesh import extrude, hertel_mehlhorn, triangulate
from meshgen.objfile import ObjMesh, parse_obj, read_obj
from meshgen.pipeline import DatasetSummary
from meshgen.prisms import prism_texts

SQUARE = np.array([[0.0, 0.0], [0.12, 0.0], [0.12, 0.1], [0.0, 0.1]])
ELL = np.array([[0.0, 0.0], [0.2, 0.0], [0.2, 0.05], [0.05, 0.05], [0.05, 0.15], [0.0, 0.15]])


def _comb(teeth: int) -> np.ndarray:
    """A comb-shaped CCW outline (concave: ``teeth`` teeth on top) away from the origin, in m."""
    x0 = 0.3
    top = []
    for k in reversed(range(teeth)):
        x = x0 + 0.04 * k
        top += [(x + 0.03, 0.2), (x + 0.03, 0.26 + 0.003 * k), (x + 0.01, 0.26), (x + 0.01, 0.2)]
    return np.array(
        [(x0, -0.1), (x0 + 0.04 * teeth, -0.1), (x0 + 0.04 * teeth, 0.2), *top, (x0, 0.2)]
    )


def _footprints(rings: list[np.ndarray]) -> list[Footprint]:
    built = build_footprints(rings, simplify_m=0.0, min_area_m2=1e-6)
    assert all(isinstance(fp, Footprint) for fp in built)
    return [fp for fp in built if isinstance(fp, Footprint)]


def _as_written(values: np.ndarray) -> np.ndarray:
    """``values`` as the ``%.6f`` text of an OBJ ``v`` line reads back."""
    return np.vectorize(lambda v: float(f"{v:.6f}"))(values)


def _expected_prism(fp: Footprint, height_m: float, up: str) -> tuple[np.ndarray, np.ndarray]:
    """The vertices (as written) and faces of the prism over ``fp``, from :func:`extrude`."""
    local = fp.ring_m - np.array(fp.centroid_m)
    vertices, faces = extrude(local, triangulate(local), height_m)
    if up == "y":
        vertices = np.stack((vertices[:, 0], vertices[:, 2], -vertices[:, 1]), axis=1)
    return _as_written(vertices), faces


def _signed_volume(mesh: ObjMesh, faces: np.ndarray | None = None) -> float:
    corners = mesh.vertices[mesh.faces if faces is None else faces]
    a, b, c = corners[:, 0], corners[:, 1], corners[:, 2]
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)


@pytest.mark.parametrize("up", ["z", "y"])
def test_prism_files_read_back_exactly_as_written(tmp_path: Path, up: str) -> None:
    fps = _footprints([SQUARE, ELL, _comb(5)])
    heights = [0.05, 0.031, 0.0123456789]
    ids = ["img_000", "img_001", "img_002"]
    texts = prism_texts(fps, heights, [ring * 1000.0 for ring in (SQUARE, ELL, _comb(5))], ids, up)
    for fp, height, name, body in zip(fps, heights, ids, texts.mesh, strict=True):
        path = tmp_path / f"{name}.obj"
        path.write_text(f"# cdw-twin meshgen {name}\nmtllib ../materials.mtl\nusemtl brick\n{body}")
        mesh = read_obj(path)
        vertices, faces = _expected_prism(fp, height, up)
        np.testing.assert_array_equal(mesh.vertices, vertices)
        np.testing.assert_array_equal(mesh.faces, faces)
        assert [(g.name, g.vertices, g.faces) for g in mesh.groups] == [
            (name, slice(0, len(vertices)), slice(0, len(faces)))
        ]
        np.testing.assert_array_equal(mesh.triangles(), vertices[faces])


@pytest.mark.parametrize("up", ["z", "y"])
def test_convex_pieces_read_back_one_group_per_piece(tmp_path: Path, up: str) -> None:
    comb = _comb(6)
    (fp,) = _footprints([comb])
    assert not fp.convex
    height = 0.04
    texts = prism_texts([fp], [height], [comb * 1000.0], ["img_007"], up)
    path = tmp_path / "img_007_convex.obj"
    path.write_text(texts.pieces[0])
    pieces = read_obj(path)
    local = fp.ring_m - np.array(fp.centroid_m)
    expected = hertel_mehlhorn([local], [triangulate(local)])
    sizes = expected.sizes.tolist()
    assert [g.name for g in pieces.groups] == [f"piece_{k}" for k in range(len(sizes))]
    assert len(sizes) == texts.n_pieces[0] > 1
    prism, _ = _expected_prism(fp, height, up)
    n = len(local)
    starts = np.cumsum(sizes) - sizes
    for group, start, size in zip(pieces.groups, starts.tolist(), sizes, strict=True):
        ring = expected.vertices[start : start + size]
        # the piece's bottom corners, then its top corners, as written for the whole prism
        want = np.concatenate((prism[ring], prism[ring + n]))
        np.testing.assert_array_equal(pieces.vertices[group.vertices], want)
        faces = pieces.faces[group.faces]
        assert len(faces) == 4 * size - 4
        assert faces.min() == group.vertices.start
        assert faces.max() == group.vertices.stop - 1
        assert _signed_volume(pieces, faces) > 0.0  # each piece is a closed, outward prism
    whole = ObjMesh(vertices=prism, faces=_expected_prism(fp, height, up)[1], groups=())
    assert _signed_volume(pieces) == pytest.approx(_signed_volume(whole), rel=1e-12)
    assert [len(v) for v in pieces.group_vertices()] == [2 * s for s in sizes]


def test_pipeline_meshes_match_their_scene_rows(meshed: DatasetSummary) -> None:
    out = meshed.out
    checked = concave = 0
    for scene_csv in sorted(out.glob("*/scene.csv")):
        folder = scene_csv.parent
        with scene_csv.open(encoding="utf-8", newline="") as handle:
            rows = list(csv.DictReader(handle))
        entries = json.loads((folder / "scene.json").read_text())["objects"]
        for row, entry in zip(rows, entries, strict=True):
            mesh = read_obj(folder / row["mesh_path"])
            ring = np.array(entry["footprint_m"]) - [entry["centroid_x_m"], entry["centroid_y_m"]]
            n = len(ring)
            assert mesh.vertices.shape == (2 * n, 3)
            assert mesh.faces.shape == (4 * n - 4, 3)
            assert [g.name for g in mesh.groups] == [row["object_id"]]
            np.testing.assert_allclose(mesh.vertices[:n, :2], ring, atol=1.5e-6)
            np.testing.assert_allclose(mesh.vertices[n:, :2], ring, atol=1.5e-6)
            half = 0.5 * entry["height_m"]
            np.testing.assert_allclose(mesh.vertices[:, 2], [-half] * n + [half] * n, atol=6e-7)
            volume = _signed_volume(mesh)
            assert volume == pytest.approx(entry["volume_m3"], rel=1e-3)
            if row["convex_path"]:
                pieces = read_obj(folder / row["convex_path"])
                assert len(pieces.groups) == int(row["n_convex_pieces"]) > 1
                assert _signed_volume(pieces) == pytest.approx(volume, rel=1e-9)
                concave += 1
            checked += 1
    assert checked == meshed.objects
    assert concave > 0


def test_line_by_line_reading_gives_the_same_mesh(meshed: DatasetSummary) -> None:
    # meshgen's own files take the vectorised route; with a tab after every keyword the same
    # file takes the line-by-line one, which must give the same arrays and groups
    paths = sorted(meshed.out.glob("*/*.obj"))
    assert any(p.name.endswith("_convex.obj") for p in paths)
    for path in paths[:60]:
        text = path.read_text()
        fast = parse_obj(text)
        slow = parse_obj(text.replace("v ", "v\t").replace("f ", "f\t").replace("o ", "o\t"))
        np.testing.assert_array_equal(fast.vertices, slow.vertices)
        np.testing.assert_array_equal(fast.faces, slow.faces)
        assert fast.groups == slow.groups
    relative = parse_obj("o tri\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf -3 -2 -1\n")
    np.testing.assert_array_equal(relative.faces, [[0, 1, 2]])
    assert relative.groups[0].name == "tri"


def test_plain_obj_from_other_tools(tmp_path: Path) -> None:
    text = (
        "# exported elsewhere\nmtllib x.mtl\nv 0 0 0\nv 1 0 0 1.0\nv 1 1 0 0.5 0.5 0.5\n"
        "v 0 1 0\nvt 0 0\nvn 0 0 1\ng side\ns off\nusemtl red\n"
        "f 1/1/1 2/1/1 3/1/1 4/1/1\nf -4//1 -2//1 -1//1\no second\nv 0 0 1\nf 1 2 5\n"
    )
    mesh = parse_obj(text, "quad.obj")
    np.testing.assert_array_equal(
        mesh.vertices, [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1]]
    )
    np.testing.assert_array_equal(mesh.faces, [[0, 1, 2], [0, 2, 3], [0, 2, 3], [0, 1, 4]])
    assert [(g.name, g.vertices, g.faces) for g in mesh.groups] == [
        ("", slice(0, 4), slice(0, 3)),
        ("second", slice(4, 5), slice(3, 4)),
    ]
    empty = parse_obj("# nothing\n")
    assert empty.vertices.shape == (0, 3)
    assert empty.faces.shape == (0, 3)
    assert empty.groups == ()


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("v 0 0 0\nv 1 0 0\nv 0 one 0\nf 1 2 3\n", r"bad\.obj:3: malformed line 'v 0 one 0'"),
        ("v 0 0\n", r"bad\.obj:1: malformed line 'v 0 0': a vertex needs 3 numbers"),
        ("v 0 0 nan\n", r"bad\.obj:1: .*not finite"),
        ("v 0 0 0\nv 1 0 0\nf 1 2 9\n", r"bad\.obj:3: face 'f 1 2 9' refers to a vertex"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 0\n", r"bad\.obj:4: face 'f 1 2 0' refers"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 -4\n", r"bad\.obj:4: face 'f 1 2 -4' refers"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2\n", r"bad\.obj:4: .*a face needs 3 corners"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 x 3\n", r"bad\.obj:4: .*a corner is not an index"),
    ],
)
def test_malformed_lines_are_named(tmp_path: Path, text: str, match: str) -> None:
    path = tmp_path / "bad.obj"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(ObjFileError, match=match):
        read_obj(path)


def test_unreadable_files_are_named(tmp_path: Path) -> None:
    with pytest.raises(ObjFileError, match=r"gone\.obj: cannot read"):
        read_obj(tmp_path / "gone.obj")
    binary = tmp_path / "binary.obj"
    binary.write_bytes(b"v 0 0 0\n\xff\xfe\n")
    with pytest.raises(ObjFileError, match=r"binary\.obj: not UTF-8"):
        read_obj(binary)


def test_texture_coordinates_read_back_on_both_routes(meshed: DatasetSummary) -> None:
    paths = sorted(meshed.out.glob("*/*.obj"))
    textured = [p for p in paths if not p.name.endswith("_convex.obj")]
    assert textured
    for path in textured[:40]:
        text = path.read_text()
        assert text.count("\nvt ") == text.count("\nv ")
        fast = parse_obj(text)
        slow = parse_obj(text.replace("v ", "v\t").replace("vt ", "vt\t").replace("f ", "f\t"))
        assert fast.uv is not None
        assert fast.uv.shape == (len(fast.vertices), 2)
        assert slow.uv is not None
        np.testing.assert_array_equal(fast.uv, slow.uv)
        np.testing.assert_array_equal(fast.faces, slow.faces)
        assert ((fast.uv >= 0.0) & (fast.uv <= 1.0)).all()
    for path in paths:
        if path.name.endswith("_convex.obj"):
            assert read_obj(path).uv is None


def test_uv_only_when_every_vertex_has_its_own() -> None:
    own = "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nf 1/1 2/2 3/3\n"
    np.testing.assert_array_equal(parse_obj(own).uv, [[0, 0], [1, 0], [0, 1]])
    shared = own.replace("f 1/1 2/2 3/3", "f 1/1 2/1 3/1")
    assert parse_obj(shared).uv is None
    fewer = "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/1 2/1 3/1\n"
    assert parse_obj(fewer).uv is None
    # OBJ lets a vt line give u alone (v = 0) and a malformed vt line only costs the uv
    alone = own.replace("vt 1 0\n", "vt 1\n")
    np.testing.assert_array_equal(parse_obj(alone).uv, [[0, 0], [1, 0], [0, 1]])
    broken = own.replace("vt 1 0\n", "vt one 0\n")
    assert parse_obj(broken).uv is None
    np.testing.assert_array_equal(parse_obj(broken).faces, [[0, 1, 2]])
    relative = own.replace("f 1/1 2/2 3/3", "f -3/-3 -2/-2 -1/-1")
    np.testing.assert_array_equal(parse_obj(relative).uv, [[0, 0], [1, 0], [0, 1]])


def test_an_error_quotes_at_most_80_characters_of_the_line(tmp_path: Path) -> None:
    path = tmp_path / "long.obj"
    path.write_text("v 0 0 0\nv 1 0 " + "x" * 100_000 + "\n", encoding="utf-8")
    with pytest.raises(ObjFileError, match=r"long\.obj:2: malformed line 'v 1 0 x+'\.\.\.") as info:
        read_obj(path)
    assert len(str(info.value)) < 250
    face = tmp_path / "face.obj"
    face.write_text("v 0 0 0\nf 1 2 " + "3 " * 50_000 + "\n", encoding="utf-8")
    with pytest.raises(ObjFileError, match=r"face\.obj:2: face 'f 1 2 3 .*'\.\.\. refers") as info:
        read_obj(face)
    assert len(str(info.value)) < 250
