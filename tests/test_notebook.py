"""The notebook API: a notebook's cells run as a notebook runs them (each cell's last expression displayed with
its ``_repr_html_`` and ``repr``), and what they show is short, true to the result, and says what is wrong with
bad input.

nbclient is not needed: the cells are executed one by one in one namespace, the last expression of each
evaluated and displayed as IPython would (HTML where the value has ``_repr_html_``, else ``repr``). The records
are short so the fits (a few LM iterations) and the diagnosis (one round, two effects) take seconds.
"""

from __future__ import annotations

import ast
import os
import pydoc
import sys
from html.parser import HTMLParser
from pathlib import Path

import pytest
from diagnose_bench import chart, record

import flowchart2sdnn as sd

ROOT = Path(__file__).resolve().parent.parent
LIMIT = 5000  # bytes of summary() and _repr_html_ (the notebook issue's acceptance)
SHOWN_DAMP = 8  # the cell that shows the linearised chart read back
EXCITATION = {"amplitude": (-6.0, 6.0), "relay_level": 3.0, "relay_switch": 1.0, "relay_band": 0.2}

CELLS = [
    "import flowchart2sdnn as sd",
    "chart = sd.load_chart('diagrams/engine.yaml')\n"
    "data = sd.read_csv('examples/data/engine_idle.csv').slice(0, 3000)\n"
    "result = sd.identify(chart, data, max_iter=8)\n"
    "result",
    "print(result.summary())",
    "result.parameters_table()",
    "result.fit_table()",
    "comparison = result.compare({'first 2 s': data.slice(0, 2000)}, horizon=50)\n"
    "comparison",
    "comparison.frame()",
    "(out / 'stage1.json').write_text(result.to_json())\n"
    "from flowchart2sdnn.diagram.dump import dump_diagram\n"
    "(out / 'stage1.chart.yaml').write_text(dump_diagram(result.chart, {}))\n"
    "back = sd.read_result(out / 'stage1.json')\n"
    "back",
    "back.linearize(at={'w1': 2.0}).damp()",
    "again = sd.identify(chart, data, fix_from=back, max_iter=3)\n"
    "again",
    "diagnosis = sd.diagnose(one_mass, train, [val], rounds=1, effects=['friction', 'damping'])\n"
    "diagnosis",
    "print(diagnosis.summary())",
    "diagnosis.candidates_table()",
    "diagnosis.rounds_table()",
]


def _run_cells(cells: list[str], namespace: dict) -> list[tuple[str, str | None]]:
    """Each cell's display: (repr, HTML or None) of its last expression, or of what it printed."""
    import contextlib
    import io

    shown = []
    for n, source in enumerate(cells):
        tree = ast.parse(source)
        last = tree.body.pop() if tree.body and isinstance(tree.body[-1], ast.Expr) else None
        printed = io.StringIO()
        with contextlib.redirect_stdout(printed):
            exec(compile(tree, f"<cell {n}>", "exec"), namespace)
            value = eval(compile(ast.Expression(last.value), f"<cell {n}>", "eval"), namespace) if last else None
        if value is None:
            shown.append((printed.getvalue(), None))
        else:
            html = getattr(value, "_repr_html_", None)
            shown.append((repr(value), html() if callable(html) else None))
    return shown


class _Tags(HTMLParser):
    """The HTML's open tags must all close (a fragment a notebook can embed), and its text is collected."""

    VOID = {"br", "hr", "img", "meta", "input"}

    def __init__(self):
        super().__init__()
        self.stack, self.text = [], []

    def handle_starttag(self, tag, attrs):
        if tag not in self.VOID:
            self.stack.append(tag)

    def handle_endtag(self, tag):
        assert self.stack and self.stack[-1] == tag, f"</{tag}> closes <{self.stack[-1] if self.stack else None}>"
        self.stack.pop()

    def handle_data(self, data):
        self.text.append(data)


def _html_text(html: str) -> str:
    parser = _Tags()
    parser.feed(html)
    parser.close()
    assert not parser.stack, f"unclosed: {parser.stack}"
    return " ".join(parser.text)


@pytest.fixture(scope="module")
def notebook(tmp_path_factory):
    out = tmp_path_factory.mktemp("notebook")
    plant = chart("one_mass_friction_plant")
    train, val = record(plant, 2.0, 3, 0.02, **EXCITATION), record(plant, 1.0, 101, 0.02, **EXCITATION)

    namespace = {"out": out, "one_mass": chart("one_mass"), "train": train, "val": val}
    cwd = os.getcwd()
    os.chdir(ROOT)
    try:
        shown = _run_cells(CELLS, namespace)
    finally:
        os.chdir(cwd)
    return namespace, shown


def test_every_display_is_short(notebook):
    namespace, shown = notebook
    for value in (namespace["result"], namespace["back"], namespace["again"], namespace["diagnosis"]):
        text, html = value.summary(), value._repr_html_()
        assert len(text.encode()) < LIMIT and len(html.encode()) < LIMIT, (len(text), len(html))
        assert "\n" not in repr(value) and len(repr(value)) < 300
    for text, html in shown:  # no cell shows more than the limit (the old repr of a diagnosis: 1.5 MB)
        assert len(text.encode()) < LIMIT and (html is None or len(html.encode()) < LIMIT)


def test_the_summary_says_what_the_result_holds(notebook):
    namespace, shown = notebook
    result = namespace["result"]
    text = result.summary()
    j1 = result.parameters["J1"]
    # each figure as the result holds it, at the summary's precision: an independent formatting of the fields
    assert f"{j1.value:.5g}" in text and j1.unit in text and f"± {j1.stderr:.2g}" in text
    assert f"({100 * j1.stderr / abs(j1.value):.2g} %)" in text
    assert result.status in text and f"{result.fit.train.rms['w1']:.4g}" in text
    html = _html_text(result._repr_html_())
    assert f"{j1.value:.5g}" in html and "Parameters" in html and "Fit" in html
    assert shown[2][0] == text + "\n"  # print(result.summary()) in a cell


def test_the_diagnosis_shows_its_verdict(notebook):
    namespace, _ = notebook
    d = namespace["diagnosis"]
    assert d.accepted, "the plant's friction is missing from the chart"
    for view in (d.summary(), _html_text(d._repr_html_()), repr(d)):
        assert d.accepted[0].title in view
        assert f"{d.before.validation_rms:.4g}" in view and f"{d.after.validation_rms:.4g}" in view
    html = _html_text(d._repr_html_())
    assert "Rounds" in html and "Final chart" in html
    assert f"{d.identification.parameters['m'].value:.5g}" in html


def test_tables_are_data_frames_with_pandas(notebook):
    pd = pytest.importorskip("pandas")
    namespace, _ = notebook
    result, d = namespace["result"], namespace["diagnosis"]
    params = result.parameters_table()
    assert isinstance(params, pd.DataFrame)
    assert list(params["parameter"]) == list(result.parameters)
    assert params.set_index("parameter").loc["J1", "value"] == result.parameters["J1"].value
    cands = d.candidates_table()
    assert isinstance(cands, pd.DataFrame) and len(cands) == len(d.candidates)
    assert list(cands["refitted"]) == [c.refit is not None for c in d.candidates]
    assert len(d.rounds_table()) == len(d.rounds)


def test_tables_are_lists_of_dicts_without_pandas(notebook, monkeypatch):
    monkeypatch.setitem(sys.modules, "pandas", None)  # import pandas -> ImportError
    namespace, _ = notebook
    result, d = namespace["result"], namespace["diagnosis"]
    rows = result.parameters_table()
    assert isinstance(rows, list) and rows[0]["parameter"] == "J1"
    assert rows[0]["value"] == result.parameters["J1"].value
    assert [r["output"] for r in result.fit_table()] == list(result.fit.train.rms)
    assert [r["effect"] for r in d.candidates_table()] == [c.effect for c in d.candidates]


def test_a_comparison_shows_its_fit_and_its_table(notebook):
    namespace, shown = notebook
    rows = namespace["comparison"].table()
    assert "\n" not in shown[5][0] and len(shown[5][0]) < 300
    assert "50-step-ahead" in shown[5][0] and f"{rows[0]['fit_percent']:.4g} %" in shown[5][0]
    frame = namespace["comparison"].frame()
    if hasattr(frame, "columns"):  # pandas is installed
        assert list(frame["fit_percent"]) == [r["fit_percent"] for r in rows]
    else:
        assert frame == rows


def test_read_result_loads_the_chart_beside_it(notebook):
    namespace, shown = notebook
    back, result = namespace["back"], namespace["result"]
    assert back.chart is not None and back.values == result.values
    # the linearised identified chart, read back, is the one of the result in memory
    assert repr(result.linearize(at={"w1": 2.0}).damp()) == shown[SHOWN_DAMP][0]


def test_fix_from_an_identification_fixes_its_parameters(notebook):
    namespace, _ = notebook
    again, result = namespace["again"], namespace["result"]
    assert again.parameters["J1"].fixed and again.parameters["J1"].value == result.parameters["J1"].value
    assert again.settings.fixed_from == ("J1", "MR1")
    # the learned curve was taken too, and kept
    assert again.curves["MR1"].a == result.curves["MR1"].a and again.curves["MR1"].fixed


def test_help_shows_the_real_docstrings():
    text = pydoc.render_doc(sd.identify, renderer=pydoc.plaintext)
    assert "fix_from" in text and "Returns" in text and "IdentifySettings" in text
    assert "Returns" in pydoc.render_doc(sd.diagnose, renderer=pydoc.plaintext)
    assert len(pydoc.render_doc(sd.Identification.summary, renderer=pydoc.plaintext).splitlines()) > 3


def test_data_without_the_charts_output_name_the_columns():
    data = sd.read_csv(ROOT / "examples" / "data" / "engine_idle.csv").slice(0, 100)
    renamed = sd.dataset_from_frame({"time": data.time, "M1": data.columns["M1"], "w_1": data.columns["w1"]},
                                    time="time", name="bench.csv")
    with pytest.raises(sd.SdnnError) as info:
        sd.identify(ROOT / "diagrams" / "engine.yaml", renamed, max_iter=1)
    line = str(info.value)
    assert "CSV012" in line and "'w1' is missing" in line and "M1, w_1" in line and "bench.csv" in line
    assert "did you mean 'w_1'" in line and "\n" not in line


def test_a_data_frame_passed_as_a_record_says_how_to_make_one():
    pd = pytest.importorskip("pandas")
    frame = pd.DataFrame({"t": [0.0, 0.01, 0.02], "M1": [0.0, 1.0, 0.0], "w1": [0.0, 0.1, 0.2]})
    for call in (lambda: sd.identify(ROOT / "diagrams" / "engine.yaml", frame),
                 lambda: sd.diagnose(ROOT / "diagrams" / "engine.yaml", [frame])):
        with pytest.raises(sd.SdnnError) as info:
            call()
        line = str(info.value)
        assert "DataFrame is not a record" in line and "t, M1, w1" in line and "dataset_from_frame" in line


def test_diagnose_takes_one_validation_record_and_effects_by_name():
    with pytest.raises(sd.SdnnError) as info:
        sd.diagnose(ROOT / "diagrams" / "engine.yaml", [], sd.read_csv(ROOT / "examples" / "data" /
                                                                      "engine_idle.csv"), effects="friction,backlsh")
    assert "unknown effect 'backlsh'" in str(info.value) and "did you mean 'backlash'" in str(info.value)


def test_simulating_a_record_without_the_charts_input_names_the_columns(notebook):
    namespace, _ = notebook
    data = namespace["data"]
    renamed = sd.dataset_from_frame({"time": data.time, "M_1": data.columns["M1"], "w1": data.columns["w1"]},
                                    time="time", name="bench.csv")
    for call in (lambda: namespace["result"].simulate(renamed), lambda: namespace["result"].compare(renamed)):
        with pytest.raises(sd.SdnnError) as info:
            call()
        assert "M1" in str(info.value) and "columns: M_1, w1" in str(info.value) and "bench.csv" in str(info.value)
    with pytest.raises(sd.SdnnError, match="a dict is not a record"):
        namespace["result"].simulate(dict(data.columns))
