"""The user guide's Python API example (docs/guide/api.md, linked from the README) runs as written, and what it
prints is the identification's own answer."""

from __future__ import annotations

import contextlib
import io
import os
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


def _example() -> str:
    text = (ROOT / "docs" / "guide" / "api.md").read_text(encoding="utf-8")
    section = text[text.index("# Python API"):]
    return re.search(r"```python\n(.*?)```", section, re.S).group(1)


def test_the_readme_python_api_example_runs():
    pytest.importorskip("pandas")
    namespace: dict = {}
    out = io.StringIO()
    cwd = os.getcwd()
    os.chdir(ROOT)  # the example's paths are relative to the repository root, as the page says
    try:
        with contextlib.redirect_stdout(out):
            exec(compile(_example(), "docs/guide/api.md", "exec"), namespace)
    finally:
        os.chdir(cwd)
    result = namespace["result"]
    # what the example reads is what the CLI's RESULT.json says
    import json

    doc = json.loads(namespace["document"])
    assert doc["parameters"]["J1"]["value"] == result.parameters["J1"].value
    assert doc["parameters"]["J1"]["ci95"] == list(result.parameters["J1"].ci95)
    assert "J1 = " in out.getvalue() and "RMS on the first 5 s:" in out.getvalue()
    # the free run of the first 5 s is the training fit's own simulation over those samples
    full = result.simulate(namespace["data"])["w1"][:5000]
    assert (namespace["w1"] == full).all()
