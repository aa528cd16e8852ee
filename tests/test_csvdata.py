"""Tests of flowchart2sdnn.data.csvdata: malformed files (code + line), fuzzing, and good files vs numpy.loadtxt."""

from __future__ import annotations

import csv
import hashlib
import io
import math
import os
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from flowchart2sdnn.data.csvdata import Dataset, parse_mapping, read_csv, write_csv
from flowchart2sdnn.errors import SdnnError

BAD = Path(__file__).parent / "data" / "bad_csv"
REAL = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "real"
W = ["w1", "w2"]

# file, required, keyword arguments, expected code, expected line (None: no line), text the message must hold
BAD_CASES = [
    ("empty.csv", W, {}, "CSV007", None, "empty"),
    ("blank_lines_only.csv", W, {}, "CSV007", None, "no header"),
    ("header_only.csv", W, {}, "CSV008", 1, "no data rows"),
    ("too_few_rows.csv", W, {}, "CSV009", None, "2 data rows, fewer than the 3"),
    ("too_few_rows.csv", W, {"min_rows": 5}, "CSV009", None, "fewer than the 5"),
    ("ragged_short.csv", W, {}, "CSV010", 4, "2 fields, fewer than the header's 3"),
    ("ragged_long.csv", W, {}, "CSV011", 3, "4 fields, more than the header's 3"),
    ("decimal_comma.csv", W, {}, "CSV011", 2, "4 fields"),
    ("semicolon_rows.csv", W, {}, "CSV010", 3, "found ';'"),
    ("nan_mixed_case.csv", W, {}, "CSV005", 5, "column 'w2': nan is not a finite number"),
    ("nan_lower.csv", W, {}, "CSV005", 3, "column 'w1': nan"),
    ("inf_negative.csv", W, {}, "CSV005", 4, "column 'w2': -inf"),
    ("overflow_to_inf.csv", W, {}, "CSV005", 3, "column 'w1': inf"),
    ("nan_in_time.csv", W, {}, "CSV005", 4, "column 'time'"),
    ("empty_cell.csv", W, {}, "CSV006", 3, "column 'w1': the cell is empty"),
    ("blank_cell.csv", W, {}, "CSV006", 4, "column 'w2'"),
    ("text_in_number.csv", W, {}, "CSV004", 17, "column 'w2': 'abc' is not a number (expected a decimal number)"),
    ("underscore_number.csv", W, {}, "CSV004", 3, "'1_000'"),
    ("arabic_digits.csv", W, {}, "CSV004", 3, "column 'w2'"),
    ("quoted_text.csv", W, {}, "CSV004", 3, "'one'"),
    ("nan_before_text.csv", W, {}, "CSV005", 3, "column 'w2'"),  # the first bad row wins
    ("text_after_blank_and_multiline.csv", W, {}, "CSV004", 7, "'oops'"),
    ("missing_column.csv", W, {}, "CSV012", 1, "did you mean 'w_2'"),
    ("missing_column.csv", ["w1", "torque"], {}, "CSV012", 1, "headers found: 'time', 'w1', 'w_2'"),
    ("missing_column.csv", ["W1", "w_2"], {}, "CSV012", 1, "column 'W1' is missing"),
    ("missing_column.csv", ["W1", "w_2"], {}, "CSV012", 1, "did you mean 'w1'"),
    ("mapped.csv", ["torque"], {}, "CSV012", 1, "did you mean 'torque_Nm'"),
    ("mapped.csv", ["power"], {}, "CSV012", 1, "hint: map it with --map power=HEADER"),
    ("duplicate_needed.csv", W, {}, "CSV013", 1, "column 'w1' occurs 2 times (fields 2, 4)"),
    ("duplicate_time.csv", W, {}, "CSV013", 1, "time column"),
    ("semicolon.csv", W, {}, "CSV014", 1, "expected comma-separated columns, found ';'"),
    ("tab.csv", W, {}, "CSV014", 1, "found tab"),
    ("spaces.csv", W, {}, "CSV014", 1, "found blanks"),
    ("latin1.csv", W, {}, "CSV015", 4, "byte 0xb0 is not UTF-8"),
    ("binary.csv", W, {}, "CSV015", 3, "NUL byte"),
    ("utf16.csv", W, {}, "CSV015", 1, "UTF-16"),
    ("unterminated_quote.csv", W, {}, "CSV022", 4, "malformed CSV"),
    ("no_header.csv", W, {}, "CSV023", 1, "no header row"),
    ("time_decreasing.csv", W, {}, "CSV019", 5, "goes back in time: step -0.0005"),
    ("time_decreasing.csv", W, {"sample_time": 1e-3}, "CSV019", 5, "expected a step of 0.001"),
    ("time_repeats.csv", W, {"sample_time": 1e-3}, "CSV019", 4, "repeats"),
    ("time_jitter.csv", W, {"sample_time": 1e-3}, "CSV020", 7, "step 0.00103 deviates 3 % from 0.001"),
    ("time_jitter.csv", W, {}, "CSV020", 7, "step 0.00103"),
    ("time_in_ms.csv", W, {"sample_time": 1e-3}, "CSV021", 3, "step 1 (expected 0.001 s"),
    ("mapped.csv", ["M1"], {"mapping": {"M1": "torque_nm"}}, "CSV016", 1, "did you mean 'torque_Nm'"),
    ("mapped.csv", ["M1", "w"], {"mapping": {"M1": "torque_Nm", "w": "torque_Nm"}}, "CSV017", 1, "'torque_Nm'"),
    ("mapped.csv", ["M1", "t"], {"mapping": {"M1": "t"}}, "CSV017", 1, "both 'M1' and 't'"),
    ("mapped.csv", ["M1"], {"mapping": {"M2": "torque_Nm"}}, "CSV025", None, "does not need"),
    ("mapped.csv", ["M1"], {"mapping": {"M1": "torque_Nm", "time": "T"}}, "CSV016", 1, "header 'T'"),
    ("mapped.csv", ["M1"], {"mapping": {"M1": "torque_Nm"}, "max_bytes": 10}, "CSV018", None, "more than"),
    ("mapped.csv", ["M1"], {"mapping": {"M1": "torque_Nm"}, "sample_time": -1.0}, "CSV026", None, "-1.0"),
    ("mapped.csv", ["M1"], {"mapping": {"M1": "torque_Nm"}, "sample_time": math.nan}, "CSV026", None, "nan"),
]


def _expect(path: Path, code: str, line: int | None, fragment: str, required, **kwargs) -> SdnnError:
    with pytest.raises(SdnnError) as info:
        read_csv(path, required, **kwargs)
    error = info.value
    diag = error.diagnostics[0]
    assert diag.code == code, str(error)
    assert diag.location is not None and diag.location.file == os.fspath(path)
    assert diag.location.line == line, str(error)
    text = str(error)
    where = f"{os.fspath(path)}:{line}: " if line is not None else f"{os.fspath(path)}: "
    assert text.startswith(f"{where}error[{code}]"), text
    assert fragment in text, text
    assert "\n" not in text
    return error


def test_at_least_twenty_hand_written_bad_files():
    assert len({case[0] for case in BAD_CASES}) >= 20
    assert {case[0] for case in BAD_CASES} <= {p.name for p in BAD.iterdir()}


@pytest.mark.parametrize(("name", "required", "kwargs", "code", "line", "fragment"), BAD_CASES,
                         ids=[f"{c[0]}-{c[3]}-{i}" for i, c in enumerate(BAD_CASES)])
def test_bad_file(name, required, kwargs, code, line, fragment):
    _expect(BAD / name, code, line, fragment, required, **kwargs)


def test_codes_are_documented_and_distinct():
    import flowchart2sdnn.data.csvdata as module

    used = {case[3] for case in BAD_CASES} | {"CSV001", "CSV002", "CSV003", "CSV024"}
    for code in used:
        assert f"\n{code}  " in module.__doc__
    assert len(used) == 26  # every documented code is exercised somewhere in this file


def test_missing_file(tmp_path):
    _expect(tmp_path / "nope.csv", "CSV001", None, "file not found", W)


def test_directory(tmp_path):
    _expect(tmp_path, "CSV002", None, "is a directory", W)


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs FIFOs")
def test_fifo_is_refused_without_blocking(tmp_path):
    fifo = tmp_path / "pipe.csv"
    os.mkfifo(fifo)
    _expect(fifo, "CSV002", None, "not a regular file", W)


@pytest.mark.skipif(os.name != "posix" or os.geteuid() == 0, reason="root reads anything")
def test_unreadable(tmp_path):
    path = tmp_path / "secret.csv"
    path.write_text("time,w1,w2\n0,1,2\n0.001,1,2\n0.002,1,2\n")
    path.chmod(0)
    try:
        _expect(path, "CSV003", None, "cannot read", W)
    finally:
        path.chmod(0o600)


def test_unreadable_path_even_as_root(tmp_path):
    plain = tmp_path / "plain.csv"
    plain.write_text("time,w1,w2\n")
    _expect(plain / "x.csv", "CSV003", None, "cannot read the file: Not a directory", W)
    _expect(tmp_path / ("a" * 5000), "CSV003", None, "cannot read", W)


def test_field_beyond_csv_limit(tmp_path):
    path = tmp_path / "huge_field.csv"
    limit = csv.field_size_limit()
    path.write_text(f'time,w1,w2\n0,1,2\n0.001,1,"{"9" * (limit + 10)}"\n')
    _expect(path, "CSV022", 3, "field larger than field limit", W)


def test_late_non_utf8_byte_is_found_by_line(tmp_path):
    # far beyond the first read buffer and the NUL sniffing window
    lines = ["time,w1,w2"] + [f"{k * 1e-3:.6f},1,2" for k in range(40000)]
    data = ("\n".join(lines) + "\n").encode()
    data += b"40.000000,1,2\xff\n"
    path = tmp_path / "late.csv"
    path.write_bytes(data)
    _expect(path, "CSV015", 40002, "0xff", W)


# ---------------------------------------------------------------- parse_mapping


def test_parse_mapping_good():
    assert parse_mapping([" M1 = torque_Nm", "w2=speed", "time=t [s]", "x=a=b", "w2=speed"]) == {
        "M1": "torque_Nm", "w2": "speed", "time": "t [s]", "x": "a=b"}
    assert parse_mapping([]) == {}


@pytest.mark.parametrize("items", [["M1"], ["=torque"], ["M1="], [" = "], ["M1=a", "M1=b"], [""]])
def test_parse_mapping_bad(items):
    with pytest.raises(SdnnError) as info:
        parse_mapping(items)
    assert info.value.diagnostics[0].code == "CSV024"
    assert "--map" in str(info.value)


# ---------------------------------------------------------------- good files, numpy.loadtxt as the oracle


def _oracle(path: Path, usecols, **kwargs) -> np.ndarray:
    return np.loadtxt(path, delimiter=",", skiprows=1, usecols=usecols, encoding="utf-8-sig", ndmin=2, **kwargs)


def test_bom_crlf_quoted(tmp_path):
    rng = np.random.default_rng(1)
    values = rng.standard_normal((50, 2))
    body = "".join(f'{k * 0.01!r},"{float(a)!r}", {float(b)!r} \r\n' for k, (a, b) in enumerate(values))
    path = tmp_path / "excel.csv"
    path.write_bytes(b"\xef\xbb\xbf" + ('"Time","w1", w2 \r\n' + body).encode())
    data = read_csv(path, W, sample_time=0.01)
    ref = _oracle(path, (0, 1, 2), quotechar='"')
    np.testing.assert_array_equal(data.time, ref[:, 0])
    np.testing.assert_array_equal(data.columns["w1"], ref[:, 1])
    np.testing.assert_array_equal(data.columns["w2"], values[:, 1])
    assert data.n_rows == 50 and data.source_columns == {"w1": "w1", "w2": "w2"}
    assert data.sha256 == hashlib.sha256(path.read_bytes()).hexdigest()
    assert abs(data.sample_time - 0.01) < 1e-15


def test_jitter_half_percent_is_accepted_and_reported(tmp_path):
    ts = 1e-3
    time = np.arange(200) * ts
    time[120:] += 0.005 * ts  # one step 0.5 % long; the rest exact
    rng = np.random.default_rng(2)
    u = rng.uniform(-1, 1, 200)
    path = tmp_path / "jitter.csv"
    write_csv(path, {"time_s": time, "u": u}, float_format="%.17g")
    data = read_csv(path, ["u"], sample_time=ts)
    ref = _oracle(path, (0, 1))
    np.testing.assert_array_equal(data.time, ref[:, 0])
    np.testing.assert_array_equal(data.columns["u"], ref[:, 1])
    assert data.max_step_deviation == pytest.approx(0.005, rel=1e-6)
    assert data.sample_time == pytest.approx(ts, rel=1e-12)
    # the same file with the median as reference: also within 1 %
    assert read_csv(path, ["u"]).max_step_deviation == pytest.approx(0.005, rel=1e-6)
    # 0.5 % over a 0.4 % tolerance: refused at the row after the long step (header line 1, row k at line k+2)
    with pytest.raises(SdnnError) as info:
        read_csv(path, ["u"], sample_time=ts, jitter_tolerance=0.004)
    assert info.value.diagnostics[0].code == "CSV020"
    assert info.value.diagnostics[0].location.line == 120 + 2


def test_mapping_and_explicit_time(tmp_path):
    path = tmp_path / "drive.csv"
    rows = [(k * 0.002, 0.5 * k, -k, k * k) for k in range(10)]
    path.write_text("stamp,torque_Nm,speed_rad_s,extra,extra\n" + "".join(
        f"{t!r},{a!r},{b!r},{c!r},0\n" for t, a, b, c in rows))
    data = read_csv(path, ["M1", "w"], mapping={"M1": "torque_Nm", "w": "speed_rad_s", "time": "stamp"},
                    sample_time=np.float32(0.002))
    ref = _oracle(path, (0, 1, 2))
    np.testing.assert_array_equal(data.columns["M1"], ref[:, 1])
    np.testing.assert_array_equal(data.columns["w"], ref[:, 2])
    np.testing.assert_array_equal(data.time, ref[:, 0])
    assert data.source_columns == {"M1": "torque_Nm", "w": "speed_rad_s"}
    assert set(data.columns) == {"M1", "w"}  # duplicate 'extra' is not needed: no error
    with pytest.raises(ValueError):
        data.columns["M1"][0] = 1.0  # read-only


def test_time_detection_order_and_case(tmp_path):
    path = tmp_path / "t.csv"
    path.write_text("T,u,TIME_S\n0,1,5\n0.5,2,6\n1.0,3,7\n")
    data = read_csv(path, ["u"])
    np.testing.assert_array_equal(data.time, [0.0, 0.5, 1.0])  # 't' comes before 'time_s' in TIME_COLUMNS
    assert data.sample_time == 0.5 and data.max_step_deviation == 0.0


def test_no_time_column(tmp_path):
    path = tmp_path / "nt.csv"
    path.write_text("sample_index,u\n0,1\n1,2\n2,3\n")
    data = read_csv(path, ["u"], sample_time=0.02)
    assert data.time is None and data.sample_time == 0.02 and data.max_step_deviation is None
    assert type(read_csv(path, ["u"], sample_time=np.float32(0.5)).sample_time) is float
    assert read_csv(path, ["u"]).sample_time is None


def test_blank_lines_multiline_field_and_slice(tmp_path):
    path = tmp_path / "odd.csv"
    path.write_text('\ntime,u,note\n0,1,"a\nb"\n\n0.1,2,x\n0.2,3,y\n0.3,4,z\n')
    data = read_csv(path, ["u"])
    np.testing.assert_array_equal(data.columns["u"], [1, 2, 3, 4])
    part = data.slice(1, 3)
    assert isinstance(part, Dataset) and part.n_rows == 2
    np.testing.assert_array_equal(part.columns["u"], [2, 3])
    np.testing.assert_allclose(part.time, [0.1, 0.2])
    assert data.slice(-2, None).n_rows == 2 and data.slice(3, 1).n_rows == 0
    assert part.sha256 == data.sha256 and part.path == data.path


def test_write_csv_round_trip_exact(tmp_path):
    rng = np.random.default_rng(3)
    cols = {"time": np.arange(100) * 1e-3, "a,b": rng.standard_normal(100), "c": rng.uniform(-1e9, 1e9, 100)}
    path = tmp_path / "out.csv"
    write_csv(path, cols, float_format="%.17g")
    assert path.read_text().splitlines()[0] == 'time,"a,b",c'
    data = read_csv(path, ["a,b", "c"], sample_time=1e-3)
    for name in ("a,b", "c"):
        np.testing.assert_array_equal(data.columns[name], cols[name])
    ref = _oracle(path, (1, 2), quotechar='"')
    np.testing.assert_array_equal(ref[:, 1], cols["c"])
    assert os.listdir(tmp_path) == ["out.csv"]
    with pytest.raises(ValueError):
        write_csv(path, {"a": np.zeros(3), "b": np.zeros(4)})


def test_default_format_ten_digits(tmp_path):
    path = tmp_path / "g.csv"
    write_csv(path, {"x": np.array([1 / 3, 2e-12, -12345678901.5])})
    assert path.read_text() == "x\n0.3333333333\n2e-12\n-1.23456789e+10\n"


@pytest.mark.realdata
@pytest.mark.skipif(not REAL.is_dir(), reason="shared real data absent")
def test_real_dataset_matches_loadtxt():
    path = REAL / "emps" / "train.csv"
    if not path.exists():
        pytest.skip("EMPS data absent")
    data = read_csv(path, ["force_N", "q_meas_m"], sample_time=1e-3)
    ref = _oracle(path, (0, 1, 3))
    np.testing.assert_array_equal(data.columns["force_N"], ref[:, 1])
    np.testing.assert_array_equal(data.columns["q_meas_m"], ref[:, 2])
    assert data.max_step_deviation < 1e-3


# ---------------------------------------------------------------- fuzzing: a Dataset or an SdnnError, nothing else

CELLS = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.integers(-10**30, 10**30).map(str),
    st.sampled_from(["", " ", "nan", "NaN", "-inf", "1e999", "abc", '"1"', '"a,b"', '"', '""', "1_0", "\u0661",
                     "0x10", "1,5", "\t", "\x00", "\ufeff", "time", "w1", "é", "\r", "\n"]),
    st.text(max_size=6),
)


def _fuzz_row(draw, names: list[str], k: int) -> list[str]:
    cells = []
    for name in names:
        if draw(st.integers(0, 39)) == 0:
            cells.append(draw(CELLS))
        elif name.strip().lower() in ("time", "t"):
            cells.append(repr(k * 1e-3 * draw(st.sampled_from([1.0, 1.0, 1.0, 1.0, 1.003, 0.98, -1.0]))))
        else:
            cells.append(repr(draw(st.floats(-1e3, 1e3))))
    if draw(st.integers(0, 39)) == 0:
        cells = cells[:-1] if draw(st.booleans()) else cells + ["1"]
    return cells


@st.composite
def csv_texts(draw):
    """Mostly plausible files (the needed columns, numbers, a time column) with rare defects of every kind."""
    delimiter = draw(st.sampled_from([",", ",", ",", ",", ",", ";", "\t"]))
    newline = draw(st.sampled_from(["\n", "\r\n", "\r"]))
    extras = draw(st.lists(st.sampled_from(["time", "Time", "t", "x", "", "w1 ", '"w2"', "w1"]), max_size=3))
    names = draw(st.permutations(["w1", "w2", *extras]))
    if draw(st.integers(0, 9)) == 0:
        names = draw(st.lists(st.one_of(CELLS, st.sampled_from(["time", "w1", "w2"])), max_size=5))
    rows = [_fuzz_row(draw, names, k) for k in range(draw(st.integers(0, 8)))]
    blank = draw(st.sampled_from(["", newline]))
    lines = [delimiter.join(names)] + [delimiter.join(row) for row in rows]
    text = blank + newline.join(lines) + draw(st.sampled_from(["", newline, newline * 2]))
    data = text.encode("utf-8", "surrogatepass")
    if draw(st.booleans()):
        data = b"\xef\xbb\xbf" + data
    return data


FUZZ = settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])


def _read_any(path: Path, **kwargs) -> None:
    try:
        data = read_csv(path, W, **kwargs)
    except SdnnError as error:
        assert "\n" not in str(error) and error.diagnostics[0].code.startswith("CSV")
        return
    assert data.n_rows >= kwargs.get("min_rows", 3)
    for values in [*data.columns.values(), *([data.time] if data.time is not None else [])]:
        assert values.dtype == np.float64 and len(values) == data.n_rows and np.all(np.isfinite(values))


@FUZZ
@given(data=csv_texts(), sample_time=st.sampled_from([None, 1e-3, 1.0]), min_rows=st.integers(1, 4))
def test_fuzz_structured_csv(tmp_path, data, sample_time, min_rows):
    path = tmp_path / "fuzz.csv"
    path.write_bytes(data)
    _read_any(path, sample_time=sample_time, min_rows=min_rows)


@FUZZ
@given(data=st.binary(max_size=300), prefix=st.sampled_from([b"", b"time,w1,w2\n", b"w1,w2\r\n0,1\r\n"]))
def test_fuzz_random_bytes(tmp_path, data, prefix):
    path = tmp_path / "fuzz.bin"
    path.write_bytes(prefix + data)
    _read_any(path, min_rows=1)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(values=st.lists(st.tuples(st.floats(allow_nan=False, allow_infinity=False, width=64),
                                 st.floats(-1e6, 1e6)), min_size=3, max_size=30),
       crlf=st.booleans(), bom=st.booleans(), quote=st.booleans())
def test_fuzz_valid_files_match_loadtxt(tmp_path, values, crlf, bom, quote):
    end = "\r\n" if crlf else "\n"
    q = '"' if quote else ""
    buffer = io.StringIO()
    buffer.write(f"{q}w1{q},x,{q}w2{q}{end}")
    for a, b in values:
        buffer.write(f"{q}{a!r}{q},junk,{b!r}{end}")
    path = tmp_path / "valid.csv"
    path.write_bytes((b"\xef\xbb\xbf" if bom else b"") + buffer.getvalue().encode())
    data = read_csv(path, W)
    ref = _oracle(path, (0, 2), quotechar='"')
    np.testing.assert_array_equal(data.columns["w1"], ref[:, 0])
    np.testing.assert_array_equal(data.columns["w2"], ref[:, 1])
    assert data.time is None and data.n_rows == len(values)
