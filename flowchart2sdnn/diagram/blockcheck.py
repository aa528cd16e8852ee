"""The checks of a chart's blocks: each block's kind, keys, numbers, curve weights, input terms and
expressions over the parameters (:class:`BlockChecks`, a base of :mod:`.validate`'s validator)."""

from __future__ import annotations

from collections.abc import Mapping

from ..errors import Diagnostic, Location, did_you_mean
from ..expr import ExprError, parse_expr
from .blocks import block_type, block_types
from .curves import BASES, BASIS_FUNCTIONS, DEFAULT_BASIS
from .fieldcheck import NAME_RE, FieldChecks, finite_number, is_number, kind_of, show_value
from .initestimate import ESTIMATE
from .model import FUNCTIONS, Block, NonlinearWeights, Term

__all__ = ["BlockChecks", "MAX_NEURONS", "MAX_DELAY"]

MAX_NEURONS = 100
MAX_DELAY = 100_000
COMMON_BLOCK_KEYS = ("type", "unit", "description")


class BlockChecks(FieldChecks):
    """The checks of the blocks section, over the field checks."""

    # -- blocks ------------------------------------------------------------------------------------
    def blocks(self, section, pnames: list[str]) -> list[Block]:
        if section is None:
            return []
        if not isinstance(section, dict):
            self.error("CHART004", f"'blocks' must be a mapping of block names, found {kind_of(section)}", ("blocks",))
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
                       f"found {kind_of(spec)}", path, name)
            return None
        kind = spec.get("type")
        kinds = tuple(block_types())
        if kind is None:
            self.error("CHART002", f"missing 'type' (one of: {', '.join(kinds)})", path, name)
            return None
        if kind not in kinds:
            self.error("CHART006", f"unknown block type {show_value(kind)}; expected one of: {', '.join(kinds)}",
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
                           f"'f' must be one of: {', '.join(FUNCTIONS)}; found {show_value(f)}", path + ("f",), name,
                           did_you_mean(str(f), FUNCTIONS))
            fields["f"] = f
        if "eps" in bt.keys:
            eps = self.number(spec, "eps", path, name)
            if eps is not None and eps <= 0:
                self.error("CHART004", f"'eps' must be positive, found {show_value(eps)}", path + ("eps",), name)
            fields["eps"] = eps
        if "init" in bt.keys:
            init = spec.get("init", 0.0)
            if init in ("data", ESTIMATE) or (isinstance(init, str) and init in pnames):
                fields["init"] = init
            elif finite_number(init):
                fields["init"] = float(init)
            else:
                self.error("CHART004", "'init' must be a number, 'data', 'estimate' or a parameter's name, found "
                           f"{show_value(init)}", path + ("init",), name,
                           did_you_mean(str(init), ["data", ESTIMATE, *pnames]) if isinstance(init, str) else None)
        if "measured_by" in bt.keys and "measured_by" in spec:
            fields["measured_by"] = self.optional_str(spec, "measured_by", path, name)
        if "n" in bt.keys:
            n = spec.get("n", 1)
            if not isinstance(n, int) or isinstance(n, bool) or not 1 <= n <= MAX_DELAY:
                self.error("CHART004", f"'n' must be a whole number of samples from 1 to {MAX_DELAY}, found {show_value(n)}",
                           path + ("n",), name)
                n = 1
            fields["n"] = n
        if "neurons" in bt.keys:  # a learned curve's keys are read together
            self.nonlinear(spec, path, name, fields)
        return Block(**fields)

    def nonlinear(self, spec: Mapping, path: tuple, name: str, fields: dict) -> None:
        neurons = spec.get("neurons", 3)
        if not isinstance(neurons, int) or isinstance(neurons, bool) or not 1 <= neurons <= MAX_NEURONS:
            self.error("CHART004", f"'neurons' must be a whole number from 1 to {MAX_NEURONS}, found {show_value(neurons)}",
                       path + ("neurons",), name)
            neurons = 3
        fields["neurons"] = neurons
        fields["bias"] = self.flag(spec, "bias", path, name)
        fields["fixed"] = self.flag(spec, "fixed", path, name)
        rng = spec.get("init_range", [-0.5, 0.5])
        if (
            not isinstance(rng, list) or len(rng) != 2 or not all(finite_number(x) for x in rng)
            or not rng[0] < rng[1]
        ):
            self.error("CHART004", f"'init_range' must be [low, high] with low < high, found {show_value(rng)}",
                       path + ("init_range",), name)
            rng = [-0.5, 0.5]
        fields["init_range"] = (float(rng[0]), float(rng[1]))
        basis = spec.get("basis", DEFAULT_BASIS)
        if basis not in BASES:
            self.error("CHART004", f"'basis' must be one of {', '.join(BASES)}, found {show_value(basis)}",
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
            if not finite_number(span) or not span > 0:
                self.error("CHART004", f"'span' must be a positive number (the half-width of the input range), "
                           f"found {show_value(span)}", path + ("span",), name)
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
        if c is not None and not finite_number(c):
            self.error("CHART004", f"weights 'c' (the linear term) must be a number, found {show_value(c)}",
                       wpath + ("c",), name)
            return
        vectors = {}
        for key in ("a", "v", "b"):
            if key not in weights:
                continue
            vec = weights[key]
            if (not isinstance(vec, list) or len(vec) != neurons
                    or not all(finite_number(x) for x in vec)):
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
                self.error("CHART004", f"an input must be a signal name like 'x' or '-x', found {kind_of(item)}",
                           ipath, name)
                continue
            text = item.strip()
            sign = 1
            if text.startswith(("+", "-")):  # not `text[:1] in "+-"`: that is true for '' as well
                sign = -1 if text[0] == "-" else 1
                text = text[1:].strip()
            if not NAME_RE.match(text):
                self.error("CHART005", f"{show_value(item)} is not a signal name (optionally prefixed by + or -)", ipath, name)
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
            self.error("CHART004", f"'{key}' must be a number or an expression, found {kind_of(value)}",
                       path + (key,), name)
            return None
        if is_number(value) and not finite_number(value):  # parse_expr's message would print a 400-digit number
            self.error("CHART007", f"'{key}' must be a finite number, found {show_value(value)}", path + (key,), name)
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
                Diagnostic("CHART007", "error", f"'{key}: {show_value(value, quote=False)}': {exc.message}",
                           Location(self.doc.file, self.doc.line(*path, key), col), name,
                           getattr(exc, "hint", None))
            )
            return None

    def known_parameters(self, pnames: list[str]) -> frozenset[str]:
        # parse_expr(names=...) copies the names into a set on every call: quadratic for 1000-mass charts
        if self._known[0] is not pnames:
            self._known = (pnames, frozenset(pnames))
        return self._known[1]
