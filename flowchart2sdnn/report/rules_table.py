"""The rule book (:mod:`flowchart2sdnn.rules`) as the Markdown page docs/guide/rules.md.

tests/test_rules.py checks the page against :func:`rules_markdown`; after changing a rule, rewrite it with
``python -c "from flowchart2sdnn.report.rules_table import rules_markdown as m; print(m(), end='')" >
docs/guide/rules.md``.
"""

from __future__ import annotations

from ..rules import RULES

__all__ = ["rules_markdown"]

_HEAD = """# The rule book

Every numeric threshold of `fit/`, `identify/` and `diagnose/`: its default, the principle it stands for, where
it acts and the command-line flag that shows it. The one place a default lives is `flowchart2sdnn/rules.py`;
the modules read it from there (`FLOOR_WARN = rules.value("floor_warn")`). Values equal by coincidence say so
in the last column; one rule that acts in several places lists them all. Measurements behind a value are in
the comment beside the name that reads it.

This page is generated from `flowchart2sdnn/rules.py` (see `flowchart2sdnn/report/rules_table.py`); do not
edit it by hand.

| rule | default | unit | principle | where | flags | note |
|---|---|---|---|---|---|---|
"""


def _cell(text: str) -> str:
    return text.replace("|", "\\|")


def _value(v) -> str:
    if isinstance(v, tuple):
        return "(" + ", ".join(_value(x) for x in v) + ")"
    return f"{v!r}" if isinstance(v, int) else f"{v:g}"


def rules_markdown() -> str:
    """The table of every rule, one row each in the book's order."""
    rows = [f"| `{r.name}` | {_value(r.value)} | {_cell(r.unit)} | {_cell(r.principle)} | "
            f"{'<br>'.join(f'`{w}`' for w in r.where)} | {'<br>'.join(f'`{f}`' for f in r.flags)} | "
            f"{_cell(r.note)} |" for r in RULES.values()]
    return _HEAD + "\n".join(rows) + "\n"
