"""Property-based fuzzing of the chart front end (issue 6, "Bad input").

Generated and mutated charts - wrong types, unknown kinds, missing and extra keys, cyclic and dangling
references, huge numbers, NaN, unicode, deep nesting, duplicate keys, damaged text, alias bombs - go through
load, validate, lint and compile. Each must end in a network (that serializes and loads back) or an
SdnnError whose first line names the file and a line; any other exception is a failure. The generator is
benchmarks/fuzz_charts.py (the 10 000-case run uses it too); hypothesis drives its random choices through
``st.randoms()``, so a failure shrinks to a small case.
"""

from __future__ import annotations

import importlib.util
import random
import re
import sys
from pathlib import Path

import pytest
import yaml
from click.testing import CliRunner
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from flowchart2sdnn.cli import main

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = sorted((ROOT / "diagrams").glob("*.yaml"))


def _load_generator():
    spec = importlib.util.spec_from_file_location("fuzz_charts", ROOT / "benchmarks" / "fuzz_charts.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault("fuzz_charts", module)
    spec.loader.exec_module(module)
    return module


F = _load_generator()
FUZZ = settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])


@pytest.fixture(scope="module")
def case_path(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("fuzz") / "case.yaml"


def _check(data: bytes, path: Path) -> F.Outcome:
    out = F.run_case(data, path)
    assert out.status != "crash", f"{data[:500]!r}\n{out.detail}"
    return out


@FUZZ
@given(r=st.randoms(use_true_random=False))
def test_generated_and_mutated_charts_compile_or_fail_cleanly(case_path, r):
    _check(F.generate_case(r), case_path)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(example=st.sampled_from(EXAMPLES), r=st.randoms(use_true_random=False))
def test_mutated_example_charts_compile_or_fail_cleanly(case_path, example, r):
    doc = yaml.safe_load(example.read_text())
    _check(F.render(r, F.mutate(r, doc)), case_path)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@example(k=-6513)  # at two_mass.yaml's N = 8 the guard's growth radius to the 8th power overflowed a float
@given(k=st.one_of(st.text(max_size=60),
                   st.text(alphabet="J1cd2pi.e+-*/^() _'[],%", max_size=80),
                   st.integers(), st.floats(allow_nan=True, allow_infinity=True)))
def test_any_gain_expression_compiles_or_fails_cleanly(case_path, k):
    doc = yaml.safe_load((ROOT / "diagrams" / "two_mass.yaml").read_text())
    doc["blocks"]["acc1"]["k"] = k
    out = _check(yaml.safe_dump(doc, sort_keys=False, allow_unicode=True).encode("utf-8"), case_path)
    if out.status == "error":
        assert out.code.startswith(("CHART", "LINT", "COMPILE", "YAML", "identify:FIT")), out


def test_the_generator_reaches_the_compiler(case_path):
    """The fuzz is only worth something if a good share of cases compile and the rest fail in many ways."""
    r = random.Random(11)
    # 300 cases: lint errors are rare among the generator's mistakes (2 in the first 150 before the product
    # block joined the kinds and shifted the random stream, 1 in 300 after)
    outcomes = [_check(F.generate_case(r), case_path) for _ in range(300)]
    compiled = sum(o.status == "ok" for o in outcomes)
    codes = {o.code for o in outcomes if o.status == "error"}
    assert compiled >= 30
    assert len(codes) >= 10 and any(c.startswith("YAML") for c in codes) and any(c.startswith("LINT") for c in codes)


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                 HealthCheck.function_scoped_fixture])
@given(r=st.randoms(use_true_random=False))
def test_cli_compile_on_fuzzed_charts_is_success_or_one_line(tmp_path, r):
    chart = tmp_path / "chart.yaml"
    out = tmp_path / "net.json"
    out.unlink(missing_ok=True)
    chart.write_bytes(F.generate_case(r))
    result = CliRunner().invoke(main, ["compile", str(chart), "-o", str(out)])
    assert result.exit_code in (0, 1), result.output
    assert "Traceback" not in result.output and "internal error" not in result.output
    if result.exit_code == 1:
        lines = result.stderr.splitlines()
        assert len(lines) == 1 and re.match(re.escape(str(chart)) + r":\d+", lines[0]), result.stderr
        assert not out.exists()
    else:
        assert out.exists()
    lint = CliRunner().invoke(main, ["lint", "--format", "json", str(chart)])
    assert lint.exit_code == result.exit_code
    assert "Traceback" not in lint.output
