"""The OBJ sequence reader's compiled pass (flockkit.io.obj._scan) against the line-by-line
parser, which reads every line with Python's float and int: the same vertices and faces, bit for
bit, for numbers written every way a tool writes them and for the awkward files a tool may
write; anything the compiled pass does not read exactly goes to that parser, whose errors name
the line."""

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from flockkit.errors import FileFormatError
from flockkit.io import obj
from flockkit.testing import strategies


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
        lambda v: f"{v:.17f}",  # 18+ significant digits: Eisel and Lemire's conversion
        lambda v: f"{v * 1e-30:.3e}",  # exponents past 22: the same
        lambda v: f"{v:.45f}",  # more than 19 digits: checked against the next mantissa
    ]
    return [ways[k](v) for k, v in zip(rng.integers(0, len(ways), len(values)).tolist(), values.tolist())]


def write(path, lines):
    path.write_bytes("".join(lines).encode())


def frames(tmp_path, count, make):
    for t in range(count):
        write(tmp_path / f"frame{t}.obj", make(t))
    return [tmp_path / f"frame{t}.obj" for t in range(count)]


def quad_frames(tmp_path, count):
    """`count` frames of one quad (4 vertices written by repr, one face), moved by t in frame t."""
    quad = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=float)
    return frames(
        tmp_path, count, lambda t: [f"v {x!r} {y!r} {z!r}\n" for x, y, z in (quad + t).tolist()] + ["f 1 2 3 4\n"]
    )


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
    plain = tmp_path / "plain.obj"
    write(plain, [f"v {x!r} {y!r} {z!r}\n" for x, y, z in values[1].tolist()] + face_lines)
    status, points, corners, counts, _ = compiled(plain)
    assert status == obj._READ
    assert_same_bits(points, values[1])
    np.testing.assert_array_equal(obj._faces(corners, counts), faces)


def compiled(path, first=None):
    """What the compiled pass reads of `path`: alone, or as a later frame of the sequence whose
    first frame is `first`."""
    data, n = obj._read_padded(path)
    if first is None:
        return obj._scan_alone(data, n)
    points, _, known = obj._read_first(first)
    return obj._compiled()(data, n, np.empty((len(points), 3)), *known, True)


def assert_same_bits(found, expected):
    """Equal as doubles, -0.0 told from 0.0."""
    found, expected = np.asarray(found, dtype=np.float64), np.asarray(expected, dtype=np.float64)
    np.testing.assert_array_equal(found.view(np.uint64), expected.view(np.uint64))


# Ways a tool writes a number, as (name, format): the compiled pass reads the first ones whole.
PLAIN = [("repr", repr), ("%.17g", lambda v: f"{v:.17g}"), ("%.6f", lambda v: f"{v:.6f}"),
         ("%e", lambda v: f"{v:e}"), ("%.25e", lambda v: f"{v:.25e}"), ("%.20g", lambda v: f"{v:.20g}"),
         ("%g", lambda v: f"{v:g}"), ("+", lambda v: repr(v) if np.signbit(v) else f"+{v!r}"),
         ("%E", lambda v: f"{v:.12E}"), (".5", lambda v: repr(v).replace("0.", ".", 1) if abs(v) < 1 else repr(v)),
         ("5.", lambda v: f"{v:.0f}." if abs(v) < 1e300 else repr(v)),
         ("zeros", lambda v: f"{'-' if np.signbit(v) else ''}000{abs(v)!r}")]  # fmt: skip
AWKWARD = [("%.60f", lambda v: f"{v:.60f}"), ("30 digits", lambda v: f"{v:.29e}")]


@pytest.mark.filterwarnings("ignore:overflow encountered:RuntimeWarning")  # Motion's check sums the largest doubles
@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(mesh=strategies.animated_meshes(max_frames=3, max_vertices=10, max_coordinate=1.7976931348623157e308),
       ways=st.lists(st.sampled_from(PLAIN + AWKWARD), min_size=1, max_size=4), data=st.data())  # fmt: skip
def test_every_number_reads_as_pythons_float(tmp_path_factory, mesh, ways, data):
    """Coordinates drawn anywhere in the doubles (subnormals, -0.0, the largest, 17 digits)
    and written in ways drawn per number read as Python's float reads their text, bit for bit,
    by the sequence reader and, for every way but the awkward ones, by the compiled pass alone."""
    folder = tmp_path_factory.mktemp("numbers")
    positions = mesh.motion.positions
    chosen = data.draw(st.lists(st.sampled_from(ways), min_size=positions[0].size, max_size=positions[0].size))
    face_lines = ["f " + " ".join(str(i + 1) for i in face) + "\n" for face in mesh.faces.tolist()]
    texts = []
    for t, frame in enumerate(positions):
        tokens = [way(v) for (_, way), v in zip(chosen, frame.ravel().tolist())]
        texts.append(tokens)
        write(folder / f"frame{t}.obj", [f"v {x} {y} {z}\n" for x, y, z in np.reshape(tokens, (-1, 3))] + face_lines)
    read, faces, _ = obj.read_sequence(str(folder))
    assert_same_bits(read.reshape(len(texts), -1), [[float(token) for token in tokens] for tokens in texts])
    np.testing.assert_array_equal(faces, mesh.faces)
    if all((name, way) in PLAIN for name, way in chosen):
        status, points, corners, counts, _ = compiled(folder / "frame0.obj")
        assert status == obj._READ
        assert_same_bits(points.ravel(), [float(token) for token in texts[0]])
        for t in range(1, len(positions)):
            assert compiled(folder / f"frame{t}.obj", folder / "frame0.obj")[0] == obj._READ


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
    paths = quad_frames(tmp_path, 3)
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


def test_a_bad_first_frame_and_the_first_of_several_bad_frames_are_named(tmp_path):
    paths = quad_frames(tmp_path, 8)
    good = paths[0].read_text()
    for bad, message in [
        ("v 0.0 0.0 0.0x", r"frame0.obj, line 1: not an OBJ vertex"),
        ("v 0.0 0.0 inf", r"frame0.obj: vertices must have finite coordinates"),
        ("v 0.0 0.0 1e309", r"frame0.obj: vertices must have finite coordinates"),
    ]:
        paths[0].write_text(good.replace("v 0.0 0.0 0.0", bad))
        with pytest.raises(FileFormatError, match=message):
            obj.read_sequence(str(tmp_path))
    paths[0].write_text(good.replace("f 1 2 3 4", "f 1 2 3 0"))
    with pytest.raises(FileFormatError, match=r"frame0.obj, line 5: not an OBJ vertex .* or face"):
        obj.read_sequence(str(tmp_path))
    paths[0].write_text(good.replace("f 1 2 3 4", "f 1 2 3 -9"))
    with pytest.raises(FileFormatError, match=r"frame0.obj, line 5: a face refers to a vertex that no OBJ file"):
        obj.read_sequence(str(tmp_path))
    paths[0].write_text(good)
    # frames read by several threads: the error is the first bad frame's, whichever thread is first
    paths[6].write_text(paths[6].read_text().replace("v 6.0", "v x"))
    paths[3].write_text(paths[3].read_text().replace("f 1 2 3 4", "f 1 2 4 3"))
    with pytest.raises(FileFormatError, match="frame3.obj: its topology differs from .*frame0.obj"):
        obj.read_sequence(str(tmp_path))


def test_a_link_that_leaves_the_folder_is_refused(tmp_path):
    outside = tmp_path / "secret.obj"
    outside.write_text("v 1 2 3\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    sequence = tmp_path / "sequence"
    sequence.mkdir()
    (sequence / "frame0.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    (sequence / "frame1.obj").symlink_to(outside)
    with pytest.raises(FileFormatError, match="frame1.obj: a link that leads outside"):
        obj.read_sequence(str(sequence))


@pytest.mark.parametrize("threads", [1, 2])
def test_polygons_and_relative_corners_read_as_the_careful_parser(tmp_path, threads):
    """Fans of pentagons and hexagons, triangles beside quads (which are cut in two), corners
    with texture and normal numbers, and corners counted back from the last vertex, read by
    one thread or two."""
    import numba

    rng = np.random.default_rng(4)
    points = rng.normal(size=(5, 12, 3))
    polygons = ["f 1 2 3 4 5", "f 6/1/1 7/2/2 8/3/3", "f -1 -2 -3 -4", "f 9//1 10//2 11//3 12//4 1//5 2//6",
                "f 3 4 5", "f +4 5 6 7"]  # fmt: skip

    def make(t):
        return [f"v {x!r} {y!r} {z!r}\n" for x, y, z in points[t].tolist()] + [line + "\n" for line in polygons]

    paths = frames(tmp_path, 5, make)
    before = numba.get_num_threads()
    numba.set_num_threads(threads)
    try:
        assert_reads_as_the_careful_parser(tmp_path, paths)
    finally:
        numba.set_num_threads(before)
    status, _, corners, counts, _ = compiled(paths[0])
    assert status == obj._READ and counts.tolist() == [5, 3, 4, 6, 3, 4]
    np.testing.assert_array_equal(obj._faces(corners, counts), careful(paths[0])[1])


# A small sequence's frames (faces with texture numbers and relative corners among them), and the
# bytes damage is drawn from: what OBJ files hold, a NUL, a byte outside ASCII, runs of digits
# longer than a 64-bit word holds, and numbers of more than 19 digits with few significant ones.
FIRST = b"# first\nv 0.5 -1.25 3\nv 1e-3 +2. .5\nv 10 20 30\nv -0 0 1\nf 1 2 3\nf 1/1 3//2 4/1/1\nf -1 -2 -3\n"
LATER = b"# later\nv 0.75 -1.5 3.25\nv 2e-3 +3. .25\nv 11 21 31\nv -1 0 2\nf 1 2 3\nf 1/1 3//2 4/1/1\nf -1 -2 -3\n"
PIECES = [bytes([b]) for b in b"0123456789.-+eE \t\n\r/vf#\x00\xff"] + [b"9" * 20, b"1" * 300, b"0" * 30, b"\n",
          b"123456789012345680.000000", b"0.000000000000000000001234567"]  # fmt: skip


def reference(paths):
    """The sequence as the line-by-line parser reads each frame, and the first bad frame's
    FileFormatError (its own, or that its topology differs from the first frame's)."""
    points, faces = obj._parse_obj(paths[0], obj._text(paths[0], paths[0].read_bytes()))
    frames = [points]
    for path in paths[1:]:
        other, own = obj._parse_obj(path, obj._text(path, path.read_bytes()))
        if len(other) != len(points) or not np.array_equal(own, faces):
            raise FileFormatError(f"{path}: its topology differs")
        frames.append(other)
    return np.stack(frames), faces


@st.composite
def hostile(draw, data: bytes):
    """`data` damaged (bytes changed, cut short) and edited: pieces of OBJ files put in, over or
    in place of its bytes."""
    data = bytearray(draw(strategies.damaged(data, max_flips=1)))
    for _ in range(draw(st.integers(0, 3))):
        at = draw(st.integers(0, len(data)))
        data[at : at + draw(st.integers(0, 2))] = draw(st.sampled_from(PIECES))
    return bytes(data)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(first=st.one_of(st.just(FIRST), hostile(FIRST)), later=st.one_of(st.just(LATER), hostile(LATER)),
       ends=st.sampled_from([b"", b"\n", b"\r\n"]))  # fmt: skip
def test_hostile_frames_read_as_the_careful_parser_or_are_named(tmp_path_factory, first, later, ends):
    """Damaged and edited frames (a truncated line, a number at the very end of the file, a NUL,
    30 or 300 digits, a face index past the vertices or 0 or counting back too far, a face line
    that differs from the first frame's by a byte) read as the line-by-line parser reads them,
    bit for bit, or fail with a FileFormatError naming the first bad frame, as it does."""
    folder = tmp_path_factory.mktemp("hostile")
    paths = [folder / f"frame{t}.obj" for t in range(3)]
    for path, data in zip(paths, [first, later, LATER.rstrip(b"\n") + ends]):
        path.write_bytes(data)
    try:
        expected = reference(paths)
    except FileFormatError as error:
        bad = str(error).split(":")[0].split(",")[0]
        with pytest.raises(FileFormatError) as raised:
            obj.read_sequence(str(folder))
        assert str(raised.value).startswith(bad)
        return
    positions, faces, _ = obj.read_sequence(str(folder))
    assert_same_bits(positions, expected[0])
    np.testing.assert_array_equal(faces, expected[1])


def test_the_compiled_pass_reads_only_padded_bytes(tmp_path):
    """The compiled pass reads no byte past the file's without the line ends after it that stop
    its scans: a buffer without them, or a first frame's without them, is left to the careful
    parser (and a face start past the first frame's bytes is not used)."""
    path = tmp_path / "frame.obj"
    path.write_bytes(FIRST)
    data, n = obj._read_padded(path)
    assert data[n : n + obj._PAD].tolist() == [10] * obj._PAD
    status, points, corners, counts, starts = obj._scan_alone(data, n)
    assert status == obj._READ and len(points) == 4 and counts.tolist() == [3, 3, 3]
    assert starts[-1] == -1  # relative corners: read again in every frame
    scan = obj._compiled()
    first = data[: n + obj._PAD]
    later = np.frombuffer(LATER + b"\n" * obj._PAD, np.uint8)
    out = np.empty((4, 3))
    assert scan(later, len(LATER), out, corners, counts, starts, first, True)[0] == obj._READ
    assert_same_bits(out, careful_bytes(tmp_path, LATER)[0])
    unpadded = np.frombuffer(LATER + b"\n" * (obj._PAD - 1) + b"1", np.uint8)
    assert scan(unpadded, len(LATER), out, corners, counts, starts, first, True)[0] == obj._CAREFUL
    assert scan(later, len(LATER) + 1, out, corners, counts, starts, first, True)[0] == obj._CAREFUL
    broken = first.copy()
    broken[-1] = ord("1")
    assert scan(later, len(LATER), out, corners, counts, starts, broken, True)[0] == obj._CAREFUL
    far = np.full_like(starts, len(first))
    assert scan(later, len(LATER), out, corners, counts, far, first, True)[0] == obj._READ


def careful_bytes(folder, data):
    path = folder / "careful.obj"
    path.write_bytes(data)
    return careful(path)


@pytest.mark.parametrize(
    "text",
    ["123456789012345680.000000", "0.000000000000000000001234567", "000000000000000000001.5", "12345678901234567890",
     "1234567890123456789.0", "1.00000000000000000000000001", "9999999999999999999", "18446744073709551616",
     "-0.000000000000000000000000000000", "0.1234567890123456789", "+00000000.00000000001e+30"],
)  # fmt: skip
def test_numbers_of_more_than_19_digits_read_as_pythons_float(tmp_path, text):
    """Numbers whose digits overflow a 64-bit word (leading and trailing zeros among them) are read
    by the compiled pass as Python's float reads them."""
    path = tmp_path / "frame.obj"
    path.write_text(f"v {text} 1 {text}\nv 0 0 0\nv 1 1 1\nf 1 2 3\n")
    status, points, *_ = compiled(path)
    assert status == obj._READ
    assert_same_bits(points[0], [float(text), 1.0, float(text)])


def test_the_room_for_a_first_frame_is_checked_against_the_memory_budget(tmp_path, monkeypatch):
    """A first frame of many small faces asks for room in doubling steps, each checked against the
    memory budget first: over it, a ValidationError naming the file."""
    from flockkit.errors import ValidationError

    (tmp_path / "frame0.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\n" + "f 1 2 3\n" * 40_000)
    assert obj.read_sequence(str(tmp_path))[1].shape == (40_000, 3)
    monkeypatch.setenv("FLOCKKIT_MEMORY_LIMIT", "2M")
    with pytest.raises(ValidationError, match=r"frame0.obj: room for \d+ vertices and faces needs"):
        obj.read_sequence(str(tmp_path))
