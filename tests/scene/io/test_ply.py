"""INRIA 3DGS .ply: foreign writer (plyfile), exactness contract, hostile input."""

from __future__ import annotations

import time
import tracemalloc
from pathlib import Path

import numpy as np
import pytest
from tests.helpers_io import assert_gaussians_identical, random_gaussians
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from plyfile import PlyData, PlyElement

from spacedg.scene.io import FileValueError, quantize_for_ply, read_ply, write_ply
from spacedg.scene.io.ply import ACTIVATION_BOUND
from spacedg.errors import FileFormatError, InvalidDataError
from spacedg.render.gaussians import SH_COEFFS

K_OF = SH_COEFFS


# ------------------------------------------------------------------ foreign files
def raw_inria(n: int, degree: int, seed: int = 0, dtype: str = "f4") -> np.ndarray:
    """A structured array with INRIA's properties (raw logit/log/unnormalised values) + extras."""
    rng = np.random.default_rng(seed)
    k = K_OF[degree]
    names = ["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"]
    names += [f"f_rest_{i}" for i in range(3 * (k - 1))]
    names += ["opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"]
    fields = [(name, dtype) for name in names] + [("extra_flag", "u1")]
    arr = np.zeros(n, dtype=fields)
    for name in names:
        arr[name] = rng.normal(0.0, 1.0, n)
    arr["opacity"] = rng.normal(0.0, 4.0, n)
    for j in range(3):
        arr[f"scale_{j}"] = rng.uniform(-9.0, 1.0, n)
    for j in range(4):
        arr[f"rot_{j}"] = rng.normal(0.0, 2.0, n)  # deliberately not unit
    arr["extra_flag"] = rng.integers(0, 255, n)
    return arr


def write_with_plyfile(path: Path, arr: np.ndarray, *, text: bool = False, byte_order: str = "<", before: bool = False) -> None:
    elements = []
    if before:  # a fixed-size element before the vertices, which readers must skip
        cam = np.array([(1.0, 2.0, 3, 4)], dtype=[("a", "f4"), ("b", "f8"), ("c", "u1"), ("d", "i2")])
        elements.append(PlyElement.describe(cam, "camera"))
    elements.append(PlyElement.describe(arr, "vertex"))
    PlyData(elements, text=text, byte_order=byte_order).write(str(path))


def expected_from_raw(arr: np.ndarray, degree: int) -> dict[str, np.ndarray]:
    n, k = arr.shape[0], K_OF[degree]
    sh = np.zeros((n, k, 3), np.float32)
    for c in range(3):
        sh[:, 0, c] = arr[f"f_dc_{c}"]
        for i in range(1, k):
            sh[:, i, c] = arr[f"f_rest_{c * (k - 1) + i - 1}"]
    q = np.stack([arr[f"rot_{j}"].astype(np.float64) for j in range(4)], axis=1)
    return {
        "means": np.stack([arr[a] for a in "xyz"], axis=1).astype(np.float32),
        "sh": sh,
        "opacities": (1.0 / (1.0 + np.exp(-arr["opacity"].astype(np.float64)))).astype(np.float32),
        "scales": np.exp(np.stack([arr[f"scale_{j}"].astype(np.float64) for j in range(3)], axis=1)).astype(np.float32),
        "quats": (q / np.linalg.norm(q, axis=1, keepdims=True)).astype(np.float32),
    }


@pytest.mark.parametrize("degree", [0, 1, 2, 3])
@pytest.mark.parametrize("variant", ["binary_le", "binary_be", "ascii"])
def test_reads_plyfile_written_files(tmp_path: Path, degree: int, variant: str) -> None:
    arr = raw_inria(40, degree, seed=degree)
    path = tmp_path / "g.ply"
    write_with_plyfile(path, arr, text=variant == "ascii", byte_order=">" if variant == "binary_be" else "<", before=degree == 2)
    g = read_ply(path)
    want = expected_from_raw(arr if variant != "ascii" else PlyData.read(str(path))["vertex"].data, degree)
    assert g.sh_degree == degree and len(g) == 40 and g.instance_ids is None
    np.testing.assert_array_equal(g.means, want["means"])
    np.testing.assert_array_equal(g.sh, want["sh"])
    np.testing.assert_array_equal(g.opacities, want["opacities"])
    np.testing.assert_array_equal(g.scales, want["scales"])
    np.testing.assert_allclose(g.quats, want["quats"], atol=1e-7)
    assert g.source == str(path)


def test_reads_double_properties(tmp_path: Path) -> None:
    arr = raw_inria(30, 1, dtype="f8")
    write_with_plyfile(tmp_path / "d.ply", arr)
    g = read_ply(tmp_path / "d.ply")
    want = expected_from_raw(arr, 1)
    np.testing.assert_array_equal(g.opacities, want["opacities"])
    np.testing.assert_array_equal(g.scales, want["scales"])
    np.testing.assert_array_equal(g.means, want["means"])


def test_sh_channel_major_layout_matches_inria(tmp_path: Path) -> None:
    g = random_gaussians(10, 3, seed=3)
    write_ply(tmp_path / "g.ply", g)
    v = PlyData.read(str(tmp_path / "g.ply"))["vertex"]
    # INRIA: features_rest (N, K-1, 3) transposed to (N, 3, K-1) and flattened → channel-major
    rest = np.stack([v[f"f_rest_{i}"] for i in range(45)], axis=1)
    np.testing.assert_array_equal(rest, g.sh[:, 1:, :].transpose(0, 2, 1).reshape(10, 45))
    np.testing.assert_array_equal(np.stack([v[f"f_dc_{c}"] for c in range(3)], axis=1), g.sh[:, 0, :])


def test_our_files_read_by_plyfile_hold_raw_values(tmp_path: Path) -> None:
    g = random_gaussians(64, 1, seed=1, instance_ids=True, include_extremes=True)
    write_ply(tmp_path / "g.ply", g)
    ply = PlyData.read(str(tmp_path / "g.ply"))
    v = ply["vertex"]
    names = [p.name for p in v.properties]
    assert names[:9] == ["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"]
    assert names[-1] == "instance_id" and v["instance_id"].dtype == np.int32
    assert v["opacity"].dtype == np.float32 and np.isfinite(v["opacity"]).all()
    assert v["opacity"][0] == -ACTIVATION_BOUND and v["opacity"][1] == ACTIVATION_BOUND  # opacity 0 and 1
    assert v["scale_0"][0] == -ACTIVATION_BOUND  # scale 0
    sig = (1.0 / (1.0 + np.exp(-v["opacity"].astype(np.float64)))).astype(np.float32)
    np.testing.assert_allclose(sig, g.opacities, rtol=1e-6, atol=1e-7)
    np.testing.assert_allclose(np.exp(v["scale_1"].astype(np.float64)), g.scales[:, 1], rtol=1e-6, atol=1e-40)
    np.testing.assert_array_equal(np.stack([v[f"rot_{j}"] for j in range(4)], 1), g.quats)
    np.testing.assert_array_equal(v["instance_id"], g.instance_ids)
    assert ply.elements[0].count == 64 and ply.byte_order == "<"


# ------------------------------------------------------------------ exactness
@pytest.mark.parametrize("degree", [0, 3])
def test_round_trip_bit_exact_after_quantize(tmp_path: Path, degree: int) -> None:
    g = quantize_for_ply(random_gaussians(500, degree, seed=degree, instance_ids=True, include_extremes=True))
    write_ply(tmp_path / "g.ply", g)
    assert_gaussians_identical(g, read_ply(tmp_path / "g.ply"))


def test_file_memory_file_memory_is_exact(tmp_path: Path) -> None:
    arr = raw_inria(2000, 2, seed=7)
    arr["opacity"][:4] = [-200.0, 200.0, 30.0, -90.0]
    write_with_plyfile(tmp_path / "a.ply", arr)
    first = read_ply(tmp_path / "a.ply")
    write_ply(tmp_path / "b.ply", first)
    second = read_ply(tmp_path / "b.ply")
    assert_gaussians_identical(first, second)
    write_ply(tmp_path / "c.ply", second)
    assert (tmp_path / "b.ply").read_bytes() == (tmp_path / "c.ply").read_bytes()


def test_unquantized_values_move_at_most_a_few_ulps(tmp_path: Path) -> None:
    g = random_gaussians(3000, 0, seed=11)
    write_ply(tmp_path / "g.ply", g)
    back = read_ply(tmp_path / "g.ply")
    assert_gaussians_identical(g, back, fields=("means", "quats", "sh"))
    ulps = np.abs(back.scales.view(np.int32).astype(np.int64) - g.scales.view(np.int32))
    assert ulps.max() <= 8
    np.testing.assert_array_equal(back.opacities, quantize_for_ply(g).opacities)
    np.testing.assert_array_equal(back.scales, quantize_for_ply(g).scales)


def test_float64_precision_round_trips_any_float32(tmp_path: Path) -> None:
    g = random_gaussians(1000, 1, seed=5, instance_ids=True, include_extremes=True)
    write_ply(tmp_path / "g.ply", g, precision="float64")
    assert PlyData.read(str(tmp_path / "g.ply"))["vertex"]["opacity"].dtype == np.float64
    assert_gaussians_identical(g, read_ply(tmp_path / "g.ply"))
    assert_gaussians_identical(quantize_for_ply(g, precision="float64"), g)


def test_quantize_is_idempotent_and_keeps_other_fields() -> None:
    g = random_gaussians(2000, 1, seed=9, include_extremes=True)
    q = quantize_for_ply(g)
    assert_gaussians_identical(q, quantize_for_ply(q))
    assert_gaussians_identical(g, q, fields=("means", "quats", "sh"))
    assert q.opacities[0] == 0.0 and q.opacities[1] == 1.0 and q.scales[0, 0] == 0.0


def test_near_unit_quaternions_kept_bit_for_bit(tmp_path: Path) -> None:
    g = random_gaussians(100, 0, seed=2)
    quats = g.quats * np.float32(1.0 + 5e-5)  # unit within the container's tolerance, not exactly
    from dataclasses import replace

    g2 = replace(g, quats=quats)
    write_ply(tmp_path / "q.ply", g2)
    np.testing.assert_array_equal(read_ply(tmp_path / "q.ply").quats, g2.quats)


def test_empty_gaussians_round_trip(tmp_path: Path) -> None:
    from spacedg.render.gaussians import Gaussians

    write_ply(tmp_path / "e.ply", Gaussians.empty(sh_degree=2))
    back = read_ply(tmp_path / "e.ply")
    assert len(back) == 0 and back.sh_degree == 2


def test_write_is_atomic_on_failure(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    path = tmp_path / "g.ply"
    write_ply(path, random_gaussians(5))
    before = path.read_bytes()

    def boom(*args: object, **kwargs: object) -> None:
        raise OSError("disk full")

    monkeypatch.setattr("spacedg.files.os.replace", boom)
    with pytest.raises(OSError):
        write_ply(path, random_gaussians(9, seed=4))
    assert path.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["g.ply"]


def test_write_rejects_bad_arguments(tmp_path: Path) -> None:
    with pytest.raises(InvalidDataError, match="precision"):
        write_ply(tmp_path / "g.ply", random_gaussians(3), precision="float16")  # type: ignore[arg-type]
    with pytest.raises(InvalidDataError, match="Gaussians"):
        write_ply(tmp_path / "g.ply", np.zeros(3))  # type: ignore[arg-type]


# ------------------------------------------------------------------ hostile input
HEADER_OK = (
    "ply\nformat binary_little_endian 1.0\nelement vertex {n}\n"
    + "".join(f"property float {p}\n" for p in ["x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"])
    + "end_header\n"
)


def small_file(tmp_path: Path) -> Path:
    path = tmp_path / "small.ply"
    write_ply(path, random_gaussians(20, 1, seed=1, instance_ids=True))
    return path


def test_truncated_files_fail_clearly(tmp_path: Path) -> None:
    data = small_file(tmp_path).read_bytes()
    header_end = data.index(b"end_header\n") + len(b"end_header\n")
    cut = tmp_path / "cut.ply"
    for size in [0, 2, 4, 30, header_end - 5, header_end, header_end + 1, (header_end + len(data)) // 2, len(data) - 1]:
        cut.write_bytes(data[:size])
        with pytest.raises(FileFormatError) as info:
            read_ply(cut)
        assert str(cut) in str(info.value)
    cut.write_bytes(data[: len(data) - 1])
    with pytest.raises(FileFormatError, match="truncated"):
        read_ply(cut)


def test_huge_vertex_count_fails_fast_without_allocating(tmp_path: Path) -> None:
    path = tmp_path / "huge.ply"
    path.write_bytes(HEADER_OK.format(n=10**12).encode() + b"\0" * 1000)
    tracemalloc.start()
    start = time.perf_counter()
    try:
        with pytest.raises(FileFormatError, match="1000000000000 vertices"):
            read_ply(path)
    finally:
        _, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
    assert time.perf_counter() - start < 1.0
    assert peak < 50 * 2**20
    ascii_path = tmp_path / "huge_ascii.ply"
    ascii_path.write_bytes(HEADER_OK.replace("binary_little_endian", "ascii").format(n=10**12).encode() + b"1 " * 500)
    with pytest.raises(FileFormatError, match="at least"):
        read_ply(ascii_path)


@pytest.mark.parametrize(
    ("header", "match"),
    [
        (HEADER_OK.replace("property float x", "property uchar x"), r"'x'.*'uchar'"),
        (HEADER_OK.replace("property float opacity\n", ""), r"opacity"),
        (HEADER_OK.replace("element vertex {n}", "element vertex many"), r"non-negative integer count"),
        (HEADER_OK.replace("element vertex {n}", "element vertex -3"), r"non-negative integer count"),
        (HEADER_OK.replace("format binary_little_endian 1.0\n", ""), r"no 'format'"),
        (HEADER_OK.replace("binary_little_endian", "binary_middle_endian"), r"format"),
        (HEADER_OK.replace("end_header\n", ""), r"end_header"),
        (HEADER_OK.replace("property float rot_3\n", "property float rot_3\nproperty list uchar int idx\n"), r"list properties"),
        (HEADER_OK.replace("property float rot_3\n", "property float rot_3\nproperty float instance_id\n"), r"instance_id.*integer"),
        (HEADER_OK.replace("property float rot_3\n", "property float rot_3\nproperty float rot_3\n"), r"declared twice"),
        (HEADER_OK.replace("property float rot_3\n", "property float rot_3\nproperty quad w\n"), r"unknown PLY type"),
        (HEADER_OK.replace("ply\n", "ply\nmystery line\n"), r"unknown header keyword"),
        (HEADER_OK.replace("element vertex {n}", "element face 1\nproperty list uchar int vertex_indices\nelement vertex {n}"), r"before 'vertex'"),
        (HEADER_OK.replace("element vertex {n}", "element points {n}"), r"no 'vertex' element"),
        ("PLY\n" + HEADER_OK[4:], r"not a PLY"),
    ],
)
def test_bad_headers_name_the_problem(tmp_path: Path, header: str, match: str) -> None:
    path = tmp_path / "bad.ply"
    path.write_bytes(header.format(n=2).encode() + b"\0" * 2 * 15 * 4)
    with pytest.raises(FileFormatError, match=match):
        read_ply(path)


@pytest.mark.parametrize("count", [5, 10, 44])
def test_unknown_f_rest_count(tmp_path: Path, count: int) -> None:
    header = HEADER_OK.replace("property float opacity", "".join(f"property float f_rest_{i}\n" for i in range(count)) + "property float opacity")
    path = tmp_path / "rest.ply"
    path.write_bytes(header.format(n=1).encode() + b"\0" * 4 * (14 + count))
    with pytest.raises(FileFormatError, match=f"{count} f_rest"):
        read_ply(path)


def test_no_end_header_within_limit(tmp_path: Path) -> None:
    path = tmp_path / "long.ply"
    path.write_bytes(b"ply\nformat ascii 1.0\n" + b"comment " + b"x" * 100 + b"\n" * 2 + b"comment filler\n" * 8000)
    with pytest.raises(FileFormatError, match="no 'end_header' line within"):
        read_ply(path)


def test_non_ascii_header(tmp_path: Path) -> None:
    path = tmp_path / "u.ply"
    path.write_bytes(b"ply\nformat ascii 1.0\ncomment \xff\xfe\nend_header\n")
    with pytest.raises(FileFormatError, match="not ASCII"):
        read_ply(path)


def test_zero_quaternions_reported_with_count(tmp_path: Path) -> None:
    arr = raw_inria(10, 0)
    for j in range(4):
        arr[f"rot_{j}"][[2, 7]] = 0.0
    write_with_plyfile(tmp_path / "z.ply", arr)
    with pytest.raises(FileValueError, match=r"2 of 10 .*zero rotation.*first at vertex 2"):
        read_ply(tmp_path / "z.ply")


def test_nan_values_are_invalid_data(tmp_path: Path) -> None:
    arr = raw_inria(10, 0)
    arr["x"][4] = np.nan
    write_with_plyfile(tmp_path / "n.ply", arr)
    with pytest.raises(InvalidDataError, match="means") as info:
        read_ply(tmp_path / "n.ply")
    assert isinstance(info.value, FileFormatError)


def test_ascii_garbage_value(tmp_path: Path) -> None:
    arr = raw_inria(3, 0)
    write_with_plyfile(tmp_path / "a.ply", arr, text=True)
    text = (tmp_path / "a.ply").read_bytes().replace(b"end_header\n", b"end_header\nzz ", 1)
    (tmp_path / "a.ply").write_bytes(text)
    with pytest.raises(FileFormatError, match="vertex 0"):
        read_ply(tmp_path / "a.ply")


def test_missing_file_and_directory(tmp_path: Path) -> None:
    with pytest.raises(FileFormatError, match="not found"):
        read_ply(tmp_path / "nope.ply")
    with pytest.raises(FileFormatError, match="directory"):
        read_ply(tmp_path)


# ------------------------------------------------------------------ fuzzing
_VALID = None


def _valid_bytes() -> bytes:
    global _VALID
    if _VALID is None:
        import tempfile

        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / "v.ply"
            write_ply(path, random_gaussians(4, 1, seed=0, instance_ids=True))
            _VALID = path.read_bytes()
    return _VALID


def _read_or_format_error(path: Path) -> None:
    try:
        g = read_ply(path)
    except FileFormatError:
        return
    assert len(g) >= 0  # parsed: a valid Gaussians object


FUZZ = settings(max_examples=100, deadline=2000, suppress_health_check=[HealthCheck.function_scoped_fixture], derandomize=True)


@FUZZ
@given(data=st.binary(max_size=600), prefix=st.sampled_from([b"", b"ply\n", b"ply\nformat binary_little_endian 1.0\nelement vertex 3\n"]))
def test_fuzz_random_bytes(tmp_path: Path, data: bytes, prefix: bytes) -> None:
    path = tmp_path / "fuzz.ply"
    path.write_bytes(prefix + data)
    _read_or_format_error(path)


@FUZZ
@given(
    edits=st.lists(st.tuples(st.integers(0, 10_000), st.sampled_from([b"", b" ", b"\n", b"1", b"9", b"-", b"x", b"double", b"list", b"ascii", b"\xff"])), min_size=1, max_size=4),
    cut=st.integers(0, 10_000),
)
def test_fuzz_header_mutations(tmp_path: Path, edits: list[tuple[int, bytes]], cut: int) -> None:
    data = bytearray(_valid_bytes())
    header_len = data.index(b"end_header") + 11
    for pos, replacement in edits:
        at = pos % header_len
        data[at : at + 1] = replacement
    if cut % 3 == 0:
        data = data[: cut % (len(data) + 1)]
    path = tmp_path / "mut.ply"
    path.write_bytes(bytes(data))
    _read_or_format_error(path)


_TOKENS = ["float", "double", "uchar", "int", "list", "0", "1", "3", "100000", "vertex", "face", "ascii",
           "binary_big_endian", "instance_id", "x", "rot_0", "f_rest_3", "property", "element"]
_VALID_ASCII = None


def _valid_ascii_bytes() -> bytes:
    global _VALID_ASCII
    if _VALID_ASCII is None:
        import io

        buf = io.BytesIO()
        ply = PlyData.read(io.BytesIO(_valid_bytes()))
        ply.text = True
        ply.write(buf)
        _VALID_ASCII = buf.getvalue()
    return _VALID_ASCII


@FUZZ
@given(
    ascii_data=st.booleans(),
    edits=st.lists(st.tuples(st.integers(0, 100), st.integers(0, 5), st.sampled_from(_TOKENS), st.sampled_from(["set", "drop", "dup"])), min_size=1, max_size=3),
)
def test_fuzz_header_token_edits(tmp_path: Path, ascii_data: bool, edits: list[tuple[int, int, str, str]]) -> None:
    data = _valid_ascii_bytes() if ascii_data else _valid_bytes()
    split = data.index(b"end_header\n")
    lines = [line.split(" ") for line in data[:split].decode().split("\n")]
    for line_no, token_no, token, op in edits:
        i = line_no % len(lines)
        if op == "set" and lines[i]:
            lines[i][token_no % len(lines[i])] = token
        elif op == "drop":
            del lines[i]
        else:
            lines.insert(i, list(lines[(i * 7) % len(lines)]))
        if not lines:
            break
    path = tmp_path / "tok.ply"
    path.write_bytes("\n".join(" ".join(t) for t in lines).encode() + b"\n" + data[split:])
    _read_or_format_error(path)
