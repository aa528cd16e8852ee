"""Fuzz the chart front end: generated and mutated charts through load, validate, lint, compile and identify.

Every case must end in a Diagram/Network or an SdnnError (a user error with a location); anything else is a
crash. ``python benchmarks/fuzz_charts.py [N] [--seed S]`` runs N cases (default 10000) and prints the number
of cases, the successes, the SdnnErrors by code and the crashes (must be 0). ``tests/test_chart_fuzz.py``
drives the same generator from hypothesis (``st.randoms()``), so a failure there shrinks to a small case.

The generator only uses the :class:`random.Random` API, so hypothesis can control and shrink every choice.
"""

from __future__ import annotations

import argparse
import copy
import math
import random
import sys
import tempfile
import time
import traceback
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

import yaml

from flowchart2sdnn.analysis.lint import lint_diagram
from flowchart2sdnn.compiler import compile_diagram
from flowchart2sdnn.diagram.blocks import CORE_KINDS
from flowchart2sdnn.diagram.model import FUNCTIONS
from flowchart2sdnn.diagram.validate import load_diagram
from flowchart2sdnn.errors import SdnnError
from flowchart2sdnn.network.model import Network

__all__ = ["valid_chart", "random_chart", "mutate", "render", "generate_case", "run_case", "Outcome", "main"]

KINDS = CORE_KINDS  # the generator below writes each kind's keys by hand; a lowered kind would shift the stream
BAD_KINDS = ("integrater", "Gain", "", "lookup", "sum ", "π")
NAMES = ("x", "y", "w1", "w2", "MB1", "acc", "dphi", "MC", "u", "M1", "J1", "c", "d", "pi", "data", "T", "_a",
         "ω", "名前", "a b", "1x", "x-y", "a.b", "", "sdnn", "__class__")
UNITS = ("N*m", "rad/s", "kg*m^2", "1", "s", "N*m*s/rad", "m/s^2", "rad", "V", "A", "Ohm", "furlong", "m/s*kg",
         "kg^(1/2)", "m^99999", "(", "N**2", "µm")
EXPR_TOKENS = ("+", "-", "*", "/", "^", "(", ")", "pi", "1", "2.5", "1e300", "0", "1e-320", ".", ",", "'",
               "__import__", "os", "[", "]", "**", "%", "J1", "c", "d", " ", "1e999", "x", "1/0")


def _name(r: random.Random, pool: list[str]) -> str:
    if pool and r.random() < 0.85:
        return r.choice(pool)
    return r.choice(NAMES) + (str(r.randint(0, 9)) if r.random() < 0.3 else "")


def _expr(r: random.Random, params: list[str]) -> object:
    roll = r.random()
    if roll < 0.25:
        return r.choice([1, 0.5, -2, 0, 1e300, 3])
    if roll < 0.75 and params:  # a well-formed expression of parameters
        terms = [r.choice(params + ["2", "pi", "0.5"]) for _ in range(r.randint(1, 3))]
        text = terms[0]
        for t in terms[1:]:
            text += r.choice(["*", "/", "+", "-", "^"]) + t
        return ("1/" + text) if r.random() < 0.3 else text
    return "".join(r.choice(EXPR_TOKENS + tuple(params)) for _ in range(r.randint(0, 12)))


def valid_chart(r: random.Random) -> dict:
    """A random chart that should compile: loops close only through integrators and delays, gains are
    products of positive parameters, nonlinear blocks read sums, integrators or inputs."""
    inputs = [f"u{i}" for i in range(r.randint(1, 2))]
    params = [f"p{i}" for i in range(r.randint(0, 4))]
    names = [f"b{i}" for i in range(r.randint(1, 12))]
    kinds = {n: r.choice(KINDS) for n in names}
    blocks: dict = {}
    for i, name in enumerate(names):
        kind = kinds[name]
        earlier = inputs + names[:i]
        # a reference to a later block closes a loop: only through an integrator or a delay, from a sum
        later = [n for n in names[i:] if kinds[n] in ("integrator", "delay")]
        spec: dict = {"type": kind}
        if kind == "sum":
            terms = [r.choice(earlier) for _ in range(r.randint(1, 3))]
            terms += [n for n in later if r.random() < 0.5]
            spec["in"] = [r.choice(["", "-", "+"]) + t for t in terms]
        elif kind == "product":  # factors from earlier blocks, none a learned curve (that needs a sum first)
            ok = inputs + [n for n in names[:i] if kinds[n] != "nonlinear"]
            spec["in"] = [r.choice(["", "-"]) + r.choice(ok) for _ in range(r.randint(2, 3))]
        elif kind == "nonlinear":
            ok = inputs + [n for n in names[:i] if kinds[n] in ("sum", "integrator")]
            spec["in"] = r.choice(ok)
            n = r.randint(1, 4)
            spec["neurons"] = n
            if r.random() < 0.3:
                spec["bias"] = True
            if r.random() < 0.5:
                spec["weights"] = {"a": [r.uniform(-2, 2) for _ in range(n)], "v": [r.uniform(-2, 2) for _ in range(n)]}
                if spec.get("bias"):
                    spec["weights"]["b"] = [r.uniform(-1, 1) for _ in range(n)]
        elif kind != "constant":
            spec["in"] = r.choice(["", "-"]) + r.choice(earlier)
        if kind in ("gain", "constant") or (kind == "function" and r.random() < 0.5):
            factors = [r.choice(params + ["2", "0.5", "pi", "3"]) for _ in range(r.randint(1, 3))]
            text = factors[0]
            for f in factors[1:]:
                text += r.choice(["*", "/", "+"]) + f
            spec["k"] = ("-" if r.random() < 0.2 else "") + text if r.random() < 0.8 else r.uniform(-3, 3)
        if kind == "function":
            spec["f"] = r.choice(FUNCTIONS)
            if spec["f"] == "sign_smooth" and r.random() < 0.5:
                spec["eps"] = r.choice([1e-3, 0.01, 0.1])
        if kind == "integrator" and r.random() < 0.3:
            spec["init"] = r.uniform(-2, 2)
        if kind == "delay" and r.random() < 0.5:
            spec["n"] = r.randint(1, 4)
        blocks[name] = spec
    chosen = r.sample(names, r.randint(1, min(3, len(names))))
    for name in chosen:
        if kinds[name] == "integrator" and r.random() < 0.3:
            blocks[name]["init"] = "data"
    parameters = {}
    for p in params:
        init = r.choice([0.1, 1.0, 2.5, 477.0, 0.24])
        spec = {"init": init, "min": 0} if r.random() < 0.5 else {"init": init}
        if r.random() < 0.3:
            spec["max"] = init * 10
        if r.random() < 0.3:
            spec["fixed"] = True
        parameters[p] = spec
    return {"sdnn": 1, "name": "fuzz", "sample_time": r.choice([0.001, 0.01, 1e-4]),
            "inputs": {i: {} for i in inputs}, "outputs": {n: {} for n in chosen}, "parameters": parameters,
            "blocks": blocks}


def random_chart(r: random.Random) -> dict:
    """A random chart in the version-1 format: loops, gains, friction, units, often with mistakes."""
    inputs = [f"u{i}" for i in range(r.choice([0, 1, 1, 1, 2, 3]))]
    params = [f"p{i}" for i in range(r.randint(0, 4))]
    n_blocks = r.randint(1, 10)
    names = [f"b{i}" for i in range(n_blocks)]
    signals = inputs + names
    blocks: dict = {}
    for name in names:
        kind = r.choice(KINDS)
        spec: dict = {"type": kind}
        if kind == "sum":
            spec["in"] = [r.choice(["", "-", "+"]) + _name(r, signals) for _ in range(r.randint(1, 3))]
        elif kind != "constant":
            spec["in"] = _name(r, signals)
        if kind == "product":
            spec["in"] = [r.choice(["", "-"]) + _name(r, signals) for _ in range(r.randint(1, 3))]
        if kind in ("gain", "constant") or (kind in ("function", "product") and r.random() < 0.5):
            spec["k"] = _expr(r, params)
        if kind == "function":
            spec["f"] = r.choice(FUNCTIONS)
            if spec["f"] == "sign_smooth" and r.random() < 0.5:
                spec["eps"] = r.choice([1e-3, 0.01, 0.1])
        if kind == "integrator" and r.random() < 0.3:
            spec["init"] = r.choice([0.0, 1.5, -2, "data"])
        if kind == "delay" and r.random() < 0.5:
            spec["n"] = r.randint(1, 4)
        if kind == "nonlinear":
            n = r.randint(1, 4)
            spec["neurons"] = n
            if r.random() < 0.3:
                spec["bias"] = True
            if r.random() < 0.4:
                spec["weights"] = {"a": [r.uniform(-2, 2) for _ in range(n)],
                                   "v": [r.uniform(-2, 2) for _ in range(n)]}
                if spec.get("bias"):
                    spec["weights"]["b"] = [r.uniform(-1, 1) for _ in range(n)]
        if r.random() < 0.2:
            spec["unit"] = r.choice(UNITS)
        blocks[name] = spec
    outputs = {n: ({"unit": r.choice(UNITS)} if r.random() < 0.2 else {})
               for n in r.sample(names, r.randint(1, min(2, len(names))))}
    parameters = {}
    for p in params:
        spec = {"init": r.choice([0.1, 1.0, 2.5, 477.0, 0.0, -1.0])}
        if r.random() < 0.4:
            spec["min"] = r.choice([0, -1, 1])
        if r.random() < 0.2:
            spec["max"] = r.choice([10, 0.5, 1000])
        if r.random() < 0.2:
            spec["fixed"] = True
        if r.random() < 0.2:
            spec["unit"] = r.choice(UNITS)
        parameters[p] = spec
    return {"sdnn": 1, "name": "fuzz", "sample_time": r.choice([0.001, 0.01, 1e-4]),
            "inputs": {i: {} for i in inputs}, "outputs": outputs, "parameters": parameters, "blocks": blocks}


def _weird_value(r: random.Random) -> object:
    roll = r.randrange(16)
    if roll == 0:
        return 10 ** r.randint(20, 400)
    if roll == 1:
        return r.choice([math.nan, math.inf, -math.inf])
    if roll == 2:
        return r.choice(["", "ω", "名前", "\u202e", "x" * r.randint(50, 2000), "-", "+x", "- x", "data"])
    if roll == 3:
        return None
    if roll == 4:
        return r.choice([True, False])
    if roll == 5:
        return [_weird_value(r) for _ in range(r.randint(0, 3))]
    if roll == 6:
        return {r.choice(NAMES): _weird_value(r) for _ in range(r.randint(0, 3))}
    if roll == 7:
        value: object = 1
        for _ in range(r.randint(2, 90)):
            value = [value]
        return value
    if roll == 8:
        return r.choice(KINDS + BAD_KINDS)
    if roll == 9:
        return r.choice([-1, 0, 1, 2, 3, 101, 100_001, -0.0, 0.5, 1e-320, 1e308, -1e308])
    if roll == 10:
        return r.choice(NAMES)
    if roll == 11:
        return r.choice(UNITS)
    if roll == 12:
        return "".join(r.choice(EXPR_TOKENS) for _ in range(r.randint(1, 30)))
    if roll == 13:
        return "(" * r.randint(40, 600) + "1" + ")" * r.randint(0, 600)
    if roll == 14:
        return "2" + "^2" * r.randint(2, 400)
    return r.uniform(-1e6, 1e6)


def _paths(node, prefix=()):
    yield prefix
    if isinstance(node, dict):
        for k, v in node.items():
            yield from _paths(v, prefix + (k,))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from _paths(v, prefix + (i,))


def _get(node, path):
    for p in path:
        node = node[p]
    return node


def mutate(r: random.Random, doc: dict) -> object:
    """Apply 1-4 structural mutations: wrong types, unknown kinds, missing/extra keys, bad references."""
    doc = copy.deepcopy(doc)
    for _ in range(r.randint(1, 4)):
        paths = [p for p in _paths(doc) if p]
        if not paths:
            return _weird_value(r)
        path = r.choice(paths)
        parent = _get(doc, path[:-1])
        key = path[-1]
        op = r.randrange(7)
        if op == 0:  # wrong type / weird value
            parent[key] = _weird_value(r)
        elif op == 1:  # missing key
            if isinstance(parent, dict):
                del parent[key]
            else:
                parent.pop(key)
        elif op == 2 and isinstance(parent, dict):  # extra (unknown) key
            parent[r.choice(NAMES + ("typ", "inn", "x-note", "weights", "k"))] = _weird_value(r)
        elif op == 3:  # dangling or cyclic reference
            blocks = doc.get("blocks") if isinstance(doc, dict) else None
            names = list(blocks) if isinstance(blocks, dict) else []
            parent[key] = r.choice(["-", "", "+"]) + _name(r, names)
        elif op == 4:  # unknown or different kind
            blocks = doc.get("blocks") if isinstance(doc, dict) else None
            if isinstance(blocks, dict) and blocks:
                spec = blocks[r.choice(list(blocks))]
                if isinstance(spec, dict):
                    spec["type"] = r.choice(KINDS + BAD_KINDS)
        elif op == 5 and isinstance(parent, dict):  # rename a key (a block, a parameter, a field)
            value = parent.pop(key)
            parent[_name(r, [str(k) for k in parent] + list(NAMES))] = value
        elif op == 6:  # swap in a subtree from elsewhere
            parent[key] = copy.deepcopy(_get(doc, r.choice(paths)))
    return doc


def render(r: random.Random, doc: object) -> bytes:
    """YAML text of `doc`, sometimes damaged at the text level (duplicate keys, truncation, bytes, bombs)."""
    try:
        text = yaml.safe_dump(doc, sort_keys=False, allow_unicode=r.random() < 0.5,
                              default_flow_style=r.choice([None, False, True]))
    except (RecursionError, yaml.YAMLError):
        text = "sdnn: 1\n"
    roll = r.randrange(14)
    lines = text.splitlines(keepends=True)
    if roll == 0 and lines:  # duplicate a line: duplicate keys
        i = r.randrange(len(lines))
        lines.insert(i, lines[i])
    elif roll == 1 and text:  # truncate
        text = text[: r.randrange(len(text))]
        lines = [text]
    elif roll == 2 and text:  # insert a random character
        i = r.randrange(len(text))
        text = text[:i] + r.choice(["\x00", "\x07", "\t", ":", "[", "{", "&a ", "*a", "!!python/object ",
                                    "'", '"', "\ufeff", "\r", "\u2028", "- ", "? ", "|", ">", "%"]) + text[i:]
        lines = [text]
    elif roll == 3:  # alias bomb
        lines.append("x-bomb:\n  a: &a [1, 1, 1, 1, 1, 1, 1, 1, 1, 1]\n")
        prev = "a"
        for name in "bcdefgh":
            lines.append(f"  {name}: &{name} [" + ", ".join([f"*{prev}"] * 10) + "]\n")
            prev = name
    elif roll == 4:  # deep flow nesting
        depth = r.randint(50, 3000)
        lines.append("x-deep: " + "[" * depth + "]" * depth + "\n")
    elif roll == 5:
        lines = [r.choice(["", "   \n", "# only a comment\n", "---\n", "...\n", "~\n", "[]\n", "42\n",
                           "sdnn: 1\n---\nsdnn: 1\n", "!!binary aGVsbG8=\n", "? [a, b]\n: 1\n", "<<: {a: 1}\n"])]
    elif roll == 6:
        data = text.encode("utf-8")
        return data[: r.randrange(len(data) + 1)] + bytes(r.getrandbits(8) for _ in range(r.randint(1, 20)))
    elif roll == 7:
        return r.choice([b"\xff\xfe\x00s\x00d", b"\xe9t\xe9: 1\n", b"\x89PNG\r\n\x1a\n", "ü: 1\n".encode("latin-1")])
    return "".join(lines).encode("utf-8")


def generate_case(r: random.Random) -> bytes:
    """One fuzz case: a random chart, usually mutated, rendered to (possibly damaged) bytes."""
    roll = r.random()
    doc: object = valid_chart(r) if roll < 0.7 else random_chart(r)
    if roll < 0.35:  # a chart that should compile, rendered cleanly: exercises lint, loops, discretize, emit
        return yaml.safe_dump(doc, sort_keys=False).encode("utf-8")
    if r.random() < 0.8:
        doc = mutate(r, doc)
    return render(r, doc)


@dataclass(frozen=True)
class Outcome:
    """What one case did: 'ok', 'error' (an SdnnError with `code`), or 'crash' (with the traceback)."""

    status: str
    code: str | None = None
    detail: str | None = None


def identify_case(diagram, network, path: Path) -> None:
    """Identify a compiled chart on a small seeded random record (2 LM iterations): it must end in a result
    whose JSON is strict (no NaN) or in an SdnnError, whatever the chart."""
    import json

    import numpy as np

    from flowchart2sdnn.data.csvdata import read_csv, write_csv
    from flowchart2sdnn.identify.offline.problem import required_columns
    from flowchart2sdnn.identify.offline.run import IdentifySettings, identify

    rng = np.random.default_rng(len(network.weights))
    cols = required_columns(diagram)
    n = 40
    columns = {"time": np.arange(n) * diagram.sample_time}
    columns.update({c: rng.normal(size=n) for c in cols})
    data_path = path.with_suffix(".csv")
    write_csv(data_path, columns)
    ds = read_csv(data_path, cols, None, diagram.sample_time)
    outcome = identify(diagram, ds, None, IdentifySettings(max_iter=2))
    json.dumps(outcome.result, allow_nan=False)


def run_case(data: bytes, path: Path, with_identify: bool = True) -> Outcome:
    """Write `data` to `path`, then load, lint, compile, serialize and identify; classify what happened."""
    path.write_bytes(data)
    try:
        diagram = load_diagram(path)
        lint_diagram(diagram)
        net = compile_diagram(diagram).network
        if Network.from_json(net.to_json()) != net:
            return Outcome("crash", detail="network file does not load back to the same network")
        if with_identify:
            try:
                identify_case(diagram, net, path)
            except SdnnError as exc:
                return Outcome("error", "identify:" + exc.diagnostics[0].code)
    except SdnnError as exc:
        d = exc.diagnostics[0]
        if d.location is None or d.location.file != str(path) or d.location.line is None:
            return Outcome("crash", d.code, f"error without the file name and line: {exc}")
        if "\n" in str(exc) or len(str(exc)) > 2000:
            return Outcome("crash", d.code, f"error message is not one short line: {str(exc)[:300]!r}")
        return Outcome("error", d.code)
    except Exception:  # noqa: BLE001 - the point: any other exception is a crash to report
        return Outcome("crash", detail=traceback.format_exc())
    return Outcome("ok")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("n", nargs="?", type=int, default=10_000, help="number of cases")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    r = random.Random(args.seed)
    codes: Counter = Counter()
    crashes: list[tuple[int, bytes, Outcome]] = []
    ok = 0
    t0 = time.perf_counter()
    slowest = 0.0
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "case.yaml"
        for i in range(args.n):
            data = generate_case(r)
            c0 = time.perf_counter()
            out = run_case(data, path)
            slowest = max(slowest, time.perf_counter() - c0)
            if out.status == "ok":
                ok += 1
            elif out.status == "error":
                codes[out.code] += 1
            else:
                crashes.append((i, data, out))
    print(f"cases: {args.n} (seed {args.seed}) in {time.perf_counter() - t0:.1f} s, slowest {slowest * 1e3:.0f} ms")
    print(f"compiled: {ok}")
    print(f"SdnnErrors: {sum(codes.values())}")
    for code, count in sorted(codes.items()):
        print(f"  {code}: {count}")
    print(f"crashes: {len(crashes)}")
    sites: dict[str, tuple[int, bytes, Outcome]] = {}
    for i, data, out in crashes:  # one example per place that raised
        tail = (out.detail or "").strip().splitlines()
        sites.setdefault(" | ".join(tail[-3:]), (i, data, out))
    for i, data, out in sites.values():
        print(f"--- case {i}: {data[:400]!r}\n{out.detail}")
    return 1 if crashes else 0


if __name__ == "__main__":
    sys.exit(main())
