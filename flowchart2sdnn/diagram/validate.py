"""Validate a parsed chart (format version 1) and build the :class:`Diagram` IR.

Every problem becomes a :class:`Diagnostic` with the file, the line and the block; all of them are collected
before failing, so `sdnn lint` can show everything at once. Only structure is checked here (types, kinds,
names, references); the semantic checks (loops, units, identifiability) live in `analysis.lint`.
"""

from __future__ import annotations

import hashlib
from collections.abc import Mapping
from pathlib import Path

from ..errors import Diagnostic, Location, SdnnError, did_you_mean
from .blockcheck import BlockChecks
from .fieldcheck import NAME_RE, finite_number, is_number, kind_of, show_value
from .initestimate import expand_estimated_inits
from .model import (
    DELAY_RULES,
    FORMAT_VERSION,
    INTERSAMPLE,
    MAX_SUBSTEPS,
    Block,
    Diagram,
    Parameter,
    Signal,
)
from .yamlload import LocatedYaml, load_yaml, parse_yaml_text

__all__ = ["load_diagram", "diagram_from_text", "diagram_from_yaml", "TOP_KEYS"]

TOP_KEYS = ("sdnn", "name", "description", "sample_time", "substeps", "delays", "inputs", "outputs", "parameters",
            "blocks", "identified")
SIGNAL_KEYS = ("unit", "description")
INPUT_KEYS = (*SIGNAL_KEYS, "intersample", "delay")
PARAM_KEYS = ("init", "unit", "min", "max", "fixed", "description", "per_record")


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


class _Validator(BlockChecks):
    """The validator of a whole chart: its top level, signals, parameters and references; the checks of
    fields and blocks are its bases'."""

    # -- top level ---------------------------------------------------------------------------------
    def run(self, sha256: str | None) -> Diagram | None:
        data = self.doc.data
        if not isinstance(data, dict):
            self.error("CHART001", f"a chart is a mapping of keys (sdnn, name, blocks, ...), found {kind_of(data)}")
            return None
        self.unknown_keys(data, TOP_KEYS, (), "the chart")
        version = data.get("sdnn")
        if "sdnn" not in data:
            self.error("CHART002", "missing 'sdnn: 1' (the chart format version)", (), hint="add 'sdnn: 1' on top")
        elif version != FORMAT_VERSION or isinstance(version, bool):
            self.error("CHART002", f"unsupported format version {show_value(version)}; this sdnn reads version 1", ("sdnn",))
        name = data.get("name")
        if not isinstance(name, str) or not name.strip():
            self.error("CHART002", f"'name' must be a non-empty string, found {kind_of(name)}", ("name",))
            name = "chart"
        description = data.get("description")
        if description is not None and not isinstance(description, str):
            self.error("CHART004", "'description' must be a string", ("description",))
            description = None
        ts = data.get("sample_time")
        if "sample_time" not in data:
            self.error("CHART002", "missing 'sample_time' (seconds, e.g. 0.001)", ())
            ts = 1.0
        elif not is_number(ts) or not finite_number(ts) or ts <= 0 or ts > 1e6:
            self.error("CHART004", f"'sample_time' must be a positive number of seconds, found {show_value(ts)}", ("sample_time",))
            ts = 1.0
        substeps = self.substeps(data)
        delays = data.get("delays")
        if "delays" in data and delays not in DELAY_RULES:
            self.error("CHART004", f"'delays' must be one of {', '.join(DELAY_RULES)}, found {show_value(delays)}",
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
                   f"{show_value(value)}", ("substeps",), hint="network steps per sample: 1 is the paper's network")
        return None

    def signals(self, section, key: str) -> list[Signal]:
        if section is None:
            return []
        if not isinstance(section, dict):
            self.error("CHART004", f"'{key}' must be a mapping of signal names, found {kind_of(section)}", (key,))
            return []
        out = []
        for name, spec in section.items():
            path = (key, name)
            if not self.check_name(name, path, "signal"):
                continue
            if spec is None:
                spec = {}
            if not isinstance(spec, dict):
                self.error("CHART004", f"signal '{name}' must be a mapping like {{unit: N*m}}, found {kind_of(spec)}", path)
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
            self.error("CHART004", f"'intersample' must be one of {', '.join(INTERSAMPLE)}, found {show_value(intersample)}",
                       path + ("intersample",), hint="hold: each sample acts until the next (a drive's torque "
                       "command); linear: straight between the samples (a smooth measured signal)")
            intersample = "hold"
        delay = spec.get("delay")
        if delay is None:
            return intersample, None
        if is_number(delay) and finite_number(delay):
            return intersample, repr(float(delay))
        if isinstance(delay, str) and NAME_RE.match(delay.strip()):
            return intersample, delay.strip()
        self.error("CHART004", f"'delay' must be a dead time in seconds: a parameter name or a number, found "
                   f"{show_value(delay)}", path + ("delay",), hint="e.g. delay: tau, with tau a parameter (unit s)")
        return intersample, None

    # -- parameters --------------------------------------------------------------------------------
    def parameters(self, section) -> list[Parameter]:
        if section is None:
            return []
        if not isinstance(section, dict):
            self.error("CHART004", f"'parameters' must be a mapping of names, found {kind_of(section)}", ("parameters",))
            return []
        out = []
        for name, spec in section.items():
            path = ("parameters", name)
            if not self.check_name(name, path, "parameter"):
                continue
            if is_number(spec):
                spec = {"init": spec}
            if not isinstance(spec, dict):
                self.error("CHART004", f"parameter '{name}' must be a mapping like {{init: 0.1}}, found {kind_of(spec)}", path)
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
                       f"sample), found init {show_value(b.init)}", where, b.name, "set 'init: data' or drop 'measured_by'")
        elif b.name in out_names:
            self.error("CHART011", f"'measured_by' names the output that measures a hidden integrator; '{b.name}' is "
                       "an output itself", where, b.name, "drop 'measured_by'")
        elif b.measured_by not in out_names:
            self.error("CHART011", f"'measured_by' must name an output of the chart, found {show_value(b.measured_by)}",
                       where, b.name, did_you_mean(str(b.measured_by), out_names))
