"""A CSV file before its rows are read: checked as a file (exists, regular, size), refused when it is not UTF-8
text, hashed while it is read, and its delimiter and decimal mark detected. The error codes are
:mod:`.csvdata`'s."""

from __future__ import annotations

import codecs
import csv
import hashlib
import io
import os
import re
import stat
from collections.abc import Callable, Iterator
from contextlib import contextmanager

from flowchart2sdnn.errors import SdnnError
from flowchart2sdnn.notices import Notice

__all__ = ["fail", "shown", "check_file", "sniff_binary", "first_bad_utf8", "hashing_text_reader", "sniff_dialect"]


def fail(code: str, message: str, file: str, line: int | None = None, hint: str | None = None) -> SdnnError:
    return SdnnError.at(code, message, file=file, line=line, hint=hint)


def shown(text: str, limit: int = 40) -> str:
    return repr(text if len(text) <= limit else text[:limit] + "...")


def check_file(file: str, max_bytes: int) -> int:
    """The file's size, after checking that it is a readable regular file of allowed size."""
    try:
        info = os.stat(file)
    except FileNotFoundError:
        raise fail("CSV001", "file not found (expected a CSV data file)", file) from None
    except OSError as exc:
        raise fail("CSV003", f"cannot read the file: {exc.strerror or exc}", file) from None
    if stat.S_ISDIR(info.st_mode):
        raise fail("CSV002", "is a directory (expected a CSV data file)", file)
    if not stat.S_ISREG(info.st_mode):
        raise fail("CSV002", "is not a regular file (expected a CSV data file)", file)
    if info.st_size > max_bytes:
        raise fail("CSV018", f"the file has {info.st_size} bytes, more than the limit of {max_bytes} "
                    "(expected a smaller file; raise max_bytes if it is right)", file)
    return info.st_size


class _HashingRaw(io.RawIOBase):
    """A raw binary reader that feeds every byte it passes on into a SHA-256."""

    def __init__(self, raw: io.FileIO):
        self._raw = raw
        self.sha = hashlib.sha256()

    def readable(self) -> bool:
        return True

    def readinto(self, buffer) -> int:
        n = self._raw.readinto(buffer)
        if n:
            self.sha.update(memoryview(buffer)[:n])
        return n or 0

    def close(self) -> None:
        self._raw.close()
        super().close()


@contextmanager
def hashing_text_reader(file: str) -> Iterator[tuple[io.TextIOWrapper, Callable[[], str]]]:
    """UTF-8 text of ``file`` for the csv module, and a function giving the digest of the bytes read so far."""
    raw = _HashingRaw(io.FileIO(file, "r"))
    text = io.TextIOWrapper(io.BufferedReader(raw, 1 << 20), encoding="utf-8-sig", newline="")
    with text:
        yield text, raw.sha.hexdigest


def sniff_binary(file: str) -> None:
    """Refuse UTF-16/32 and binary files by their first bytes, before the csv module sees them."""
    try:
        with open(file, "rb") as handle:
            head = handle.read(1 << 16)
    except OSError as exc:
        raise fail("CSV003", f"cannot read the file: {exc.strerror or exc}", file) from None
    for bom, name in ((codecs.BOM_UTF32_LE, "UTF-32"), (codecs.BOM_UTF32_BE, "UTF-32"),
                      (codecs.BOM_UTF16_LE, "UTF-16"), (codecs.BOM_UTF16_BE, "UTF-16")):
        if head.startswith(bom):
            raise fail("CSV015", f"the file is {name} text (expected UTF-8)", file, 1,
                        hint="save the file as UTF-8 CSV")
    nul = head.find(b"\0")
    if nul >= 0:
        raise fail("CSV015", "NUL byte: a binary file (expected UTF-8 text)", file, head.count(b"\n", 0, nul) + 1)


def first_bad_utf8(file: str) -> tuple[int | None, int]:
    """The line and value of the first byte that is not UTF-8 (line None if none is found)."""
    decoder = codecs.getincrementaldecoder("utf-8")()
    line = 1
    with open(file, "rb") as handle:
        while chunk := handle.readline(1 << 20):  # bounded even for a file without newlines
            try:
                decoder.decode(chunk)
            except UnicodeDecodeError as exc:
                return line, exc.object[exc.start]
            line += chunk.count(b"\n")
        try:
            decoder.decode(b"", final=True)
        except UnicodeDecodeError as exc:
            return line, exc.object[exc.start]
    return None, 0


_DELIMITERS = {",": "','", ";": "';'", "\t": "tab", "|": "'|'"}
_COMMA_NUMBER = re.compile(r"^\s*[-+]?\d*,\d+([eE][-+]?\d+)?\s*$")


def sniff_dialect(file: str, delimiter: str, decimal: str) -> tuple[str, str, list[Notice]]:
    """The delimiter and decimal mark to read `file` with, detected where "auto", and the notes saying so."""
    if delimiter != "auto" and delimiter not in _DELIMITERS:
        raise ValueError(f"delimiter must be one of ',', ';', tab, '|' or 'auto', not {delimiter!r}")
    if decimal not in (".", ",", "auto"):
        raise ValueError(f"decimal must be '.', ',' or 'auto', not {decimal!r}")
    if delimiter == "," and decimal == ",":
        raise ValueError("decimal ',' needs a delimiter other than ',' (e.g. delimiter ';')")
    if delimiter != "auto" and decimal != "auto":
        return delimiter, decimal, []
    head = _first_lines(file, 2)
    notes = []
    if delimiter == "auto":
        counts = {sep: len(next(csv.reader([head[0]], delimiter=sep), [])) for sep in _DELIMITERS} if head else {}
        delimiter = max(counts, key=lambda sep: (counts[sep], sep == ","), default=",")
        if delimiter != ",":
            notes.append(Notice("READ001", f"delimiter {_DELIMITERS[delimiter]} (detected from the header; "
                                "--delimiter to set it)", {"delimiter": delimiter}, "--delimiter to set it"))
    if decimal == "auto":
        cells = next(csv.reader([head[1]], delimiter=delimiter), []) if len(head) > 1 else []
        decimal = "," if delimiter != "," and any(_COMMA_NUMBER.match(c) for c in cells) else "."
        if decimal == ",":
            notes.append(Notice("READ002", "decimal comma (detected from the first data row; --decimal to set it)",
                                {"decimal": ","}, "--decimal to set it"))
    return delimiter, decimal, notes


def _first_lines(file: str, n: int) -> list[str]:
    """The first `n` non-blank lines of `file` (fewer at its end; none when it cannot be read as UTF-8: the
    reader reports that)."""
    out: list[str] = []
    try:
        with open(file, encoding="utf-8-sig", newline="") as handle:
            for line in handle:
                if line.strip():
                    out.append(line.rstrip("\r\n"))
                    if len(out) == n:
                        break
    except (OSError, UnicodeDecodeError):
        return []
    return out
