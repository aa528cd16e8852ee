"""Effects written by users in YAML: a chart fragment with placeholders, loaded with ``--effects-file``.

Format (``sdnn_effects: 1``)::

    sdnn_effects: 1
    effects:
      stiction:
        description: a static friction torque F*sign_smooth(w) against the motion
        attach: speed                # speed | speed_difference | spring_angle | position | state | input |
                                     # signal
        at: w2                       # optional: only this signal of the chart (required for signal)
        parameters:
          "{name}_F": {init: 0, unit: N*m}
        blocks:
          "{name}_s": {type: function, f: sign_smooth, in: "{at}", eps: 0.01}
          "{name}":   {type: gain, in: "{name}_s", k: "{name}_F", unit: N*m}
        output: "{name}"
        options: [0.01, 0.1]         # optional: each value replaces {option}; one candidate per value
        neutral: true                # optional (default true): the parameters' inits leave the outputs as
                                     # they were, so the joint score test applies

Placeholders (replaced as plain text in keys and values; no expressions are evaluated): ``{at}`` the signal
the effect attaches to, ``{name}`` a fresh prefix for new names (``<effect>_<at>``), ``{option}``, ``{sum}``
the first torque sum of a speed, ``{spring}`` the spring gain of a spring angle.

What ``output`` does, by ``attach``: speed and speed_difference - subtracted (against the motion) in the
torque sum(s); position (an integrator of a speed) - subtracted in the speed's torque sum (against the
position, as a spring to ground pulls); spring_angle - added to the spring torque (the gain is renamed
``<gain>_lin`` and a sum with the old name adds the two); state (any integrator) - subtracted from its
integrand (a leak, an outflow); input and signal (any block or input named by ``at``) - every block that read
the signal reads ``output`` instead (the fragment's own blocks still read it).

``at: <signal>`` restricts the effect to that one signal of the chart (a chart without it is an error naming
the effects file's line). Without ``attach``, the kind is read off the chart: ``at: x`` with x a position
attaches as a position, a speed as a speed, any other block or input as a signal.

The fragment is validated as a chart of its own (the chart's signals stand in as inputs) when it is applied,
so every structural mistake is reported as for a chart, naming the effects file and the effect.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path

import yaml

from ..diagram.model import Block, Diagram, Term
from ..diagram.validate import diagram_from_text
from ..diagram.yamlload import load_yaml
from ..errors import Location, SdnnError, did_you_mean
from .effects import Scales
from .graph import (
    Place,
    add_blocks,
    add_terms,
    fresh_name,
    input_places,
    positions,
    reroute,
    signal_place,
    speed_differences,
    speeds,
    spring_angles,
    states,
)

__all__ = ["YamlEffect", "load_effects_file", "EFFECTS_FORMAT", "ATTACH_KINDS"]

EFFECTS_FORMAT = 1
ATTACH_KINDS = ("speed", "speed_difference", "spring_angle", "position", "state", "input", "signal")
_KEYS = ("description", "attach", "at", "parameters", "blocks", "output", "options", "neutral")
_FINDERS = {"speed": speeds, "speed_difference": speed_differences, "spring_angle": spring_angles,
            "position": positions, "state": states, "input": input_places}
_PLACEHOLDERS = ("at", "name", "option", "sum", "spring")


_NUMBER = re.compile(r"^[+-]?(\d+(\.\d*)?|\.\d+)([eE][+-]?\d+)?$")


def _substitute(value, table: Mapping[str, str]):
    if isinstance(value, str):
        original = value
        for key, text in table.items():
            value = value.replace("{" + key + "}", text)
        if value != original and _NUMBER.match(value):  # "{option}" in a numeric field stays a number
            return int(value) if value.lstrip("+-").isdigit() else float(value)
        return value
    if isinstance(value, dict):
        return {_substitute(k, table): _substitute(v, table) for k, v in value.items()}
    if isinstance(value, list):
        return [_substitute(v, table) for v in value]
    return value


def _option_text(option) -> str:
    if isinstance(option, float) and option.is_integer():
        return str(int(option))
    return str(option)


@dataclass(frozen=True, eq=False)
class YamlEffect:
    """An effect defined by a chart fragment (see the module docstring)."""

    name: str
    attach: str | None
    parameters: dict
    blocks: dict
    output: str
    description: str = ""
    option_values: tuple = ()
    neutral: bool = True
    extra_dof: int = 0
    file: str = "<effects>"
    lines: dict = field(default_factory=dict)
    at: str | None = None

    def places(self, diagram: Diagram) -> tuple[Place, ...]:
        """Every place of the attach kind, or the one named by `at` (SdnnError when the chart lacks it)."""
        if self.at is None:
            return _FINDERS[self.attach](diagram)
        if self.attach is None or self.attach == "signal":
            try:
                place = signal_place(diagram, self.at)
            except KeyError:
                raise self._fail(f"at: '{self.at}' is no signal of the chart",
                                 did_you_mean(self.at, list(diagram.block_names) + list(diagram.input_names)),
                                 ("at",)) from None
            return (place if self.attach is None else Place(self.at, "signal"),)
        found = _FINDERS[self.attach](diagram)
        chosen = tuple(p for p in found if p.at == self.at)
        if not chosen:
            there = ", ".join(p.at for p in found) or "none"
            raise self._fail(f"at: '{self.at}' is no {self.attach.replace('_', ' ')} of the chart "
                             f"(its {self.attach.replace('_', ' ')}s: {there})",
                             did_you_mean(self.at, [p.at for p in found]), ("at",))
        return chosen

    def options(self, diagram: Diagram, place: Place, scales: Scales) -> tuple:
        return self.option_values or (None,)

    def label(self, option) -> str:
        return "" if option is None else f"{_option_text(option)}"

    def describe(self) -> str:
        return f"{self.name} ({self.file}): {self.description or 'user effect'}"

    def _fail(self, message: str, hint: str | None = None, key: tuple = ()) -> SdnnError:
        line = self.lines.get(key) or self.lines.get(())
        return SdnnError.at("DIAG021", f"effect '{self.name}': {message}", self.file, line, hint=hint)

    def patch(self, diagram: Diagram, place: Place, option=None) -> Diagram:
        prefix = fresh_name(diagram, f"{self.name}_{place.at}")
        table = {"at": place.at, "name": prefix, "option": "" if option is None else _option_text(option),
                 "sum": place.sums[0][0] if place.sums else "", "spring": place.via or ""}
        params = _substitute(self.parameters, table)
        blocks = _substitute(self.blocks, table)
        output = _substitute(self.output, table)
        existing = set(diagram.block_names) | set(diagram.input_names) | set(diagram.parameter_names)
        clash = sorted((set(params) | set(blocks)) & existing)
        if clash:
            raise self._fail(f"adds {', '.join(clash)}, which the chart already has",
                             "use {name} in the names of new blocks and parameters")
        if output not in blocks:
            raise self._fail(f"output '{output}' is not one of its blocks", did_you_mean(output, blocks))
        mini = self._validate(diagram, params, blocks, output)
        new_params = [replace(p, location=Location(self.file, self.lines.get(("parameters",)))) for p in
                      mini.parameters if p.name in params]
        new_blocks = [replace(b, location=Location(self.file, self.lines.get(("blocks",)))) for b in mini.blocks]
        patched = add_blocks(diagram, new_blocks, new_params)
        kind = place.kind if place.kind in ATTACH_KINDS else self.attach
        if kind in ("speed", "speed_difference", "position"):
            terms: dict[str, tuple[Term, ...]] = {}
            for s, sign in place.sums:
                terms[s] = terms.get(s, ()) + (Term(output, sign),)
            return add_terms(patched, terms)
        if kind in ("input", "signal"):
            return reroute(patched, place.at, output, keep=set(blocks))
        if kind == "state":
            x = diagram.block(place.at)
            integrand = fresh_name(patched, f"{place.at}_in")
            summed = Block(integrand, "sum", tuple(x.inputs) + (Term(output, -1),),
                           description=f"integrand of {place.at} with {self.name} (diagnose)")
            patched = add_blocks(patched, [summed])
            return replace(patched, blocks=tuple(replace(b, inputs=(Term(integrand),)) if b.name == place.at else b
                                                 for b in patched.blocks))
        spring = diagram.block(place.via)
        lin = fresh_name(patched, f"{spring.name}_lin")
        out = []
        for b in patched.blocks:
            if b.name == spring.name:
                out.append(replace(b, name=lin))
                out.append(Block(spring.name, "sum", (Term(lin), Term(output)), unit=spring.unit,
                                 description=f"spring torque with {self.name} (diagnose)"))
            else:
                out.append(b)
        return replace(patched, blocks=tuple(out))

    def _validate(self, diagram: Diagram, params: dict, blocks: dict, output: str) -> Diagram:
        signals = list(diagram.input_names) + list(diagram.block_names)
        doc = {"sdnn": 1, "name": f"{self.name}_fragment", "sample_time": diagram.sample_time,
               "inputs": {s: {} for s in signals if s not in blocks},
               "outputs": {output: {}},
               "parameters": {**{p.name: {"init": p.init} for p in diagram.parameters}, **params},
               "blocks": blocks}
        try:
            text = yaml.safe_dump(doc, sort_keys=False)
        except yaml.YAMLError as exc:  # pragma: no cover - the fragment came from YAML
            raise self._fail(f"cannot be written as a chart: {exc}") from None
        try:
            return diagram_from_text(text, f"{self.file} (effect '{self.name}')")
        except SdnnError as exc:
            d = exc.diagnostics[0]
            raise SdnnError.at(d.code, f"effect '{self.name}': {d.message}", self.file, self.lines.get(("blocks",)),
                               block=d.block, hint=d.hint) from None


def _check(cond: bool, message: str, file: str, line: int | None, hint: str | None = None) -> None:
    if not cond:
        raise SdnnError.at("DIAG020", message, file, line, hint=hint)


def load_effects_file(path: str | Path) -> dict[str, YamlEffect]:
    """Read an effects file; SdnnError (DIAG020) at the offending line for any structural problem."""
    doc = load_yaml(path)
    file = str(path)
    data = doc.data
    _check(isinstance(data, dict), "an effects file must be a mapping with 'sdnn_effects: 1' and 'effects'", file, 1)
    _check(data.get("sdnn_effects") == EFFECTS_FORMAT, f"expected 'sdnn_effects: {EFFECTS_FORMAT}' at the top",
           file, doc.line("sdnn_effects"))
    unknown = sorted(set(data) - {"sdnn_effects", "effects"})
    _check(not unknown, f"unknown top-level key(s) {', '.join(map(str, unknown))}; expected sdnn_effects, effects",
           file, doc.line(unknown[0]) if unknown else None)
    effects = data.get("effects")
    _check(isinstance(effects, dict) and effects, "'effects' must be a non-empty mapping of effect names", file,
           doc.line("effects"))
    out: dict[str, YamlEffect] = {}
    for name, spec in effects.items():
        where = ("effects", name)
        line = doc.line(*where)
        _check(isinstance(name, str) and name.isidentifier(), f"effect name {name!r} must be an identifier", file, line)
        _check(isinstance(spec, dict), f"effect '{name}' must be a mapping", file, line)
        bad = sorted(set(spec) - set(_KEYS))
        _check(not bad, f"effect '{name}': unknown key(s) {', '.join(map(str, bad))}", file,
               doc.line(*where, bad[0]) if bad else line, did_you_mean(str(bad[0]), _KEYS) if bad else None)
        attach, at = spec.get("attach"), spec.get("at")
        _check(at is None or (isinstance(at, str) and at.isidentifier()),
               f"effect '{name}': 'at' must name a signal of the chart, found {at!r}", file, doc.line(*where, "at"))
        _check(attach in ATTACH_KINDS or (attach is None and at is not None),
               f"effect '{name}': 'attach' must be one of {', '.join(ATTACH_KINDS)}, found {attach!r}"
               + ("" if attach is not None else " (or give 'at: <signal>')"), file,
               doc.line(*where, "attach") or line, did_you_mean(str(attach), ATTACH_KINDS))
        _check(attach != "signal" or at is not None, f"effect '{name}': 'attach: signal' needs 'at: <signal>'",
               file, doc.line(*where, "attach"))
        for key in ("parameters", "blocks"):
            value = spec.get(key, {} if key == "parameters" else None)
            _check(isinstance(value, dict) and (key == "parameters" or value),
                   f"effect '{name}': '{key}' must be a {'non-empty ' if key == 'blocks' else ''}mapping", file,
                   doc.line(*where, key))
        output = spec.get("output")
        _check(isinstance(output, str) and output, f"effect '{name}': 'output' must name one of its blocks", file,
               doc.line(*where, "output"))
        options = spec.get("options", [])
        _check(isinstance(options, list) and all(isinstance(o, (int, float, str)) and not isinstance(o, bool)
                                                 for o in options),
               f"effect '{name}': 'options' must be a list of numbers or names", file, doc.line(*where, "options"))
        neutral = spec.get("neutral", True)
        _check(isinstance(neutral, bool), f"effect '{name}': 'neutral' must be true or false", file,
               doc.line(*where, "neutral"))
        description = spec.get("description", "")
        _check(isinstance(description, str), f"effect '{name}': 'description' must be text", file,
               doc.line(*where, "description"))
        lines = {(): line, ("blocks",): doc.line(*where, "blocks"), ("parameters",): doc.line(*where, "parameters"),
                 ("at",): doc.line(*where, "at")}
        out[name] = YamlEffect(name, attach, dict(spec.get("parameters") or {}), dict(spec["blocks"]), output,
                               description, tuple(options), neutral, 1 if len(options) > 1 else 0, file, lines, at)
    return out
