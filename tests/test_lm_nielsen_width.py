"""The LM options the coulomb speed bench kept (benchmarks/bench_rough_init.py): Nielsen's damping schedule
against hand-computed updates, the scaled bound transform against its formula and finite differences, a first
Gauss-Newton step that lands on a linear model's closed-form fit, simulating the first trial with its Jacobian
(same iterates, fewer simulations), and NIST Misra1a's certified values with all of them."""

import dataclasses
import math

import nist_misra1a as misra
import numpy as np
import pytest

from flowchart2sdnn.fit.damping import nielsen_accepted, nielsen_refused
from flowchart2sdnn.fit.lm import LMOptions, levenberg_marquardt
from flowchart2sdnn.fit.transforms import Bounds

SPEED = dict(damping="nielsen", trial_jacobian=True, bound_width=0.01)


@pytest.mark.parametrize("rho, factor", [(0.5, 1.0), (0.75, 1 - 0.5**3), (0.25, 1 + 0.5**3), (0.9, 1 - 0.8**3),
                                         (1.0, 1 / 3), (3.0, 1 / 3), (0.0, 2.0)])
def test_nielsen_moves_mu_by_one_minus_the_cube_of_two_rho_minus_one(rho, factor):
    """Madsen, Nielsen & Tingleff (2004) eq. 2.21: mu *= max(1/3, 1 - (2 rho - 1)^3), by hand for each rho."""
    assert nielsen_accepted(2.0, rho, 1e-20) == pytest.approx(2.0 * factor, rel=1e-15)
    assert nielsen_accepted(2e-20, 1.0, 1e-20) == 1e-20  # never below mu_min


def test_nielsen_refusals_in_a_row_raise_mu_by_2_4_8():
    mu, nu = 1.0, 2.0
    seen = []
    for _ in range(4):
        mu, nu = nielsen_refused(mu, nu, math.inf)
        seen.append(mu)
    assert seen == [2.0, 8.0, 64.0, 1024.0] and nu == 32.0
    assert nielsen_refused(10.0, 4.0, 20.0)[0] == 20.0  # capped


def test_the_scaled_transform_is_its_formula_and_its_derivative():
    b = Bounds.make(["lo", "hi", "both", "free"], [0.5, -np.inf, 0.0, -np.inf], [np.inf, 2.0, 1.0, np.inf])
    w = np.array([0.003, 7.0, 5.0, 5.0])
    bw = b.with_width(w)
    u = np.array([0.01, -30.0, 0.3, -2.0])
    x = bw.to_external(u)
    # x = min + w (sqrt((u/w)^2 + 1) - 1), max - the same; the two-sided and free ones ignore w
    np.testing.assert_allclose(x, [0.5 + 0.003 * (math.sqrt((0.01 / 0.003) ** 2 + 1) - 1),
                                   2.0 - 7.0 * (math.sqrt((30.0 / 7.0) ** 2 + 1) - 1),
                                   0.5 + 0.5 * math.sin(0.3), -2.0], rtol=1e-14)
    np.testing.assert_allclose(bw.to_internal(x), np.abs(u) * [1, 1, 0, 0] + u * [0, 0, 1, 1], rtol=1e-12)
    h = 1e-7
    fd = np.array([(bw.to_external(u + h * e) - bw.to_external(u - h * e))[i] / (2 * h)
                   for i, e in enumerate(np.eye(4))])
    np.testing.assert_allclose(bw.dx_du(u), fd, rtol=1e-6)
    np.testing.assert_array_equal(b.with_width(np.ones(4)).to_external(u), b.to_external(u))  # w = 1: the old
    with pytest.raises(ValueError, match="width"):
        b.with_width([1.0, 0.0, 1.0, 1.0])


def test_a_small_quantity_above_zero_moves_in_straight_steps():
    """y = b t with b near 0.024 and min 0: the first undamped step from 3x the fit lands on the closed-form
    least-squares b* = Σty/Σt² with the scaled transform (the bend sits at 1 % of the start), and 31 % off it
    with the unit transform, where x = sqrt(u² + 1) - 1 bends within 1 (b lives near x = u²/2)."""
    t = np.linspace(0.0, 10.0, 50)
    y = 0.024 * t + 0.001 * np.random.default_rng(0).normal(size=t.size)
    best = (t @ y) / (t @ t)

    def one_step(width):
        opts = LMOptions(max_iter=1, mu0=1e-12, bound_width=width)
        return levenberg_marquardt(lambda b: (y - b[0] * t, t[:, None]), [0.072], ["b"], 0.0, None, opts).x[0]

    assert one_step(0.01) == pytest.approx(best, rel=1e-3)
    assert one_step(0.0) > 1.2 * best


def test_the_first_trial_with_its_jacobian_gives_the_same_iterates_with_fewer_simulations():
    runs = [levenberg_marquardt(misra.fun, misra.START_1, ["b1", "b2"], 0.0, None,
                                LMOptions(damping="nielsen", trial_jacobian=tj, geodesic=0.75),
                                residual=misra.residual) for tj in (False, True)]
    np.testing.assert_allclose(runs[1].cost_history, runs[0].cost_history, rtol=1e-12)
    np.testing.assert_array_equal(runs[1].x, runs[0].x)
    assert runs[1].nfev < runs[0].nfev - runs[0].iterations // 2


@pytest.mark.parametrize("start", [misra.START_1, np.array([250.0, 5e-4])])
@pytest.mark.parametrize("scale", ["none", "jac"])
def test_nist_misra1a_certified_with_the_speed_options(start, scale):
    res = levenberg_marquardt(misra.fun, start, ["b1", "b2"], 0.0, None,
                              LMOptions(scale=scale, geodesic=0.75, **SPEED), residual=misra.residual)
    assert res.converged, res.message
    np.testing.assert_allclose(res.x, misra.CERTIFIED, rtol=1e-6)
    np.testing.assert_allclose(2 * res.cost, misra.RESIDUAL_SUM_OF_SQUARES, rtol=1e-8)


def test_bad_speed_options_are_refused():
    with pytest.raises(ValueError, match="damping"):
        LMOptions(damping="marquardt")
    with pytest.raises(ValueError, match="bound_width"):
        LMOptions(bound_width=-1.0)


def test_identify_takes_nielsen_steps_only_where_no_learned_curve_is_fitted():
    """benchmarks/notes/rough_init.md "Speed": with Nielsen's schedule 3 of 12 seed-1 learned-chart fits ran into the limit."""
    from pathlib import Path

    import flowchart2sdnn as sd
    from flowchart2sdnn.diagram.validate import load_diagram
    from flowchart2sdnn.identify.offline.optimize import lm_options
    from flowchart2sdnn.identify.offline.problem import build_problem
    from flowchart2sdnn.identify.settings import IdentifySettings

    root = Path(__file__).resolve().parent.parent
    record = sd.read_csv(root / "examples" / "data" / "engine_idle.csv")
    # the paper's free-slope neurons: trainlm's schedule and the transform's geodesic steps
    learned = build_problem(load_diagram(root / "tests" / "data" / "engine_neurons.yaml"), record)
    opts = lm_options(IdentifySettings(), learned)
    assert (opts.damping, opts.trial_jacobian, opts.bounds, opts.geodesic) == ("trainlm", False, "transform", 0.75)
    # the tanh basis's weights enter linearly: no valley, so Nielsen's schedule, in the transform's coordinates
    basis = build_problem(load_diagram(root / "diagrams" / "engine.yaml"), record)
    opts = lm_options(IdentifySettings(), basis)
    assert (opts.damping, opts.trial_jacobian, opts.bounds, opts.geodesic) == ("nielsen", True, "transform", 0.75)
    chart = load_diagram(root / "diagrams" / "engine.yaml")
    fixed = dataclasses.replace(chart, blocks=tuple(dataclasses.replace(b, fixed=True) if b.kind == "nonlinear" else b
                                                    for b in chart.blocks))
    # without learned curves the default keeps the bounds in the box with a trust radius (test_lm_box.py);
    # with the transform, Nielsen's damping
    opts = lm_options(IdentifySettings(), build_problem(fixed, record))
    assert (opts.damping, opts.trial_jacobian, opts.bounds, opts.geodesic) == ("trust", True, "box", 0.0)
    opts = lm_options(IdentifySettings(lm_bounds="transform"), build_problem(fixed, record))
    assert (opts.damping, opts.trial_jacobian, opts.bounds, opts.geodesic) == ("nielsen", True, "transform", 0.75)
    opts = lm_options(IdentifySettings(lm_damping="trainlm"), build_problem(fixed, record))
    assert (opts.damping, opts.trial_jacobian) == ("trainlm", False)


def test_result_files_record_how_lm_kept_the_bounds_and_older_ones_read_as_the_transform():
    """RESULT.json's settings carry lm_bounds as lm_damping is carried; a file written before the key existed was
    fitted with the bound transform and reads back so (identify.document)."""
    import json
    from pathlib import Path

    import flowchart2sdnn as sd
    from flowchart2sdnn.diagram.validate import load_diagram
    from flowchart2sdnn.identify.document import dumps, from_document, to_document

    root = Path(__file__).resolve().parent.parent
    chart = load_diagram(root / "diagrams" / "engine.yaml")
    fixed = dataclasses.replace(chart, blocks=tuple(dataclasses.replace(b, fixed=True) if b.kind == "nonlinear" else b
                                                    for b in chart.blocks))
    record = sd.read_csv(root / "examples" / "data" / "engine_idle.csv")
    out = sd.identify(fixed, record, max_iter=5, floor_bias=False, lm_bounds="box")
    doc = json.loads(dumps(to_document(out)))
    assert doc["settings"]["lm_bounds"] == "box"
    assert from_document(doc).settings.lm_bounds == "box"
    del doc["settings"]["lm_bounds"]
    assert from_document(doc).settings.lm_bounds == "transform"
    with pytest.raises(ValueError, match="lm_bounds"):
        sd.identify(fixed, record, lm_bounds="clip")


def test_identify_cli_takes_the_bounds_handling(tmp_path):
    """`--lm-bounds box` is the library's lm_bounds = "box" (the same fit), recorded in RESULT.json; a wrong word
    is a usage error."""
    import json
    from pathlib import Path

    from click.testing import CliRunner

    import flowchart2sdnn as sd
    from flowchart2sdnn.cli import main

    root = Path(__file__).resolve().parent.parent
    chart, csv = root / "diagrams" / "engine.yaml", root / "examples" / "data" / "engine_idle.csv"
    out = tmp_path / "box.json"
    common = ["--max-iter", "5", "--curve-start", "random", "--no-floor-bias", "--quiet"]
    res = CliRunner().invoke(main, ["identify", str(csv), "--diagram", str(chart), *common, "--lm-bounds", "box",
                                    "-o", str(out)])
    assert res.exit_code == 0, res.output
    doc = json.loads(out.read_text())
    assert doc["settings"]["lm_bounds"] == "box"
    lib = sd.identify(chart, sd.read_csv(csv), max_iter=5, curve_start="random", floor_bias=False, lm_bounds="box")
    assert doc["parameters"]["J1"]["value"] == lib.parameters["J1"].value
    bad = CliRunner().invoke(main, ["identify", str(csv), "--diagram", str(chart), "--lm-bounds", "clip"])
    assert bad.exit_code == 2
