"""Read OBJ meshes: the ones meshgen writes, and plain OBJ files from other tools.

meshgen writes two kinds of OBJ file per object (:mod:`meshgen.pipeline`): ``<id>.obj``, one
``o <id>`` block with the prism's ``v`` and ``f`` lines, and, for a concave footprint,
``<id>_convex.obj`` with one ``o piece_k`` block per convex piece, each a closed prism.
:func:`read_obj` gives back the numbers in the file: the vertices as written, the faces as
0-based vertex indices, and the ``o`` blocks (:class:`ObjGroup`).

Understood lines: ``v x y z`` (further numbers, a ``w`` or a colour, are ignored), ``f`` with
three or more corners written ``i``, ``i/t``, ``i//n`` or ``i/t/n`` (``i`` from 1, or negative:
counted back from the last vertex so far), fan-triangulated as ``(a, b, c), (a, c, d), ...``,
and ``o NAME``. Vertex indices count through the whole file, whatever block they are in, as OBJ
defines them. Every other line (comments, ``mtllib``, ``usemtl``, ``vt``, ``vn``, ``s``, ``g``,
``l``) is ignored. A malformed ``v`` or ``f`` line raises :class:`~meshgen.errors.ObjFileError`
naming the file and the line number.

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
    ``o`` blocks in file order.
    """

    vertices: FloatArray
    faces: IntArray
    groups: tuple[ObjGroup, ...]

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

    def vertex(self, tokens: list[str], number: int, line: str) -> None:
        try:
            x, y, z = (float(token) for token in tokens[1:4])
        except ValueError:
            msg = f"{self.source}:{number}: malformed line {line!r}: a vertex needs 3 numbers"
            raise ObjFileError(msg) from None
        if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(z)):
            msg = f"{self.source}:{number}: malformed line {line!r}: a coordinate is not finite"
            raise ObjFileError(msg)
        self._open_implicit_group()
        self.vertices.append((x, y, z))

    def face(self, tokens: list[str], number: int, line: str) -> None:
        count = len(self.vertices)
        try:
            ids = [int(token.split("/", 1)[0]) for token in tokens[1:]]
        except ValueError:
            msg = f"{self.source}:{number}: malformed line {line!r}: a corner is not an index"
            raise ObjFileError(msg) from None
        if len(ids) < 3:
            msg = f"{self.source}:{number}: malformed line {line!r}: a face needs 3 corners"
            raise ObjFileError(msg)
        ids = [i - 1 if i > 0 else count + i for i in ids]
        if any(not 0 <= i < count for i in ids):
            msg = f"{self.source}:{number}: face {line!r} refers to a vertex not defined before it"
            raise ObjFileError(msg)
        self._open_implicit_group()
        first = ids[0]
        self.faces.extend((first, ids[k], ids[k + 1]) for k in range(1, len(ids) - 1))

    def group(self, tokens: list[str]) -> None:
        self.starts.append((" ".join(tokens[1:]), len(self.vertices), len(self.faces)))

    def _open_implicit_group(self) -> None:
        if not self.starts:
            self.starts.append(("", 0, 0))

    def mesh(self) -> ObjMesh:
        n_vertices, n_faces = len(self.vertices), len(self.faces)
        return ObjMesh(
            vertices=np.array(self.vertices, dtype=np.float64).reshape(-1, 3),
            faces=np.array(self.faces, dtype=np.int64).reshape(-1, 3),
            groups=_groups(self.starts, n_vertices, n_faces),
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
    """The ``v`` and ``f`` lines of a file without their keyword, and where groups begin."""

    vertices: list[str]
    faces: list[str]
    defined: IntArray  # per face line: the number of vertices defined before it
    starts: list[tuple[str, int, int]]


def _sort_lines(lines: list[str]) -> _Lines | None:
    """The ``v``, ``f`` and ``o`` lines of a file whose keywords all start their line.

    None when some ``v``, ``f`` or ``o`` keyword is written otherwise (indented, followed by a
    tab, alone on its line).
    """
    v_lines: list[str] = []
    f_lines: list[str] = []
    defined: list[int] = []
    starts: list[tuple[str, int, int]] = []
    for line in lines:
        head = line[:2]
        if head == "v ":
            v_lines.append(line[2:])
        elif head == "f ":
            f_lines.append(line[2:])
            defined.append(len(v_lines))
        elif head == "o ":
            if not starts and (v_lines or f_lines):
                starts.append(("", 0, 0))
            starts.append((" ".join(line.split()[1:]), len(v_lines), len(f_lines)))
        elif line.split(None, 1)[:1] in (["v"], ["f"], ["o"]):
            return None
    if not starts and (v_lines or f_lines):
        starts.append(("", 0, 0))
    count = np.array(defined, dtype=np.int64).reshape(-1, 1)
    return _Lines(vertices=v_lines, faces=f_lines, defined=count, starts=starts)


def _parse_simple(lines: list[str]) -> ObjMesh | None:
    """:func:`parse_obj` of a file as meshgen writes it, vectorised; None for any other file.

    Handles ``v x y z`` with finite numbers and triangles ``f a b c`` of plain indices (positive
    or negative) that refer to vertices defined before them, each keyword at the start of its
    line. Anything else (a malformed line included) returns None, and the line-by-line reader
    gives the result or the error.
    """
    found = _sort_lines(lines)
    if found is None:
        return None
    face_text = " ".join(found.faces)
    if "/" in face_text:
        return None
    vertex_tokens = " ".join(found.vertices).split()
    face_tokens = face_text.split()
    if len(vertex_tokens) != 3 * len(found.vertices) or len(face_tokens) != 3 * len(found.faces):
        return None
    try:
        vertices = np.array(list(map(float, vertex_tokens)), dtype=np.float64).reshape(-1, 3)
        ids = np.array(list(map(int, face_tokens)), dtype=np.int64).reshape(-1, 3)
    except (ValueError, OverflowError):
        return None
    count = found.defined
    faces = np.where(ids > 0, ids - 1, count + ids)
    if not (np.isfinite(vertices).all() and ((faces >= 0) & (faces < count)).all()):
        return None
    groups = _groups(found.starts, len(vertices), len(faces))
    return ObjMesh(vertices=vertices, faces=faces, groups=groups)


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
