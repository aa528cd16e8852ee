"""Malformed data given to `sdnn identify`: one line on stderr naming file, line and column, exit 1, no file.

The generic CSV cases of tests/data/bad_csv (columns time, w1, w2 at 1 ms) are fed through the lag chart
tests/data/bad_identify/lag.yaml (input w1, output w2); the cases specific to identification (a missing
output or input, a time step that disagrees with the chart's sample time, --map to a missing column, a bad
validation file) use the engine chart and tests/data/bad_identify. No case gets as far as fitting. (Jittered
timestamps and other delimiters load with a note: tests/test_timebase.py.)
"""

from __future__ import annotations

from pathlib import Path

import pytest
from click.testing import CliRunner

from flowchart2sdnn.cli import main

TESTS = Path(__file__).parent
BAD_CSV = TESTS / "data" / "bad_csv"
BAD_ID = TESTS / "data" / "bad_identify"
LAG = BAD_ID / "lag.yaml"
ENGINE = TESTS.parent / "diagrams" / "engine.yaml"

# (data file, chart, extra arguments, code, line or None, column text or None)
CASES = [
    (BAD_CSV / "arabic_digits.csv", LAG, [], "CSV004", 3, "column 'w2'"),
    (BAD_CSV / "blank_cell.csv", LAG, [], "CSV006", 4, "column 'w2'"),
    (BAD_CSV / "empty_cell.csv", LAG, [], "CSV006", 3, "column 'w1'"),
    (BAD_CSV / "inf_negative.csv", LAG, [], "CSV005", 4, "column 'w2'"),
    (BAD_CSV / "overflow_to_inf.csv", LAG, [], "CSV005", 3, "column 'w1'"),
    (BAD_CSV / "nan_lower.csv", LAG, [], "CSV005", 3, "column 'w1'"),
    (BAD_CSV / "nan_mixed_case.csv", LAG, [], "CSV005", 5, "column 'w2'"),
    (BAD_CSV / "nan_in_time.csv", LAG, [], "CSV005", 4, "column 'time'"),
    (BAD_CSV / "nan_before_text.csv", LAG, [], "CSV005", 3, "column 'w2'"),
    (BAD_CSV / "quoted_text.csv", LAG, [], "CSV004", 3, "column 'w1'"),
    (BAD_CSV / "text_in_number.csv", LAG, [], "CSV004", 17, "column 'w2'"),
    (BAD_CSV / "text_after_blank_and_multiline.csv", LAG, [], "CSV004", 7, "column 'w1'"),
    (BAD_CSV / "underscore_number.csv", LAG, [], "CSV004", 3, "column 'w1'"),
    (BAD_CSV / "missing_column.csv", LAG, [], "CSV012", 1, "column 'w2'"),
    (BAD_CSV / "duplicate_needed.csv", LAG, [], "CSV013", 1, "column 'w1'"),
    (BAD_CSV / "duplicate_time.csv", LAG, [], "CSV013", 1, "time column 'Time'"),
    (BAD_CSV / "time_decreasing.csv", LAG, [], "CSV019", 5, "column 'time'"),
    (BAD_CSV / "time_repeats.csv", LAG, [], "CSV019", 4, "column 'time'"),
    (BAD_CSV / "time_in_ms.csv", LAG, [], "CSV021", 3, "column 'time'"),
    (BAD_CSV / "ragged_short.csv", LAG, [], "CSV010", 4, "2 fields"),
    (BAD_CSV / "ragged_long.csv", LAG, [], "CSV011", 3, "4 fields"),
    (BAD_CSV / "decimal_comma.csv", LAG, [], "CSV011", 2, "4 fields"),
    (BAD_CSV / "semicolon_rows.csv", LAG, [], "CSV010", 3, "1 fields"),
    (BAD_CSV / "semicolon.csv", LAG, ["--delimiter", ","], "CSV014", 1, "found ';'"),
    (BAD_CSV / "tab.csv", LAG, ["--delimiter", ","], "CSV014", 1, "found tab"),
    (BAD_CSV / "latin1.csv", LAG, [], "CSV015", 4, "0xb0"),
    (BAD_CSV / "binary.csv", LAG, [], "CSV015", 3, "binary"),
    (BAD_CSV / "utf16.csv", LAG, [], "CSV015", 1, "UTF-16"),
    (BAD_CSV / "no_header.csv", LAG, [], "CSV023", 1, "no header row"),
    (BAD_CSV / "unterminated_quote.csv", LAG, [], "CSV022", 4, "quoted"),
    (BAD_CSV / "header_only.csv", LAG, [], "CSV008", 1, "no data rows"),
    (BAD_CSV / "empty.csv", LAG, [], "CSV007", None, None),
    (BAD_CSV / "blank_lines_only.csv", LAG, [], "CSV007", None, None),
    (BAD_CSV / "too_few_rows.csv", LAG, [], "CSV009", None, None),
    # specific to identify: the engine chart needs M1 (input) and w1 (output) at T = 1 ms
    (BAD_ID / "missing_output.csv", ENGINE, [], "CSV012", 1, "column 'w1' is missing"),
    (BAD_ID / "missing_input.csv", ENGINE, [], "CSV012", 1, "column 'M1' is missing"),
    (BAD_ID / "output_misspelled.csv", ENGINE, [], "CSV012", 1, "column 'w1' is missing"),
    (BAD_ID / "two_speed_columns.csv", ENGINE, [], "CSV013", 1, "column 'w1'"),
    (BAD_ID / "step_mismatch.csv", ENGINE, [], "CSV021", 3, "column 'time'"),
    (BAD_ID / "nan_in_output.csv", ENGINE, [], "CSV005", 6, "column 'w1'"),
    (BAD_ID / "text_in_input.csv", ENGINE, [], "CSV004", 4, "column 'M1'"),
    (BAD_ID / "good_small.csv", ENGINE, ["--map", "w1=speed"], "CSV016", 1, "'speed'"),
    (BAD_ID / "good_small.csv", ENGINE, ["--map", "torque=M1"], "CSV025", None, "torque"),
    (BAD_ID / "good_small.csv", ENGINE, ["--map", "time=t"], "CSV016", 1, "'t'"),
]


def _id(case) -> str:
    return f"{case[0].name}{'+' + '_'.join(case[2]) if case[2] else ''}"


@pytest.mark.parametrize("case", CASES, ids=_id)
def test_malformed_data_gives_one_line_and_leaves_no_file(case, tmp_path):
    data, chart, extra, code, line, column = case
    out = tmp_path / "out"
    out.mkdir()
    res = CliRunner().invoke(main, ["identify", str(chart), str(data), "-o", str(out / "r.json"),
                                    *extra], catch_exceptions=False)
    assert res.exit_code == 1, res.output
    lines = res.stderr.splitlines()
    assert len(lines) == 1, res.stderr
    message = lines[0]
    assert f"error[{code}]" in message
    if code != "CSV025":  # option errors name the option, not a file
        prefix = f"{data}:{line}: " if line is not None else f"{data}: "
        assert message.startswith(prefix), message
    if column is not None:
        assert column in message
    assert "Traceback" not in res.output
    assert list(out.iterdir()) == []  # neither RESULT.json, nor the chart, nor temporary files


def test_a_map_item_without_equals_is_a_usage_error(tmp_path):
    res = CliRunner().invoke(main, ["identify", str(BAD_ID / "good_small.csv"), "--diagram", str(ENGINE),
                                    "-o", str(tmp_path / "r.json"), "--map", "w1"])
    assert res.exit_code == 2, res.output
    assert "Invalid value for '--map': 'w1' is not NAME=HEADER" in res.stderr
    assert list(tmp_path.iterdir()) == []


def test_at_least_twenty_cases_name_line_and_column():
    assert sum(1 for c in CASES if c[4] is not None and c[5] and "column" in c[5]) >= 20


def test_a_bad_validation_file_is_named_and_nothing_is_written(tmp_path):
    res = CliRunner().invoke(main, ["identify", str(ENGINE), str(BAD_ID / "good_small.csv"),
                                    "--validate", str(BAD_ID / "nan_in_output.csv"), "-o", str(tmp_path / "r.json")])
    assert res.exit_code == 1
    assert res.stderr.count("\n") == 1
    assert res.stderr.startswith(f"{BAD_ID / 'nan_in_output.csv'}:6: error[CSV005] column 'w1'")
    assert list(tmp_path.iterdir()) == []


def test_a_bad_fix_from_file_is_named_and_nothing_is_written(tmp_path):
    not_a_result = tmp_path / "r0.json"
    not_a_result.write_text('{"format": "something else"}')
    res = CliRunner().invoke(main, ["identify", str(ENGINE), str(BAD_ID / "good_small.csv"),
                                    "--fix-from", str(not_a_result), "-o", str(tmp_path / "r.json")])
    assert res.exit_code == 1
    assert res.stderr.count("\n") == 1 and "RES003" in res.stderr and str(not_a_result) in res.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r0.json"]
