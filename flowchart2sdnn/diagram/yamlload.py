"""Read a YAML chart safely and remember where every value came from.

PyYAML's safe composer builds a node tree that keeps line and column marks; we turn it into plain Python
values ourselves so that we can (a) record the line of every key, (b) refuse duplicate keys, which PyYAML
silently overwrites, and (c) stop alias bombs ("billion laughs") by counting the values we expand.
"""

from __future__ import annotations

import dataclasses
import hashlib
import re
from dataclasses import dataclass, field
from pathlib import Path

import yaml

from ..errors import SdnnError

__all__ = ["LocatedYaml", "load_yaml", "parse_yaml_text", "MAX_CHART_BYTES", "MAX_NODES"]

MAX_CHART_BYTES = 1_000_000
MAX_NODES = 200_000
MAX_DEPTH = 64


class _ChartLoader(getattr(yaml, "CSafeLoader", yaml.SafeLoader)):  # type: ignore[misc]
    """The safe loader (libyaml's when PyYAML has it: three times faster on a 1000-mass chart) with two
    YAML 1.2 readings that charts need:

    - ``1e-3`` is a number. YAML 1.1 wants a dot and a signed exponent (``1.0e-3``), so plain PyYAML turns
      ``sample_time: 1e-3`` into the text '1e-3' and the chart fails with a baffling message;
    - only ``true``/``false`` are booleans. YAML 1.1 also reads ``on``, ``off``, ``yes`` and ``no`` as
      booleans, so a signal named ``off`` (an offset) became ``False``. Validation still takes yes/no/on/off
      for flags such as ``fixed``.
    """


_ChartLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?(?:[0-9][0-9_]*)(?:\.[0-9_]*)?[eE][-+]?[0-9]+$"),
    list("-+0123456789"),
)
for _resolvers in _ChartLoader.yaml_implicit_resolvers.values():  # lists copied by the call above
    _resolvers[:] = [(tag, rx) for tag, rx in _resolvers if tag != "tag:yaml.org,2002:bool"]
_ChartLoader.add_implicit_resolver(
    "tag:yaml.org,2002:bool", re.compile(r"^(?:true|True|TRUE|false|False|FALSE)$"), list("tTfF")
)
_LOADER = _ChartLoader

Path_ = tuple  # a path into the document: ("blocks", "MB1", "in", 2)


@dataclass(frozen=True)
class LocatedYaml:
    """A YAML document as plain values plus the 1-based (line, column) of every path in it."""

    file: str
    data: object
    marks: dict = field(default_factory=dict)
    sha256: str | None = None  # of the file's bytes, when read from a file

    def line(self, *path) -> int | None:
        """Line of the deepest known prefix of `path` (a missing key reports its parent's line)."""
        for cut in range(len(path), -1, -1):
            mark = self.marks.get(tuple(path[:cut]))
            if mark is not None:
                return mark[0]
        return None

    def column(self, *path) -> int | None:
        mark = self.marks.get(tuple(path))
        return mark[1] if mark else None


def load_yaml(path: str | Path) -> LocatedYaml:
    """Read and parse a chart file; every failure is an SdnnError naming the file and line."""
    name = str(path)
    p = Path(path)
    try:
        if p.is_dir():
            raise SdnnError.at("YAML001", "is a directory, expected a YAML chart file", name)
        size = p.stat().st_size
        if size > MAX_CHART_BYTES:
            raise SdnnError.at(
                "YAML002", f"file is {size} bytes, more than the {MAX_CHART_BYTES} a chart may have", name
            )
        raw = p.read_bytes()
    except FileNotFoundError:
        raise SdnnError.at("YAML001", "no such file", name) from None
    except PermissionError:
        raise SdnnError.at("YAML001", "permission denied", name) from None
    except OSError as exc:
        raise SdnnError.at("YAML001", f"cannot read: {exc.strerror or exc}", name) from None
    if b"\x00" in raw:
        at = raw.index(b"\x00")
        raise SdnnError.at("YAML003", "binary file (contains NUL bytes), expected a YAML text file", name,
                           raw.count(b"\n", 0, at) + 1)
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise SdnnError.at("YAML003", f"not UTF-8 text (bad byte 0x{raw[exc.start]:02x} at offset {exc.start})",
                           name, raw.count(b"\n", 0, exc.start) + 1) from None
    doc = parse_yaml_text(text, name)
    # hash the bytes that were parsed: reading the file a second time could see a different file
    return dataclasses.replace(doc, sha256=hashlib.sha256(raw).hexdigest())


def _check_nesting(text: str, name: str) -> bool:
    """Refuse deep nesting from the event stream, before any recursive composer sees the document.

    libyaml's parser is iterative but PyYAML's composer recurses, and the C one (CSafeLoader) overflows the C
    stack (a segfault, not an exception) on a few ten thousand nested brackets. Returns whether the document
    uses an alias (only then can it expand to more values than it has nodes).
    """
    depth = 0
    aliases = False
    opening, closing = (yaml.MappingStartEvent, yaml.SequenceStartEvent), (yaml.MappingEndEvent, yaml.SequenceEndEvent)
    for event in yaml.parse(text, Loader=_LOADER):
        kind = type(event)
        if kind in opening:
            depth += 1
            if depth > MAX_DEPTH + 1:
                raise SdnnError.at("YAML005", f"nesting deeper than {MAX_DEPTH} levels", name,
                                   event.start_mark.line + 1, event.start_mark.column + 1)
        elif kind in closing:
            depth -= 1
        elif kind is yaml.AliasEvent:
            aliases = True
    return aliases


def parse_yaml_text(text: str, name: str = "<chart>") -> LocatedYaml:
    """Parse chart text (already decoded); every failure is an SdnnError naming `name` and, when known, a line."""
    if len(text) > MAX_CHART_BYTES:
        raise SdnnError.at("YAML002", f"chart text longer than {MAX_CHART_BYTES} characters", name)
    try:
        aliases = _check_nesting(text, name)
        nodes = list(yaml.compose_all(text, Loader=_LOADER))
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        line = mark.line + 1 if mark else None
        col = mark.column + 1 if mark else None
        problem = exc.problem or exc.context or "invalid YAML"
        if "nesting depth" in problem:  # PyYAML >= 6.0.4 refuses deep nesting itself: the same error as ours
            raise SdnnError.at("YAML005", f"nesting too deep ({problem})", name, line, col) from None
        raise SdnnError.at("YAML004", f"invalid YAML: {problem}", name, line, col) from None
    except yaml.reader.ReaderError as exc:  # a character YAML does not allow (control characters)
        char = chr(exc.character) if isinstance(exc.character, int) else str(exc.character)[:1]
        at = text.find(char) if char else -1  # libyaml reports a byte offset; find the character instead
        line = text.count("\n", 0, at) + 1 if at >= 0 else None
        raise SdnnError.at("YAML003", f"invalid YAML: {exc.reason} (character {ascii(char)})", name,
                           line) from None
    except yaml.YAMLError as exc:
        raise SdnnError.at("YAML004", f"invalid YAML: {exc}", name) from None
    except UnicodeError:  # lone surrogates in text handed in directly: libyaml cannot encode them
        at = next((i for i, c in enumerate(text) if "\ud800" <= c <= "\udfff"), -1)
        raise SdnnError.at("YAML003", "text is not valid Unicode (a lone surrogate character)", name,
                           text.count("\n", 0, at) + 1 if at >= 0 else None) from None
    except RecursionError:
        raise SdnnError.at("YAML005", "nesting too deep", name) from None
    if len(nodes) > 1:
        line = nodes[1].start_mark.line + 1 if nodes[1] is not None else None
        raise SdnnError.at("YAML004", "more than one YAML document ('---'); a chart is one document", name, line)
    if not nodes or nodes[0] is None:
        raise SdnnError.at("YAML006", "empty file, expected a chart (a mapping with 'sdnn: 1')", name, 1)
    if aliases:
        _check_expansion(nodes[0], name)
    builder = _Builder(name)
    data = builder.build(nodes[0], (), 0)
    return LocatedYaml(name, data, builder.marks)


def _check_expansion(root: yaml.Node, name: str) -> None:
    """Refuse an alias bomb before expanding it: count the values each node expands to, once per node.

    A billion-laughs document has a few dozen nodes that expand to 10^9 values; the builder would spend a
    second reaching its limit, this takes microseconds. A node that contains itself (``&a [*a]``) is refused.
    """
    sizes: dict[int, int] = {}

    def size(node: yaml.Node) -> int:
        key = id(node)
        if key in sizes:
            if sizes[key] < 0:
                raise SdnnError.at("YAML005", "an alias refers to a collection that contains it (a recursive "
                                   "alias)", name, node.start_mark.line + 1)
            return sizes[key]
        sizes[key] = -1  # in progress
        if isinstance(node, yaml.MappingNode):
            total = 1 + sum(size(k) + size(v) for k, v in node.value)
        elif isinstance(node, yaml.SequenceNode):
            total = 1 + sum(size(v) for v in node.value)
        else:
            total = 1
        sizes[key] = min(total, 10 * MAX_NODES)  # saturate: big numbers cost time too
        return sizes[key]

    if size(root) <= MAX_NODES:
        return
    node = root  # point at the smallest collection that alone expands past the limit
    while True:
        children = ([c for kv in node.value for c in kv] if isinstance(node, yaml.MappingNode)
                    else node.value if isinstance(node, yaml.SequenceNode) else [])
        big = [c for c in children if sizes.get(id(c), 0) > MAX_NODES]
        if not big:
            break
        node = big[0]
    raise SdnnError.at("YAML005", f"more than {MAX_NODES} values after expanding aliases (an alias bomb?)", name,
                       node.start_mark.line + 1)


class _Builder:
    def __init__(self, name: str):
        self.name = name
        self.marks: dict[Path_, tuple[int, int]] = {}
        self.count = 0
        self._scalar_loader = yaml.SafeLoader("")

    def build(self, node: yaml.Node, path: Path_, depth: int):
        self.count += 1
        line, col = node.start_mark.line + 1, node.start_mark.column + 1
        if self.count > MAX_NODES:
            raise SdnnError.at(
                "YAML005",
                f"more than {MAX_NODES} values after expanding aliases (an alias bomb?)",
                self.name,
                line,
            )
        if depth > MAX_DEPTH:
            raise SdnnError.at("YAML005", f"nesting deeper than {MAX_DEPTH} levels", self.name, line)
        self.marks.setdefault(path, (line, col))
        if isinstance(node, yaml.MappingNode):
            out: dict = {}
            for key_node, value_node in node.value:
                if not isinstance(key_node, yaml.ScalarNode):
                    raise SdnnError.at(
                        "YAML007", "a mapping key must be a plain name", self.name, key_node.start_mark.line + 1
                    )
                if key_node.tag == "tag:yaml.org,2002:merge":
                    raise SdnnError.at(
                        "YAML007", "merge keys ('<<') are not supported in charts", self.name,
                        key_node.start_mark.line + 1,
                    )
                key = self._scalar(key_node)
                if not isinstance(key, (str, int, float, bool)) or key is None:
                    key = str(key)
                key = str(key) if not isinstance(key, str) else key
                key_line = key_node.start_mark.line + 1
                if key in out:
                    first = self.marks.get(path + (key,), (None,))[0]
                    raise SdnnError.at(
                        "YAML008",
                        f"duplicate key '{key}' (first defined on line {first})",
                        self.name,
                        key_line,
                        key_node.start_mark.column + 1,
                    )
                self.marks[path + (key,)] = (key_line, key_node.start_mark.column + 1)
                out[key] = self.build(value_node, path + (key,), depth + 1)
            return out
        if isinstance(node, yaml.SequenceNode):
            return [self.build(item, path + (i,), depth + 1) for i, item in enumerate(node.value)]
        return self._scalar(node)

    def _scalar(self, node: yaml.ScalarNode):
        if node.tag == "tag:yaml.org,2002:str":  # most scalars: what the constructor would return, 10x cheaper
            return node.value
        try:
            return self._scalar_loader.construct_object(node, deep=True)
        except (yaml.YAMLError, ValueError, OverflowError):
            # e.g. an explicit tag PyYAML's safe loader does not know: keep the text, validation says what it expected
            return str(node.value)
