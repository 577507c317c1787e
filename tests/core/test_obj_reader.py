"""The OBJ sequence reader's compiled pass (flockkit.io.obj._scan) against the line-by-line
parser, which reads every line with Python's float and int: the same vertices and faces, bit for
bit, for numbers written every way a tool writes them and for the awkward files a tool may
write; anything the compiled pass does not read exactly goes to that parser, whose errors name
the line."""

import numpy as np
import pytest

from flockkit.errors import FileFormatError
from flockkit.io import obj


def careful(path):
    return obj._parse_obj(path, path.read_text(encoding="utf-8-sig"))


def formats(rng, values):
    """Each value written a way chosen at random: repr, %.6f, %g, %e, %.17g, an integer, a
    leading +, a leading or trailing dot, leading zeros, upper-case E, 18 and more digits, an
    exponent past 22, 45 decimals."""
    ways = [
        repr,
        lambda v: f"{v:.6f}",
        lambda v: f"{v:g}",
        lambda v: f"{v:e}",
        lambda v: f"{v:.17g}",
        lambda v: str(int(v * 100)) if abs(v) < 1e300 else repr(v),
        lambda v: f"+{abs(v):.4f}",
        lambda v: f"{v:.3f}".replace("0.", ".") if abs(v) < 1 else f"{v:.0f}.",
        lambda v: f"{'-' if v < 0 else ''}000{abs(v):.5f}",
        lambda v: f"{v:.5E}",
        lambda v: f"{v:.17f}",  # 18+ significant digits: read by the line-by-line parser
        lambda v: f"{v * 1e-30:.3e}",  # exponents past 22: the same
        lambda v: f"{v:.45f}",  # longer than HARD_WIDTH: Python's float itself
    ]
    return [ways[k](v) for k, v in zip(rng.integers(0, len(ways), len(values)).tolist(), values.tolist())]


def write(path, lines):
    path.write_bytes("".join(lines).encode())


def frames(tmp_path, count, make):
    for t in range(count):
        write(tmp_path / f"frame{t}.obj", make(t))
    return [tmp_path / f"frame{t}.obj" for t in range(count)]


def assert_reads_as_the_careful_parser(tmp_path, paths):
    positions, faces, _ = obj.read_sequence(str(tmp_path))
    for t, path in enumerate(paths):
        points, own = careful(path)
        np.testing.assert_array_equal(positions[t], points)
        assert np.array_equal(np.signbit(positions[t]), np.signbit(points))  # -0.0 stays -0.0
        np.testing.assert_array_equal(own, faces)


@pytest.mark.parametrize("seed", range(6))
def test_numbers_written_every_way_read_as_pythons_float_reads_them(tmp_path, seed):
    rng = np.random.default_rng(seed)
    n = 300
    faces = rng.integers(0, n, (200, 3))
    scale = 10.0 ** rng.integers(-8, 9, (4, n, 3))
    values = rng.normal(size=(4, n, 3)) * scale
    values[0, :5] = [[0.0, -0.0, 1e-300], [5e-324, 1.7976931348623157e308, -2.5], [1, 10, 100], [0.1, 0.2, 0.3],
                     [9007199254740993, 2**53, 123456789012345678]]  # fmt: skip
    face_lines = ["f " + " ".join(str(i + 1) for i in face) + "\n" for face in faces]

    def make(t):
        text = formats(rng, values[t].ravel())
        return ["# written\n", "o thing\n"] + [f"v {x} {y} {z}\n" for x, y, z in np.reshape(text, (n, 3))] + face_lines

    paths = frames(tmp_path, 4, make)
    assert_reads_as_the_careful_parser(tmp_path, paths)
    # plain repr coordinates are read by the compiled pass, faces and all
    scan = obj._scanner()
    plain = [tmp_path / "plain0.obj", tmp_path / "plain1.obj"]
    for t, path in enumerate(plain):
        write(path, [f"v {x!r} {y!r} {z!r}\n" for x, y, z in values[t].tolist()] + face_lines)
    status, _, _, text = scan(np.frombuffer(plain[0].read_bytes(), np.uint8), obj._NO_FACES, False)
    assert status == obj._FACE_TEXT and bytes(text) == "".join(face_lines)[2:-1].replace("\nf ", "\n").encode()
    status, points, hard, _ = scan(np.frombuffer(plain[1].read_bytes(), np.uint8), text, True)
    assert status == obj._SAME_FACES and len(hard)  # repr's 17 digits: some left to Python's float
    easy = np.setdiff1d(np.arange(points.size), hard[:, 0])
    np.testing.assert_array_equal(points.ravel()[easy], values[1].ravel()[easy])


@pytest.mark.parametrize(
    "layout",
    [
        "crlf", "cr", "tabs", "leading blanks", "colours", "w", "comment after", "vt vn lines", "slashes",
        "quads", "mixed", "no final newline", "bom", "non-ascii comment", "vertical tab", "form feed",
    ],
)  # fmt: skip
def test_awkward_files_read_as_the_careful_parser(tmp_path, layout):
    rng = np.random.default_rng(1)
    points = rng.normal(size=(4, 20, 3))
    quads = layout in ("quads", "mixed")
    faces = rng.integers(0, 20, (15, 4 if quads else 3))

    def make(t):
        vertex = {"tabs": "v\t{}\t{} \t{}", "leading blanks": "  \tv {} {} {}", "colours": "v {} {} {} 0.5 0.25 1",
                  "w": "v {} {} {} 1.0", "comment after": "v {} {} {} # a note"}.get(layout, "v {} {} {}")  # fmt: skip
        lines = [vertex.format(*map(repr, p)) for p in points[t].tolist()]
        if layout == "vt vn lines":
            lines += ["vt 0.5 0.5", "vn 0 0 1"]
        corner = "{0}/{0}/{0}" if layout in ("slashes", "vt vn lines") else "{0}"
        lines += ["f " + " ".join(corner.format(i + 1) for i in face) for face in faces]
        if layout == "mixed":
            lines.append("f 1 2 3")
        if layout == "non-ascii comment":
            lines.insert(0, "# émile's fox")
        if layout == "vertical tab":
            lines[3] += "\x0bv 1 2 3"  # a line break to Python's splitlines: one vertex more
        if layout == "form feed":
            lines[-1] += "\x0cf 1 2 3"
        end = {"crlf": "\r\n", "cr": "\r"}.get(layout, "\n")
        text = end.join(lines) + ("" if layout == "no final newline" else end)
        return ["\ufeff" + text if layout == "bom" else text]

    assert_reads_as_the_careful_parser(tmp_path, frames(tmp_path, 3, make))


def test_a_triangle_soup_and_relative_indices(tmp_path):
    rng = np.random.default_rng(2)
    soup = rng.normal(size=(3, 30, 3))

    def make(t):
        lines = []
        for k in range(10):  # each triangle its own corners, named relative to the vertices so far
            lines += [f"v {x!r} {y!r} {z!r}\n" for x, y, z in soup[t, 3 * k : 3 * k + 3].tolist()] + ["f -3 -2 -1\n"]
        return lines

    paths = frames(tmp_path, 3, make)
    assert_reads_as_the_careful_parser(tmp_path, paths)
    np.testing.assert_array_equal(obj.read_sequence(str(tmp_path))[1], np.arange(30).reshape(10, 3))


def test_later_frames_that_break_the_rules_are_named_by_the_careful_parser(tmp_path):
    quad = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=float)

    def make(t):
        return [f"v {x!r} {y!r} {z!r}\n" for x, y, z in (quad + t).tolist()] + ["f 1 2 3 4\n"]

    paths = frames(tmp_path, 3, make)
    good = paths[2].read_text()
    for bad, message in [
        ("v 2.0 3.0", r"frame2.obj, line 4: not an OBJ vertex"),
        ("v 2.0 3.0 2.0x", r"frame2.obj, line 4: not an OBJ vertex"),
        ("v 2.0 3.0 1e", r"frame2.obj, line 4: not an OBJ vertex"),
        ("v 2.0 3.0 1-2", r"frame2.obj, line 4: not an OBJ vertex"),
        ("v 2.0 3.0 .", r"frame2.obj, line 4: not an OBJ vertex"),
        ("v 2.0 3.0 nan", r"frame2.obj: vertices must have finite coordinates"),
        ("v 2.0 3.0 1e999", r"frame2.obj: vertices must have finite coordinates"),
    ]:
        paths[2].write_text(good.replace("v 2.0 3.0 2.0", bad))
        with pytest.raises(FileFormatError, match=message):
            obj.read_sequence(str(tmp_path))
    paths[2].write_text(good.replace("f 1 2 3 4", "f 1 2 3"))
    with pytest.raises(FileFormatError, match="frame2.obj: its topology differs from"):
        obj.read_sequence(str(tmp_path))
    paths[2].write_text(good + "v 1 1 1\n")
    with pytest.raises(FileFormatError, match="frame2.obj: its topology differs from"):
        obj.read_sequence(str(tmp_path))
    paths[2].write_bytes(good.encode() + b"# \xff\n")
    with pytest.raises(FileFormatError, match="frame2.obj: not UTF-8 text"):
        obj.read_sequence(str(tmp_path))
    paths[2].write_text(good.replace("f 1 2 3 4", "f 1 2 3 9"))
    with pytest.raises(FileFormatError, match="frame2.obj: a face refers to vertex 9"):
        obj.read_sequence(str(tmp_path))
