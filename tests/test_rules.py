"""The rule book (flowchart2sdnn/rules.py): every threshold of fit/, identify/ and diagnose/ has its default in
one place, a principle and a place where it acts; the code and the command line read it from there; the
generated page docs/guide/rules.md matches it."""

from __future__ import annotations

import ast
import dataclasses
import importlib
import itertools
import re
from pathlib import Path

import pytest

from flowchart2sdnn.rules import RULES, rule, value

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = ROOT / "flowchart2sdnn"
SCANNED = ("fit", "identify", "diagnose")

#: Module-level numbers that are not thresholds: format versions of the documents (a contract, not a choice),
#: status codes, slot numbers of the quasi-online kernel's state arrays, and sizes of caches and slices that
#: change memory and speed, never a result.
_SLOTS = ("F_MU F_EE F_CC F_CH F_NL I_COUNT I_HEAD I_STEPS I_BLOCK_POS I_ACCEPTED I_REJECTED I_DIVERGED "
          "I_CHOL_FALLBACK I_SKIPPED I_RESYNC I_N_DIV_T I_NEXT I_SINCE_RESYNC N_FS N_ITS").split()
ALLOWED = {*(("identify/online/window.py", name) for name in _SLOTS),
    ("identify/serialize.py", "RESULT_VERSION"), ("diagnose/serialize.py", "REPORT_VERSION"),
    ("diagnose/usereffects.py", "EFFECTS_FORMAT"),
    ("identify/online/kernel.py", "STATUS_OK"), ("identify/online/kernel.py", "STATUS_DIVERGED_BEFORE_START"),
    ("identify/online/run.py", "_SLICE"), ("identify/offline/workers.py", "_CACHE_SIZE"),
}
#: Settings fields whose numeric default is a count or a switch, not a threshold.
ALLOWED_FIELDS = {"seed", "starts", "every", "online_start", "threads", "init_window"}
SETTINGS = {("fit/lm.py", "LMOptions"), ("identify/settings.py", "IdentifySettings"),
            ("diagnose/fitting.py", "DiagnoseSettings")}


def _numbers(node: ast.AST) -> list:
    return [c.value for c in ast.walk(node) if isinstance(c, ast.Constant)
            and isinstance(c.value, (int, float)) and not isinstance(c.value, bool)]


def _assigned(body):
    for n in body:
        if isinstance(n, ast.Assign) and n.value is not None:
            for t in n.targets:
                for name in ast.walk(t):
                    if isinstance(name, ast.Name):
                        yield n.lineno, name.id, n.value
        elif isinstance(n, ast.AnnAssign) and isinstance(n.target, ast.Name) and n.value is not None:
            yield n.lineno, n.target.id, n.value


def test_every_rule_says_why_and_where():
    for r in RULES.values():
        assert r.principle.strip() and r.unit.strip() and r.where, r.name
        assert all(w.strip() for w in r.where), r.name
    with pytest.raises(KeyError, match="no rule 'nonesuch'"):
        rule("nonesuch")


def _resolve(where: str):
    """The object a `where` names ("identify.assess.floor.FLOOR_WARN", "fit.lm.LMOptions.max_iter"): a module
    attribute, or a dataclass field's default (returned as a dataclasses.Field)."""
    parts = where.split(" ")[0].split(".")
    for cut in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module("flowchart2sdnn." + ".".join(parts[:cut]))
        except ModuleNotFoundError:
            continue
        for name in parts[cut:]:
            if dataclasses.is_dataclass(obj) and name in {f.name for f in dataclasses.fields(obj)}:
                return next(f for f in dataclasses.fields(obj) if f.name == name)
            obj = getattr(obj, name)
        return obj
    raise AssertionError(f"{where}: no such module")


def test_each_place_holds_its_rules_value():
    """The places read the book: every module constant and settings default a rule names is that rule's value,
    of the same type (the defaults stay bit-identical)."""
    for r in RULES.values():
        for where in r.where:
            got = _resolve(where)
            if isinstance(got, dataclasses.Field):
                got = got.default
            elif callable(got) or isinstance(got, type(importlib)) or " " in where:
                continue  # a function, a module or a described use: its existence is what is checked
            if where == "identify.offline.initstate._OPTIONS":
                continue  # an LMOptions whose fields test_initstate_options checks
            assert type(got) is type(r.value) and got == r.value, (r.name, where, got)


def test_initstate_options():
    from flowchart2sdnn.identify.offline import initstate

    o = initstate._OPTIONS
    assert (o.max_iter, o.tau, o.min_rel_cost_change) == (value("initstate_max_iter"), value("initstate_tau"),
                                                         value("initstate_min_rel_cost_change"))


def test_no_threshold_outside_the_book():
    """No module of fit/, identify/ or diagnose/ writes a number into a module-level name or a settings
    default: it reads the rule book (allow-list: ALLOWED, ALLOWED_FIELDS)."""
    found = []
    for pkg in SCANNED:
        for path in sorted((PACKAGE / pkg).rglob("*.py")):
            rel = path.relative_to(PACKAGE).as_posix()
            tree = ast.parse(path.read_text(encoding="utf-8"))
            found += [f"{rel}:{line} {name}" for line, name, v in _assigned(tree.body)
                      if _numbers(v) and (rel, name) not in ALLOWED]
            for cls in (n for n in tree.body if isinstance(n, ast.ClassDef) and (rel, n.name) in SETTINGS):
                found += [f"{rel}:{line} {cls.name}.{name}" for line, name, v in _assigned(cls.body)
                          if _numbers(v) and name not in ALLOWED_FIELDS]
    assert not found, "read these from flowchart2sdnn.rules: " + ", ".join(found)


def test_the_scan_sees_a_literal(tmp_path):
    """The scan above can fail: a written-in threshold is found (module level and in a settings class)."""
    tree = ast.parse("X = 0.5\nY = rules.value('x')\nclass LMOptions:\n    a: float = 1e-3\n    seed: int = 0\n")
    module = [name for _, name, v in _assigned(tree.body) if _numbers(v)]
    fields = [name for _, name, v in _assigned(tree.body[2].body) if _numbers(v) and name not in ALLOWED_FIELDS]
    assert module == ["X"] and fields == ["a"]


def test_equal_values_are_tied_or_called_coincidence():
    """Two rules with the same value either are one rule or one of them says the other is a coincidence
    (0 and infinity, the generic trainer's "off", aside)."""
    missing = []
    for a, b in itertools.combinations(RULES.values(), 2):
        if type(a.value) is type(b.value) and a.value == b.value and a.value not in (0, float("inf")):
            if b.name not in a.note and a.name not in b.note:
                missing.append(f"{a.name}={b.name}={a.value!r}")
    assert not missing, "tie these or say 'equal to ... by coincidence': " + ", ".join(missing)


def _command(name):
    from flowchart2sdnn.cli.main import main

    return main.get_command(None, name)


def test_the_command_line_shows_the_books_defaults():
    for r in RULES.values():
        for flag in r.flags:
            command, option = flag.split(" ")
            params = [p for p in _command(command).params if option in p.opts or option in p.secondary_opts]
            assert len(params) == 1, flag
            p = params[0]
            if isinstance(p.default, (int, float)) and not isinstance(p.default, bool):
                assert type(p.default) is type(r.value) and p.default == r.value, (flag, p.default)
            else:  # a switch, a word or an unset option, whose help quotes the number as a number of its own
                assert re.search(rf"(?<![\d.]){re.escape(f'{r.value:g}')}(?![\d.])", p.help), (flag, p.help)


def test_the_page_is_the_book():
    from flowchart2sdnn.report.rules_table import rules_markdown

    page = (ROOT / "docs" / "guide" / "rules.md").read_text(encoding="utf-8")
    assert page == rules_markdown(), ("docs/guide/rules.md is out of step with flowchart2sdnn/rules.py; "
                                      "rewrite it as flowchart2sdnn/report/rules_table.py says")
    assert all(f"`{name}`" in page for name in RULES)
