"""Read OBJ meshes: the ones meshgen writes, and plain OBJ files from other tools.

meshgen writes two kinds of OBJ file per object (:mod:`meshgen.pipeline`): ``<id>.obj``, one
``o <id>`` block with the prism's ``v`` lines, one ``vt`` line per ``v`` line (its texture
coordinate, same index) and ``f a/a b/b c/c`` faces, and, for a concave footprint,
``<id>_convex.obj`` with one ``o piece_k`` block per convex piece, each a closed prism (no
texture coordinates). :func:`read_obj` gives back the numbers in the file: the vertices as
written, the faces as 0-based vertex indices, the ``o`` blocks (:class:`ObjGroup`) and, when the
file gives every vertex its own texture coordinate, those (:attr:`ObjMesh.uv`).

Understood lines: ``v x y z`` (further numbers, a ``w`` or a colour, are ignored), ``vt u v``
(a further ``w`` is ignored), ``f`` with three or more corners written ``i``, ``i/t``, ``i//n``
or ``i/t/n`` (``i`` from 1, or negative: counted back from the last vertex so far),
fan-triangulated as ``(a, b, c), (a, c, d), ...``, and ``o NAME``. Vertex indices count through
the whole file, whatever block they are in, as OBJ defines them. Every other line (comments,
``mtllib``, ``usemtl``, ``vn``, ``s``, ``g``, ``l``) is ignored. A malformed ``v``, ``vt`` or
``f`` line raises :class:`~meshgen.errors.ObjFileError` naming the file and the line number
(and quoting at most :data:`QUOTE_CHARS` characters of the line).

Example::

    mesh = read_obj(Path("out/sample_000/sample_000_002_convex.obj"))
    pieces = [mesh.vertices[g.vertices] for g in mesh.groups]
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt

from meshgen.annotations import FloatArray
from meshgen.errors import ObjFileError

IntArray = npt.NDArray[np.int64]

QUOTE_CHARS = 80
"""An error quotes at most this many characters of the offending line."""


def quote(line: str) -> str:
    """``repr`` of ``line`` cut to :data:`QUOTE_CHARS` characters (``...`` marks a cut)."""
    if len(line) <= QUOTE_CHARS:
        return repr(line)
    return repr(line[:QUOTE_CHARS]) + "..."


@dataclass(frozen=True, slots=True)
class ObjGroup:
    """One ``o`` block of an OBJ file: its name, and the vertices and faces written in it.

    ``vertices`` and ``faces`` are slices of :attr:`ObjMesh.vertices` and
    :attr:`ObjMesh.faces`. Lines before the first ``o`` line form a block named ``""`` (a file
    without ``o`` lines is one such block).
    """

    name: str
    vertices: slice
    faces: slice


@dataclass(frozen=True, slots=True)
class ObjMesh:
    """The geometry of one OBJ file.

    ``vertices`` is ``(n, 3) float`` in file order; ``faces`` is ``(t, 3) int``, 0-based indices
    into ``vertices``, one row per triangle (polygons fan-triangulated); ``groups`` are the
    ``o`` blocks in file order. ``uv`` is the ``(n, 2) float`` texture coordinate of each
    vertex when the file gives every vertex one of its own (as meshgen writes them: as many
    ``vt`` as ``v`` lines, and every face corner names the ``vt`` of its vertex's index);
    otherwise None (no ``vt`` lines, or coordinates shared or split between vertices).
    """

    vertices: FloatArray
    faces: IntArray
    groups: tuple[ObjGroup, ...]
    uv: FloatArray | None = None

    def triangles(self) -> FloatArray:
        """The corners of every face, ``(t, 3, 3) float``."""
        corners: FloatArray = self.vertices[self.faces]
        return corners

    def group_vertices(self) -> list[FloatArray]:
        """Each group's vertices, ``[(k_i, 3) float, ...]`` (the convex pieces of a pieces file)."""
        return [self.vertices[group.vertices] for group in self.groups]


class _Builder:
    """The vertices, faces and groups read so far, with the file name for error messages."""

    def __init__(self, source: str) -> None:
        self.source = source
        self.vertices: list[tuple[float, float, float]] = []
        self.faces: list[tuple[int, int, int]] = []
        self.starts: list[tuple[str, int, int]] = []  # (name, first vertex, first face)
        self.coords: list[tuple[float, float]] = []
        self.aligned = True  # every corner so far names the vt of its own vertex index

    def _error(self, number: int, line: str, why: str) -> ObjFileError:
        return ObjFileError(f"{self.source}:{number}: malformed line {quote(line)}: {why}")

    def vertex(self, tokens: list[str], number: int, line: str) -> None:
        try:
            x, y, z = (float(token) for token in tokens[1:4])
        except ValueError:
            raise self._error(number, line, "a vertex needs 3 numbers") from None
        if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(z)):
            raise self._error(number, line, "a coordinate is not finite")
        self._open_implicit_group()
        self.vertices.append((x, y, z))

    def texture(self, tokens: list[str]) -> None:
        coord = texture_coordinate(tokens[1:])
        if coord is None:
            self.aligned = False  # uv is optional: a malformed vt only means no uv
            coord = (math.nan, math.nan)
        self.coords.append(coord)

    def face(self, tokens: list[str], number: int, line: str) -> None:
        count = len(self.vertices)
        corners = [token.split("/") for token in tokens[1:]]
        try:
            ids = [int(corner[0]) for corner in corners]
        except ValueError:
            raise self._error(number, line, "a corner is not an index") from None
        if len(ids) < 3:
            raise self._error(number, line, "a face needs 3 corners")
        ids = [i - 1 if i > 0 else count + i for i in ids]
        if any(not 0 <= i < count for i in ids):
            msg = (
                f"{self.source}:{number}: face {quote(line)} refers to a vertex not defined "
                "before it"
            )
            raise ObjFileError(msg)
        if self.aligned:
            self.aligned = self._texture_of_own_index(corners, ids)
        self._open_implicit_group()
        first = ids[0]
        self.faces.extend((first, ids[k], ids[k + 1]) for k in range(1, len(ids) - 1))

    def _texture_of_own_index(self, corners: list[list[str]], ids: list[int]) -> bool:
        """True when every corner names the texture coordinate of its vertex's index."""
        textures = len(self.coords)
        for corner, vertex in zip(corners, ids, strict=True):
            if len(corner) < 2 or not corner[1]:
                return False
            try:
                t = int(corner[1])
            except ValueError:
                return False
            if (t - 1 if t > 0 else textures + t) != vertex:
                return False
        return True

    def group(self, tokens: list[str]) -> None:
        self.starts.append((" ".join(tokens[1:]), len(self.vertices), len(self.faces)))

    def _open_implicit_group(self) -> None:
        if not self.starts:
            self.starts.append(("", 0, 0))

    def mesh(self) -> ObjMesh:
        n_vertices, n_faces = len(self.vertices), len(self.faces)
        uv = None
        if self.aligned and self.coords and len(self.coords) == n_vertices:
            uv = np.array(self.coords, dtype=np.float64).reshape(-1, 2)
        return ObjMesh(
            vertices=np.array(self.vertices, dtype=np.float64).reshape(-1, 3),
            faces=np.array(self.faces, dtype=np.int64).reshape(-1, 3),
            groups=_groups(self.starts, n_vertices, n_faces),
            uv=uv,
        )


def _groups(
    starts: list[tuple[str, int, int]], n_vertices: int, n_faces: int
) -> tuple[ObjGroup, ...]:
    """The groups that begin at ``starts`` ``(name, first vertex, first face)``, in order."""
    ends = [(v, f) for _, v, f in starts[1:]] + [(n_vertices, n_faces)]
    return tuple(
        ObjGroup(name, slice(v0, v1), slice(f0, f1))
        for (name, v0, f0), (v1, f1) in zip(starts, ends[: len(starts)], strict=True)
    )


@dataclass(frozen=True, slots=True)
class _Lines:
    """The ``v``, ``vt`` and ``f`` lines of a file without their keyword, and where groups begin."""

    vertices: list[str]
    coords: list[str]
    faces: list[str]
    defined: IntArray  # per face line: the number of vertices defined before it
    defined_coords: IntArray  # per face line: the number of vt lines before it
    starts: list[tuple[str, int, int]]


def _sort_lines(lines: list[str]) -> _Lines | None:
    """The ``v``, ``vt``, ``f`` and ``o`` lines of a file whose keywords all start their line.

    None when some ``v``, ``vt``, ``f`` or ``o`` keyword is written otherwise (indented,
    followed by a tab, alone on its line).
    """
    v_lines: list[str] = []
    vt_lines: list[str] = []
    f_lines: list[str] = []
    defined: list[int] = []
    defined_coords: list[int] = []
    starts: list[tuple[str, int, int]] = []
    for line in lines:
        head = line[:2]
        if head == "v ":
            v_lines.append(line[2:])
        elif head == "f ":
            f_lines.append(line[2:])
            defined.append(len(v_lines))
            defined_coords.append(len(vt_lines))
        elif head == "vt" and line[2:3] == " ":
            vt_lines.append(line[3:])
        elif head == "o ":
            if not starts and (v_lines or f_lines):
                starts.append(("", 0, 0))
            starts.append((" ".join(line.split()[1:]), len(v_lines), len(f_lines)))
        elif line.split(None, 1)[:1] in (["v"], ["vt"], ["f"], ["o"]):
            return None
    if not starts and (v_lines or f_lines):
        starts.append(("", 0, 0))
    return _Lines(
        vertices=v_lines,
        coords=vt_lines,
        faces=f_lines,
        defined=np.array(defined, dtype=np.int64).reshape(-1, 1),
        defined_coords=np.array(defined_coords, dtype=np.int64).reshape(-1, 1),
        starts=starts,
    )


def _simple_faces(found: _Lines) -> tuple[IntArray, IntArray | None] | None:
    """The ``(t, 3)`` 1-based (or negative) vertex indices of triangles ``f a b c`` or
    ``f a/s b/t c/u``, and the texture indices of the latter (None for the former).

    None for any other face line (a missing corner, ``a//n``, a polygon, a mix of both forms).
    """
    face_text = " ".join(found.faces)
    slashes = face_text.count("/")
    tokens = face_text.split()
    if len(tokens) != 3 * len(found.faces):
        return None
    try:
        if not slashes:
            return np.array(list(map(int, tokens)), dtype=np.int64).reshape(-1, 3), None
        if slashes != len(tokens) or "//" in face_text:
            return None
        pairs = np.array(list(map(int, face_text.replace("/", " ").split())), dtype=np.int64)
    except (ValueError, OverflowError):
        return None
    if len(pairs) != 6 * len(found.faces):
        return None
    pairs = pairs.reshape(-1, 3, 2)
    return pairs[:, :, 0], pairs[:, :, 1]


def texture_coordinate(numbers: list[str]) -> tuple[float, float] | None:
    """``(u, v)`` of a ``vt`` line's numbers (``u [v [w]]``, ``v`` 0 when left out), or None
    when they are not one to three finite numbers."""
    if not 1 <= len(numbers) <= 3:
        return None
    try:
        u = float(numbers[0])
        v = float(numbers[1]) if len(numbers) > 1 else 0.0
    except ValueError:
        return None
    return (u, v) if math.isfinite(u) and math.isfinite(v) else None


def _simple_uv(found: _Lines, faces: IntArray, texture_ids: IntArray | None) -> FloatArray | None:
    """The per-vertex uv of a file whose every corner names the vt of its own index, else None.

    The ``(t, 3)`` ``texture_ids`` are the corners' ``vt`` indices as written (None: the faces
    name none).
    """
    if texture_ids is None or len(found.coords) != len(found.vertices) or not found.coords:
        return None
    coords = [texture_coordinate(line.split()) for line in found.coords]
    if any(c is None for c in coords):
        return None
    count = found.defined_coords
    named = np.where(texture_ids > 0, texture_ids - 1, count + texture_ids)
    if not np.array_equal(named, faces):
        return None
    return np.array(coords, dtype=np.float64).reshape(-1, 2)


def _parse_simple(lines: list[str]) -> ObjMesh | None:
    """:func:`parse_obj` of a file as meshgen writes it, vectorised; None for any other file.

    Handles ``v x y z`` with finite numbers, ``vt u v`` and triangles ``f a b c`` or
    ``f a/s b/t c/u`` of plain indices (positive or negative) that refer to vertices defined
    before them, each keyword at the start of its line. Anything else (a malformed line
    included) returns None, and the line-by-line reader gives the result or the error.
    """
    found = _sort_lines(lines)
    if found is None:
        return None
    simple = _simple_faces(found)
    if simple is None:
        return None
    ids, texture_ids = simple
    vertex_tokens = " ".join(found.vertices).split()
    if len(vertex_tokens) != 3 * len(found.vertices):
        return None
    try:
        vertices = np.array(list(map(float, vertex_tokens)), dtype=np.float64).reshape(-1, 3)
    except (ValueError, OverflowError):
        return None
    count = found.defined
    faces = np.where(ids > 0, ids - 1, count + ids)
    if not (np.isfinite(vertices).all() and ((faces >= 0) & (faces < count)).all()):
        return None
    uv = _simple_uv(found, faces, texture_ids)
    groups = _groups(found.starts, len(vertices), len(faces))
    return ObjMesh(vertices=vertices, faces=faces, groups=groups, uv=uv)


def parse_obj(text: str, source: str = "<obj>") -> ObjMesh:
    """The :class:`ObjMesh` of OBJ ``text``; ``source`` names it in error messages."""
    lines = text.splitlines()
    simple = _parse_simple(lines)
    if simple is not None:
        return simple
    builder = _Builder(source)
    for number, line in enumerate(lines, start=1):
        tokens = line.split()
        if not tokens:
            continue
        key = tokens[0]
        if key == "v":
            builder.vertex(tokens, number, line)
        elif key == "vt":
            builder.texture(tokens)
        elif key == "f":
            builder.face(tokens, number, line)
        elif key == "o":
            builder.group(tokens)
    return builder.mesh()


def read_obj(path: Path) -> ObjMesh:
    """The :class:`ObjMesh` of the UTF-8 OBJ file at ``path``.

    Raises :class:`~meshgen.errors.ObjFileError` naming the file when it cannot be read or
    decoded, and the file and line for a malformed ``v`` or ``f`` line.
    """
    try:
        text = Path(path).read_text(encoding="utf-8")
    except OSError as exc:
        msg = f"{path}: cannot read: {exc.strerror}"
        raise ObjFileError(msg) from None
    except UnicodeDecodeError as exc:
        msg = f"{path}: not UTF-8 text (byte {exc.start}): not an OBJ file"
        raise ObjFileError(msg) from None
    return parse_obj(text, str(path))
