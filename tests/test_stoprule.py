"""The status line names the one stop rule that fired. Each case runs the real trainer with only that rule able
to end the fit (the oracle is the choice of options), then reads the rule back from status and message."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from flowchart2sdnn.cli import main
from flowchart2sdnn.fit.lm import LMOptions, levenberg_marquardt
from flowchart2sdnn.fit.stoprule import status_line, stop_rule

T = np.linspace(0.0, 4.0, 40)
Y = 2.0 * np.exp(-0.7 * T) + 0.05 * np.random.default_rng(0).standard_normal(T.size)  # noise: a cost floor


def decay(p):
    """y = a exp(-b t): residual y - yhat and the Jacobian of yhat."""
    f = np.exp(-p[1] * T)
    return Y - p[0] * f, np.column_stack([f, -p[0] * T * f])


#: everything off but the rule under test (min_grad 0, no step limit, a generous iteration limit)
OFF = dict(min_grad=0.0, min_rel_step=0.0, max_iter=500, mu_max=1e300, max_mu_tries=200)

CASES = {
    "max_iter": dict(OFF, max_iter=2),
    "min_grad": dict(OFF, min_grad=1e-3),
    "min_rel_cost_change": dict(OFF, min_rel_cost_change=1e-3),
    "stall_decrease": dict(OFF, stall_decrease=1e-3, stall_iterations=3),
    "crawl_decrease": dict(OFF, crawl_decrease=1e-3, crawl_iterations=3),
    "negligible_gain": dict(OFF, negligible_gain=0.5),
}


@pytest.mark.parametrize("rule", sorted(CASES))
def test_the_rule_read_back_is_the_only_one_that_could_fire(rule):
    res = levenberg_marquardt(decay, np.array([0.5, 2.0]), ["a", "b"], options=LMOptions(**CASES[rule]))
    got = stop_rule(res.status, res.message)
    assert got is not None, res.message
    assert got.rule == rule, (res.status, res.message)
    assert got.iterations == res.iterations and got.cost == pytest.approx(res.cost, rel=1e-5)
    line = status_line(res.status, res.message, rule != "max_iter")
    assert line.startswith(f"status: {res.status} (")
    # one rule named, not the list of every rule the status word stands for
    others = {"min_rel_cost_change", "stall_decrease", "crawl_decrease"} - {rule}
    assert not any(o in line for o in others), line


def test_a_message_of_another_kind_is_shown_as_it_is():
    assert stop_rule("completed", "quasi-online: 20 windows") is None
    assert status_line("no_excitation", "the input never moves") == "status: no_excitation - the input never moves"
    assert status_line("max_iter", "garbled") == "status: max_iter - garbled"
    assert status_line("max_iter", None) == "status: max_iter"


def test_the_status_line_says_whether_the_fit_converged():
    res = levenberg_marquardt(decay, np.array([0.5, 2.0]), ["a", "b"], options=LMOptions(**CASES["max_iter"]))
    line = status_line(res.status, res.message, False)
    assert line.startswith("status: max_iter (not converged after 2 iterations, cost ")
    assert line.endswith("the iteration limit max_iter was reached")


def test_identify_names_the_rule_on_its_status_line_and_its_not_converged_warning(tmp_path):
    chart = str(Path(__file__).resolve().parents[1] / "diagrams" / "mass_spring_damper.yaml")
    runner = CliRunner()
    made = runner.invoke(main, ["excite", chart, "--seconds", "0.3", "--amplitude", "-50", "50",
                                "-o", str(tmp_path / "msd.csv")])
    assert made.exit_code == 0, made.output
    res = runner.invoke(main, ["identify", chart, str(tmp_path / "msd.csv"), "--max-iter", "1", "--shooting", "off",
                               "--no-floor-bias"])
    assert res.exit_code == 0, res.output
    assert res.stdout.startswith("status: max_iter (not converged after 1 iteration, cost ")
    assert "warning: not converged: the iteration limit max_iter was reached (after 1 iteration); raise --max-iter" \
        in res.stderr
