"""Validate a parsed chart (format version 1) and build the :class:`Diagram` IR.

Every problem becomes a :class:`Diagnostic` with the file, the line and the block; all of them are collected
before failing, so `sdnn lint` can show everything at once. Only structure is checked here (types, kinds,
names, references); the semantic checks (loops, units, identifiability) live in `analysis.lint`.
"""

from __future__ import annotations

import hashlib
import math
import re
from collections.abc import Mapping
from pathlib import Path

from ..errors import Diagnostic, Location, SdnnError, did_you_mean
from ..expr import ExprError, parse_expr
from .blocks import block_type, block_types
from .curves import BASES, BASIS_FUNCTIONS, DEFAULT_BASIS
from .initestimate import ESTIMATE, expand_estimated_inits
from .model import (
    DELAY_RULES,
    FORMAT_VERSION,
    FUNCTIONS,
    INTERSAMPLE,
    MAX_SUBSTEPS,
    RESERVED,
    Block,
    Diagram,
    NonlinearWeights,
    Parameter,
    Signal,
    Term,
)
from .yamlload import LocatedYaml, load_yaml, parse_yaml_text

__all__ = ["load_diagram", "diagram_from_text", "diagram_from_yaml", "TOP_KEYS"]

NAME_RE = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
_YAML11_BOOLS = {"yes": True, "on": True, "no": False, "off": False}
MAX_NEURONS = 100
MAX_DELAY = 100_000

TOP_KEYS = ("sdnn", "name", "description", "sample_time", "substeps", "delays", "inputs", "outputs", "parameters",
            "blocks", "identified")
SIGNAL_KEYS = ("unit", "description")
INPUT_KEYS = (*SIGNAL_KEYS, "intersample", "delay")
PARAM_KEYS = ("init", "unit", "min", "max", "fixed", "description", "per_record")
COMMON_BLOCK_KEYS = ("type", "unit", "description")


def load_diagram(path: str | Path) -> Diagram:
    """Read, parse and validate a chart file. Raises SdnnError listing every structural problem."""
    doc = load_yaml(path)
    return diagram_from_yaml(doc, doc.sha256)


def diagram_from_text(text: str, name: str = "<chart>") -> Diagram:
    doc = parse_yaml_text(text, name)
    return diagram_from_yaml(doc, hashlib.sha256(text.encode()).hexdigest())


def diagram_from_yaml(doc: LocatedYaml, sha256: str | None = None) -> Diagram:
    v = _Validator(doc)
    diagram = v.run(sha256)
    errors = [d for d in v.diagnostics if d.severity == "error"]
    if errors or diagram is None:
        raise SdnnError(errors or [Diagnostic("CHART000", "error", "invalid chart", Location(doc.file))])
    return diagram


def _is_number(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool)


def _finite_number(x) -> bool:
    """A number that is a finite float; a YAML integer of 400 digits is not (math.isfinite would raise)."""
    if not _is_number(x):
        return False
    try:
        return math.isfinite(x)
    except OverflowError:
        return False


def _show(value, quote: bool = True, limit: int = 40) -> str:
    """A short printable form of a user value for a message (repr of a huge int raises, a list may be huge)."""
    if isinstance(value, int) and not isinstance(value, bool) and value.bit_length() > 128:
        return f"an integer of {value.bit_length()} bits"
    text = repr(value) if quote else str(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


class _Validator:
    def __init__(self, doc: LocatedYaml):
        self.doc = doc
        self.diagnostics: list[Diagnostic] = []
        self.broken_blocks: set[str] = set()  # blocks that exist but failed to validate
        self._known: tuple[list[str] | None, frozenset[str]] = (None, frozenset())

    # -- reporting ---------------------------------------------------------------------------------
    def error(self, code: str, message: str, path: tuple = (), block: str | None = None, hint=None) -> None:
        loc = Location(self.doc.file, self.doc.line(*path), self.doc.column(*path))
        self.diagnostics.append(Diagnostic(code, "error", message, loc, block, hint))

    def loc(self, *path) -> Location:
        return Location(self.doc.file, self.doc.line(*path), self.doc.column(*path))

    def unknown_keys(self, mapping: Mapping, allowed, path: tuple, what: str, block=None) -> None:
        for key in mapping:
            if key not in allowed and not str(key).startswith("x-"):
                self.error(
                    "CHART003",
                    f"unknown key '{key}' in {what}; expected one of: {', '.join(allowed)}",
                    path + (key,),
                    block,
                    did_you_mean(key, allowed),
                )

    # -- top level ---------------------------------------------------------------------------------
    def run(self, sha256: str | None) -> Diagram | None:
        data = self.doc.data
        if not isinstance(data, dict):
            self.error("CHART001", f"a chart is a mapping of keys (sdnn, name, blocks, ...), found {_kind(data)}")
            return None
        self.unknown_keys(data, TOP_KEYS, (), "the chart")
        version = data.get("sdnn")
        if "sdnn" not in data:
            self.error("CHART002", "missing 'sdnn: 1' (the chart format version)", (), hint="add 'sdnn: 1' on top")
        elif version != FORMAT_VERSION or isinstance(version, bool):
            self.error("CHART002", f"unsupported format version {_show(version)}; this sdnn reads version 1", ("sdnn",))
        name = data.get("name")
        if not isinstance(name, str) or not name.strip():
            self.error("CHART002", f"'name' must be a non-empty string, found {_kind(name)}", ("name",))
            name = "chart"
        description = data.get("description")
        if description is not None and not isinstance(description, str):
            self.error("CHART004", "'description' must be a string", ("description",))
            description = None
        ts = data.get("sample_time")
        if "sample_time" not in data:
            self.error("CHART002", "missing 'sample_time' (seconds, e.g. 0.001)", ())
            ts = 1.0
        elif not _is_number(ts) or not _finite_number(ts) or ts <= 0 or ts > 1e6:
            self.error("CHART004", f"'sample_time' must be a positive number of seconds, found {_show(ts)}", ("sample_time",))
            ts = 1.0
        substeps = self.substeps(data)
        delays = data.get("delays")
        if "delays" in data and delays not in DELAY_RULES:
            self.error("CHART004", f"'delays' must be one of {', '.join(DELAY_RULES)}, found {_show(delays)}",
                       ("delays",), hint="torques: delay every torque where it enters a speed sum")
            delays = None
        inputs = self.signals(data.get("inputs"), "inputs")
        outputs = self.signals(data.get("outputs"), "outputs")
        parameters = self.parameters(data.get("parameters"))
        pnames = [p.name for p in parameters]
        blocks = self.blocks(data.get("blocks"), pnames)
        if "blocks" not in data:
            self.error("CHART002", "missing 'blocks' (the chart's blocks)", ())
        if "inputs" not in data:
            self.error("CHART002", "missing 'inputs' (the measured excitation signals)", ())
        if "outputs" not in data:
            self.error("CHART002", "missing 'outputs' (the measured signals to fit)", ())
        self.param_names = pnames
        self.references(inputs, outputs, blocks)
        if any(d.severity == "error" for d in self.diagnostics):
            return None
        return expand_estimated_inits(Diagram(
            name=name.strip(),
            description=description,
            sample_time=float(ts),
            substeps=substeps,
            delays=delays,
            inputs=tuple(inputs),
            outputs=tuple(outputs),
            parameters=tuple(parameters),
            blocks=tuple(blocks),
            file=self.doc.file,
            source_sha256=sha256,
            extra={"identified": data.get("identified")} if "identified" in data else {},
        ))

    def substeps(self, data: Mapping) -> int | str | None:
        """`substeps`: a whole number of network steps per sample (1 to MAX_SUBSTEPS) or `auto`."""
        if "substeps" not in data:
            return None
        value = data["substeps"]
        if value == "auto" or (isinstance(value, int) and not isinstance(value, bool) and 1 <= value <= MAX_SUBSTEPS):
            return value
        self.error("CHART004", f"'substeps' must be a whole number from 1 to {MAX_SUBSTEPS} or 'auto', found "
                   f"{_show(value)}", ("substeps",), hint="network steps per sample: 1 is the paper's network")
        return None

    def check_name(self, name, path: tuple, what: str) -> bool:
        if not isinstance(name, str) or not NAME_RE.match(name):
            self.error(
                "CHART005",
                f"{what} name {_show(name)} is not a valid name (letters, digits, '_', not starting with a digit)",
                path,
            )
            return False
        if name in RESERVED:
            self.error("CHART005", f"{what} name '{name}' is reserved", path)
            return False
        return True

    def signals(self, section, key: str) -> list[Signal]:
        if section is None:
            return []
        if not isinstance(section, dict):
            self.error("CHART004", f"'{key}' must be a mapping of signal names, found {_kind(section)}", (key,))
            return []
        out = []
        for name, spec in section.items():
            path = (key, name)
            if not self.check_name(name, path, "signal"):
                continue
            if spec is None:
                spec = {}
            if not isinstance(spec, dict):
                self.error("CHART004", f"signal '{name}' must be a mapping like {{unit: N*m}}, found {_kind(spec)}", path)
                continue
            self.unknown_keys(spec, INPUT_KEYS if key == "inputs" else SIGNAL_KEYS, path, f"signal '{name}'")
            unit = self.optional_str(spec, "unit", path)
            desc = self.optional_str(spec, "description", path)
            intersample, delay = self.input_timing(spec, path) if key == "inputs" else ("hold", None)
            out.append(Signal(name, unit, desc, self.loc(*path), intersample, delay))
        return out

    def input_timing(self, spec: Mapping, path: tuple) -> tuple[str, str | None]:
        """An input's `intersample` (hold | linear) and `delay` (seconds: a parameter name or a number); the
        name is checked against the parameters in :meth:`references`."""
        intersample = spec.get("intersample", "hold")
        if intersample not in INTERSAMPLE:
            self.error("CHART004", f"'intersample' must be one of {', '.join(INTERSAMPLE)}, found {_show(intersample)}",
                       path + ("intersample",), hint="hold: each sample acts until the next (a drive's torque "
                       "command); linear: straight between the samples (a smooth measured signal)")
            intersample = "hold"
        delay = spec.get("delay")
        if delay is None:
            return intersample, None
        if _is_number(delay) and _finite_number(delay):
            return intersample, repr(float(delay))
        if isinstance(delay, str) and NAME_RE.match(delay.strip()):
            return intersample, delay.strip()
        self.error("CHART004", f"'delay' must be a dead time in seconds: a parameter name or a number, found "
                   f"{_show(delay)}", path + ("delay",), hint="e.g. delay: tau, with tau a parameter (unit s)")
        return intersample, None

    def optional_str(self, spec: Mapping, key: str, path: tuple, block=None) -> str | None:
        value = spec.get(key)
        if value is None:
            return None
        if _is_number(value) and key == "unit":
            return str(value)
        if not isinstance(value, str):
            self.error("CHART004", f"'{key}' must be a string, found {_kind(value)}", path + (key,), block)
            return None
        return value

    def number(self, spec: Mapping, key: str, path: tuple, block=None, default=None, required=False):
        if key not in spec or spec[key] is None:
            if required:
                self.error("CHART002", f"missing '{key}' (a number)", path, block)
            return default
        value = spec[key]
        if not _is_number(value) or not _finite_number(value):
            self.error("CHART004", f"'{key}' must be a finite number, found {_show(value)}", path + (key,), block)
            return default
        return float(value)

    def flag(self, spec: Mapping, key: str, path: tuple, block=None, default=False) -> bool:
        value = spec.get(key, default)
        if value is None:
            return default
        if isinstance(value, str) and value.lower() in _YAML11_BOOLS:  # the loader reads only true/false
            return _YAML11_BOOLS[value.lower()]
        if not isinstance(value, bool):
            self.error("CHART004", f"'{key}' must be true or false, found {_show(value)}", path + (key,), block)
            return default
        return value

    # -- parameters --------------------------------------------------------------------------------
    def parameters(self, section) -> list[Parameter]:
        if section is None:
            return []
        if not isinstance(section, dict):
            self.error("CHART004", f"'parameters' must be a mapping of names, found {_kind(section)}", ("parameters",))
            return []
        out = []
        for name, spec in section.items():
            path = ("parameters", name)
            if not self.check_name(name, path, "parameter"):
                continue
            if _is_number(spec):
                spec = {"init": spec}
            if not isinstance(spec, dict):
                self.error("CHART004", f"parameter '{name}' must be a mapping like {{init: 0.1}}, found {_kind(spec)}", path)
                continue
            self.unknown_keys(spec, PARAM_KEYS, path, f"parameter '{name}'")
            init = self.number(spec, "init", path, required=True)
            lo = self.number(spec, "min", path)
            hi = self.number(spec, "max", path)
            out.append(
                Parameter(
                    name=name,
                    init=0.0 if init is None else init,
                    unit=self.optional_str(spec, "unit", path),
                    min=lo,
                    max=hi,
                    fixed=self.flag(spec, "fixed", path),
                    description=self.optional_str(spec, "description", path),
                    location=self.loc(*path),
                    per_record=self.flag(spec, "per_record", path),
                )
            )
        return out

    # -- blocks ------------------------------------------------------------------------------------
    def blocks(self, section, pnames: list[str]) -> list[Block]:
        if section is None:
            return []
        if not isinstance(section, dict):
            self.error("CHART004", f"'blocks' must be a mapping of block names, found {_kind(section)}", ("blocks",))
            return []
        out = []
        # references to a block that failed to validate are not reported as "undefined" as well
        self.broken_blocks = {n for n in section if isinstance(n, str) and NAME_RE.match(n)}
        for name, spec in section.items():
            block = self.block(name, spec, pnames)
            if block is not None:
                out.append(block)
        self.broken_blocks -= {b.name for b in out}
        return out

    def block(self, name, spec, pnames: list[str]) -> Block | None:
        path = ("blocks", name)
        if not self.check_name(name, path, "block"):
            return None
        if not isinstance(spec, dict):
            self.error("CHART004", f"block '{name}' must be a mapping like {{type: gain, in: x, k: c}}, "
                       f"found {_kind(spec)}", path, name)
            return None
        kind = spec.get("type")
        kinds = tuple(block_types())
        if kind is None:
            self.error("CHART002", f"missing 'type' (one of: {', '.join(kinds)})", path, name)
            return None
        if kind not in kinds:
            self.error("CHART006", f"unknown block type {_show(kind)}; expected one of: {', '.join(kinds)}",
                       path + ("type",), name, did_you_mean(str(kind), kinds))
            return None
        bt = block_type(kind)
        article = "an" if kind[0] in "aeiou" else "a"
        self.unknown_keys(spec, COMMON_BLOCK_KEYS + bt.keys, path, f"{article} {kind} block", name)
        fields: dict = {
            "name": name,
            "kind": kind,
            "unit": self.optional_str(spec, "unit", path, name),
            "description": self.optional_str(spec, "description", path, name),
            "location": self.loc(*path),
        }
        if bt.operands == "none":
            if "in" in spec:
                self.error("CHART003", f"{article} {kind} block takes no 'in'", path + ("in",), name)
        else:
            fields["inputs"] = self.terms(spec, path, name, many=bt.operands == "many")
            if 0 < len(fields["inputs"]) < bt.min_operands:
                self.error("CHART004", bt.too_few or f"{article} {kind} block needs at least {bt.min_operands} "
                           "signals in 'in'", path + ("in",), name)
        if bt.k != "none":
            fields["k"] = self.expression(spec, "k", path, name, pnames, required=bt.k == "required")
        # the keys beyond `in` and `k`, each read where a kind names it (diagram.blocks)
        if "f" in bt.keys:
            f = spec.get("f")
            if f not in FUNCTIONS:
                self.error("CHART004" if "f" in spec else "CHART002",
                           f"'f' must be one of: {', '.join(FUNCTIONS)}; found {_show(f)}", path + ("f",), name,
                           did_you_mean(str(f), FUNCTIONS))
            fields["f"] = f
        if "eps" in bt.keys:
            eps = self.number(spec, "eps", path, name)
            if eps is not None and eps <= 0:
                self.error("CHART004", f"'eps' must be positive, found {_show(eps)}", path + ("eps",), name)
            fields["eps"] = eps
        if "init" in bt.keys:
            init = spec.get("init", 0.0)
            if init in ("data", ESTIMATE) or (isinstance(init, str) and init in pnames):
                fields["init"] = init
            elif _finite_number(init):
                fields["init"] = float(init)
            else:
                self.error("CHART004", "'init' must be a number, 'data', 'estimate' or a parameter's name, found "
                           f"{_show(init)}", path + ("init",), name,
                           did_you_mean(str(init), ["data", ESTIMATE, *pnames]) if isinstance(init, str) else None)
        if "measured_by" in bt.keys and "measured_by" in spec:
            fields["measured_by"] = self.optional_str(spec, "measured_by", path, name)
        if "n" in bt.keys:
            n = spec.get("n", 1)
            if not isinstance(n, int) or isinstance(n, bool) or not 1 <= n <= MAX_DELAY:
                self.error("CHART004", f"'n' must be a whole number of samples from 1 to {MAX_DELAY}, found {_show(n)}",
                           path + ("n",), name)
                n = 1
            fields["n"] = n
        if "neurons" in bt.keys:  # a learned curve's keys are read together
            self.nonlinear(spec, path, name, fields)
        return Block(**fields)

    def nonlinear(self, spec: Mapping, path: tuple, name: str, fields: dict) -> None:
        neurons = spec.get("neurons", 3)
        if not isinstance(neurons, int) or isinstance(neurons, bool) or not 1 <= neurons <= MAX_NEURONS:
            self.error("CHART004", f"'neurons' must be a whole number from 1 to {MAX_NEURONS}, found {_show(neurons)}",
                       path + ("neurons",), name)
            neurons = 3
        fields["neurons"] = neurons
        fields["bias"] = self.flag(spec, "bias", path, name)
        fields["fixed"] = self.flag(spec, "fixed", path, name)
        rng = spec.get("init_range", [-0.5, 0.5])
        if (
            not isinstance(rng, list) or len(rng) != 2 or not all(_finite_number(x) for x in rng)
            or not rng[0] < rng[1]
        ):
            self.error("CHART004", f"'init_range' must be [low, high] with low < high, found {_show(rng)}",
                       path + ("init_range",), name)
            rng = [-0.5, 0.5]
        fields["init_range"] = (float(rng[0]), float(rng[1]))
        basis = spec.get("basis", DEFAULT_BASIS)
        if basis not in BASES:
            self.error("CHART004", f"'basis' must be one of {', '.join(BASES)}, found {_show(basis)}",
                       path + ("basis",), name, did_you_mean(str(basis), BASES))
            basis = DEFAULT_BASIS
        fields["basis"] = basis
        if basis != "neurons":  # the basis has its own density; `neurons` counts the paper's free neurons
            weights = spec.get("weights")
            given = weights.get("a") if isinstance(weights, dict) else None
            neurons = len(given) if isinstance(given, list) and 1 <= len(given) <= MAX_NEURONS else BASIS_FUNCTIONS
            fields["neurons"] = neurons
        if "linear" in spec and spec["linear"] is not None:
            fields["linear"] = self.flag(spec, "linear", path, name)
            if basis == "neurons" and fields["linear"]:
                self.error("CHART004", "'linear: true' needs the tanh basis (the paper's neurons have no linear "
                           "term)", path + ("linear",), name)
        if "span" in spec and spec["span"] is not None:
            span = spec["span"]
            if not _finite_number(span) or not span > 0:
                self.error("CHART004", f"'span' must be a positive number (the half-width of the input range), "
                           f"found {_show(span)}", path + ("span",), name)
            else:
                fields["span"] = float(span)
        weights = spec.get("weights")
        if weights is None:
            return
        wpath = path + ("weights",)
        if not isinstance(weights, dict):
            self.error("CHART004", "'weights' must be a mapping {a: [...], v: [...], b: [...]}", wpath, name)
            return
        self.unknown_keys(weights, ("a", "v", "b", "c"), wpath, "nonlinear weights", name)
        c = weights.get("c")
        if c is not None and not _finite_number(c):
            self.error("CHART004", f"weights 'c' (the linear term) must be a number, found {_show(c)}",
                       wpath + ("c",), name)
            return
        vectors = {}
        for key in ("a", "v", "b"):
            if key not in weights:
                continue
            vec = weights[key]
            if (not isinstance(vec, list) or len(vec) != neurons
                    or not all(_finite_number(x) for x in vec)):
                self.error("CHART004", f"weights '{key}' must be a list of {neurons} numbers", wpath + (key,), name)
                return
            vectors[key] = tuple(float(x) for x in vec)
        if "a" not in vectors or "v" not in vectors:
            self.error("CHART002", "nonlinear weights need both 'a' and 'v'", wpath, name)
            return
        if "b" in vectors and not fields["bias"]:
            self.error("CHART004", "weights 'b' given but the block has no bias (set 'bias: true')", wpath + ("b",), name)
            return
        if fields["bias"] and "b" not in vectors:
            vectors["b"] = (0.0,) * neurons
        fields["weights"] = NonlinearWeights(vectors["a"], vectors["v"], vectors.get("b"),
                                             None if c is None else float(c))

    def terms(self, spec: Mapping, path: tuple, name: str, many: bool) -> tuple[Term, ...]:
        if "in" not in spec:
            self.error("CHART002", "missing 'in' (the input signal" + ("s" if many else "") + ")", path, name)
            return ()
        raw = spec["in"]
        items = raw if isinstance(raw, list) else [raw]
        if not many and len(items) != 1:
            self.error("CHART004", f"'in' must be one signal, found a list of {len(items)}; use a sum block to add "
                       "signals", path + ("in",), name)
            return ()
        if many and not items:
            self.error("CHART004", "'in' must list at least one signal", path + ("in",), name)
            return ()
        out = []
        for i, item in enumerate(items):
            ipath = path + ("in", i) if isinstance(raw, list) else path + ("in",)
            if not isinstance(item, str):
                self.error("CHART004", f"an input must be a signal name like 'x' or '-x', found {_kind(item)}",
                           ipath, name)
                continue
            text = item.strip()
            sign = 1
            if text.startswith(("+", "-")):  # not `text[:1] in "+-"`: that is true for '' as well
                sign = -1 if text[0] == "-" else 1
                text = text[1:].strip()
            if not NAME_RE.match(text):
                self.error("CHART005", f"{_show(item)} is not a signal name (optionally prefixed by + or -)", ipath, name)
                continue
            out.append(Term(text, sign))
        return tuple(out)

    def expression(self, spec: Mapping, key: str, path: tuple, name: str, pnames: list[str], required: bool):
        if key not in spec or spec[key] is None:
            if required:
                self.error("CHART002", f"missing '{key}' (a number or an expression of parameters)", path, name)
            return None
        value = spec[key]
        if isinstance(value, bool) or not isinstance(value, (int, float, str)):
            self.error("CHART004", f"'{key}' must be a number or an expression, found {_kind(value)}",
                       path + (key,), name)
            return None
        if _is_number(value) and not _finite_number(value):  # parse_expr's message would print a 400-digit number
            self.error("CHART007", f"'{key}' must be a finite number, found {_show(value)}", path + (key,), name)
            return None
        try:
            expr = parse_expr(value)
            if not expr.variables <= self.known_parameters(pnames):
                parse_expr(value, names=pnames)  # raises, naming the unknown parameter with a did-you-mean
            return expr
        except ExprError as exc:
            col = self.doc.column(*path, key)
            if col is not None and exc.column is not None:
                col = col + exc.column - 1
            self.diagnostics.append(
                Diagnostic("CHART007", "error", f"'{key}: {_show(value, quote=False)}': {exc.message}",
                           Location(self.doc.file, self.doc.line(*path, key), col), name,
                           getattr(exc, "hint", None))
            )
            return None

    def known_parameters(self, pnames: list[str]) -> frozenset[str]:
        # parse_expr(names=...) copies the names into a set on every call: quadratic for 1000-mass charts
        if self._known[0] is not pnames:
            self._known = (pnames, frozenset(pnames))
        return self._known[1]

    # -- references --------------------------------------------------------------------------------
    def references(self, inputs: list[Signal], outputs: list[Signal], blocks: list[Block]) -> None:
        input_names = {s.name for s in inputs}
        block_names = {b.name for b in blocks}
        for b in blocks:
            if b.name in input_names:
                self.error("CHART008", f"signal '{b.name}' is driven twice: it is a chart input and a block",
                           ("blocks", b.name), b.name, "rename the block or the input")
        known = input_names | block_names
        broken = self.broken_blocks
        for b in blocks:
            for i, t in enumerate(b.inputs):
                if t.signal not in known and t.signal not in broken:
                    ipath = ("blocks", b.name, "in", i) if len(b.inputs) > 1 else ("blocks", b.name, "in")
                    self.error("CHART009", f"undefined signal '{t.signal}' (not an input nor a block)", ipath,
                               b.name, did_you_mean(t.signal, known))
        pnames = set(getattr(self, "param_names", ()))
        for s in inputs:
            if s.delay is not None and NAME_RE.match(s.delay) and s.delay not in pnames:
                self.error("CHART009", f"input '{s.name}': delay '{s.delay}' is not a parameter of the chart",
                           ("inputs", s.name, "delay"), hint=did_you_mean(s.delay, sorted(pnames)))
        for s in outputs:
            if s.name in input_names:
                self.error("CHART010", f"output '{s.name}' is a chart input; outputs must be block signals",
                           ("outputs", s.name))
            elif s.name not in block_names and s.name not in broken:
                self.error("CHART009", f"output '{s.name}' is not a block of the chart", ("outputs", s.name),
                           hint=did_you_mean(s.name, block_names))
        if not outputs and "outputs" in (self.doc.data or {}):
            self.error("CHART002", "a chart needs at least one output", ("outputs",))
        out_names = [s.name for s in outputs]
        for b in blocks:
            if b.kind != "integrator":
                continue
            if b.measured_by is not None:
                self._measured_by(b, out_names)
            elif b.init == "data" and b.name not in out_names:
                self.error("CHART011", "'init: data' needs the integrator to be a measured output",
                           ("blocks", b.name, "init"), b.name,
                           "give a number, list the block under 'outputs', or name the output that measures it "
                           "with 'measured_by'")

    def _measured_by(self, b: Block, out_names: list[str]) -> None:
        """`measured_by: y` starts a hidden integrator from output y's first sample: only with `init: data`,
        on an integrator that is not an output itself, naming an output of the chart."""
        where = ("blocks", b.name, "measured_by")
        if b.init != "data":
            self.error("CHART011", "'measured_by' goes with 'init: data' (the start read from that output's first "
                       f"sample), found init {_show(b.init)}", where, b.name, "set 'init: data' or drop 'measured_by'")
        elif b.name in out_names:
            self.error("CHART011", f"'measured_by' names the output that measures a hidden integrator; '{b.name}' is "
                       "an output itself", where, b.name, "drop 'measured_by'")
        elif b.measured_by not in out_names:
            self.error("CHART011", f"'measured_by' must name an output of the chart, found {_show(b.measured_by)}",
                       where, b.name, did_you_mean(str(b.measured_by), out_names))


def _kind(value) -> str:
    if value is None:
        return "nothing"
    if isinstance(value, bool):
        return f"a boolean ({value})"
    if isinstance(value, dict):
        return "a mapping"
    if isinstance(value, list):
        return "a list"
    if isinstance(value, str):
        return f"the text {_show(value)}"
    if _is_number(value):
        return f"the number {_show(value)}"
    return type(value).__name__
