"""Geodesic acceleration (Transtrum & Sethna 2012): the second-order correction against a hand computation on a
residual that is exactly quadratic, and fits that still end at the known minima (Rosenbrock, NIST Misra1a)."""

from types import SimpleNamespace

import nist_misra1a as misra
import numpy as np
import pytest

from flowchart2sdnn.fit.lm import LMOptions, levenberg_marquardt
from flowchart2sdnn.fit.steps import geodesic_step


def rosenbrock(p):
    e = np.array([10 * (p[1] - p[0] ** 2), 1 - p[0]])
    return e, -np.array([[-20 * p[0], 10.0], [-1.0, 0.0]])  # J = d yhat / dx = -de/dx


def test_the_acceleration_is_the_damped_solve_of_the_exact_second_derivative():
    """e(u) = y - (B u + 1/2 [uᵀC_k u]_k) is quadratic, so the finite difference along du is exact:
    e_vv[k] = -duᵀ C_k du, and a = (JᵀJ + mu I)⁻¹ Jᵀ e_vv with J = B + [C_k u]_k."""
    rng = np.random.default_rng(3)
    B = rng.normal(size=(6, 2))
    C = rng.normal(size=(6, 2, 2))
    C = C + C.transpose(0, 2, 1)
    y = rng.normal(size=6)
    u = np.array([0.3, -0.2])

    def residual(x):
        return y - (B @ x + 0.5 * np.einsum("i,kij,j->k", x, C, x))

    J = B + np.einsum("kij,j->ki", C, u)
    e = residual(u)
    mu = 0.5
    A = J.T @ J
    du = np.linalg.solve(A + mu * np.eye(2), J.T @ e)
    point = SimpleNamespace(u=u, e=e)  # unbounded: the internal coordinates are the quantities
    out = geodesic_step(residual, point, J, J, A, None, du, mu, 1.99)
    e_vv = -np.einsum("i,kij,j->k", du, C, du)
    a = np.linalg.solve(A + mu * np.eye(2), J.T @ e_vv)
    np.testing.assert_allclose(out, du + 0.5 * a, rtol=1e-7)


def test_a_step_that_bends_more_than_alpha_falls_back_to_the_plain_step():
    rng = np.random.default_rng(4)
    J = rng.normal(size=(5, 2))
    u = np.zeros(2)

    def residual(x):  # strongly curved along every direction
        return -(J @ x) - 50.0 * float(x @ x) * np.ones(5)

    e = residual(u) + 1.0
    A = J.T @ J
    du = np.linalg.solve(A, J.T @ e)
    point = SimpleNamespace(u=u, e=e)
    out = geodesic_step(lambda x: residual(x) + 1.0, point, J, J, A, None, du, 0.0, 0.75)
    np.testing.assert_array_equal(out, du)
    bent = geodesic_step(lambda x: residual(x) + 1.0, point, J, J, A, None, 1e-4 * du, 0.0, 0.75)
    assert not np.array_equal(bent, 1e-4 * du)  # a short step on the same curve is bent


@pytest.mark.parametrize("scale", ["none", "jac"])
def test_rosenbrock_still_ends_at_its_minimum_in_fewer_iterations(scale):
    plain = levenberg_marquardt(rosenbrock, [-1.2, 1.0], ["x1", "x2"], options=LMOptions(scale=scale))
    bent = levenberg_marquardt(rosenbrock, [-1.2, 1.0], ["x1", "x2"], options=LMOptions(scale=scale, geodesic=0.75),
                               residual=lambda p: rosenbrock(p)[0])
    assert bent.converged, bent.message
    np.testing.assert_allclose(bent.x, [1.0, 1.0], atol=1e-8)
    assert bent.iterations < plain.iterations


def test_nist_misra1a_with_acceleration():
    res = levenberg_marquardt(misra.fun, misra.START_1, ["b1", "b2"], options=LMOptions(geodesic=0.75),
                              residual=misra.residual)
    assert res.converged, res.message
    np.testing.assert_allclose(res.x, misra.CERTIFIED, rtol=1e-6)
    np.testing.assert_allclose(2 * res.cost, misra.RESIDUAL_SUM_OF_SQUARES, rtol=1e-8)


def test_the_option_is_checked():
    with pytest.raises(ValueError, match="geodesic"):
        LMOptions(geodesic=-0.1)
    with pytest.raises(ValueError, match="geodesic"):
        LMOptions(geodesic=float("nan"))


def test_identify_cli_takes_plain_steps(tmp_path):
    """`--lm-steps plain` is the library's lm_geodesic = 0 (the same iterates), recorded in RESULT.json."""
    import json
    from pathlib import Path

    from click.testing import CliRunner

    import flowchart2sdnn as sd
    from flowchart2sdnn.cli import main

    root = Path(__file__).resolve().parent.parent
    # the paper's free-slope neurons: the chart whose fit takes the transform's geodesic steps
    chart, csv = root / "tests" / "data" / "engine_neurons.yaml", root / "examples" / "data" / "engine_idle.csv"
    docs = {}
    for steps in ("plain", "geodesic"):
        out = tmp_path / f"{steps}.json"
        res = CliRunner().invoke(main, ["identify", str(csv), "--diagram", str(chart), "--max-iter", "5",
                                        "--curve-start", "random", "--no-floor-bias", "--lm-steps", steps,
                                        "--quiet", "-o", str(out)])
        assert res.exit_code == 0, res.output
        docs[steps] = json.loads(out.read_text())
    assert docs["plain"]["settings"]["lm_geodesic"] == 0.0 and docs["geodesic"]["settings"]["lm_geodesic"] == 0.75
    lib = sd.identify(chart, sd.read_csv(csv), max_iter=5, curve_start="random", floor_bias=False, lm_geodesic=0.0)
    assert docs["plain"]["parameters"]["J1"]["value"] == lib.parameters["J1"].value
    assert docs["plain"]["parameters"]["J1"]["value"] != docs["geodesic"]["parameters"]["J1"]["value"]
    bad = CliRunner().invoke(main, ["identify", str(csv), "--diagram", str(chart), "--lm-steps", "bent"])
    assert bad.exit_code == 2


def test_the_cli_defaults_of_max_iter_are_the_libraries():
    """The CLI shows the libraries' safety limits (both read them from the rule book, flowchart2sdnn.rules)."""
    from click.testing import CliRunner

    from flowchart2sdnn.cli import main
    from flowchart2sdnn.diagnose.fitting import DiagnoseSettings
    from flowchart2sdnn.identify.settings import IdentifySettings

    for command, settings in (("diagnose", DiagnoseSettings()), ("identify", IdentifySettings())):
        out = CliRunner().invoke(main, [command, "--help"], terminal_width=200).output
        text = " ".join(out.split())
        i = text.index("--max-iter")
        entry = text[i:text.index(" --", i + 1)]
        assert f"default: {settings.max_iter};" in entry or f"default: {settings.max_iter}]" in entry, entry
