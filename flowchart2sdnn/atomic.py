"""Atomic file output: a reader sees either the complete old file or the complete new one, never a mix.

The data go to a temporary file in the target's own directory (so :func:`os.replace` stays a rename
inside one file system), are flushed and fsynced, and only then replace the target; the directory is
fsynced afterwards so that the rename itself survives a crash. If the writing code raises, the temporary
file is removed and the old target is left untouched.

Temporary files are named ``.sdnn-tmp.<target name>.<8 hex digits>`` (see :data:`TEMP_PREFIX`). A process
killed mid-write (SIGKILL, power loss) cannot remove its own temporary file, so such a file may be left
next to the target; it is never the target itself and can be deleted at any time when no write is running
(:func:`clean_temp_files`).

Error codes (all raised as :class:`~flowchart2sdnn.errors.SdnnError` by :func:`check_output_path`):

======  ===============================================================
code    meaning
======  ===============================================================
OUT001  the output's directory does not exist
OUT002  the output is one of the inputs ("would overwrite its input")
OUT003  the output exists and overwriting was not allowed (no --force)
OUT004  the output path is a directory
======  ===============================================================
"""

from __future__ import annotations

import os
import secrets
import stat
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import IO, Any

from flowchart2sdnn.errors import SdnnError

__all__ = [
    "TEMP_PREFIX",
    "atomic_open",
    "atomic_write_bytes",
    "atomic_write_text",
    "check_output_path",
    "clean_temp_files",
    "read_json",
]

TEMP_PREFIX = ".sdnn-tmp."

PathLike = str | os.PathLike


def _target(path: PathLike) -> Path:
    # Writing through a symlink should update the file it points to, not replace the link by a file.
    p = Path(os.fspath(path))
    return Path(os.path.realpath(p)) if p.is_symlink() else p


def _create_temp(target: Path) -> tuple[int, Path]:
    directory = target.parent
    while True:
        tmp = directory / f"{TEMP_PREFIX}{target.name}.{secrets.token_hex(4)}"
        try:
            # 0o666 lets the umask decide the final permissions, as for a plain open(); mkstemp would force 0o600.
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_BINARY", 0), 0o666)
        except FileExistsError:
            continue
        return fd, tmp


def _fsync_directory(directory: Path) -> None:
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:  # e.g. Windows, where directories cannot be opened; the rename is still atomic there
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


@contextmanager
def atomic_open(
    path: PathLike, mode: str = "w", encoding: str | None = "utf-8", newline: str | None = None
) -> Iterator[IO[Any]]:
    """Open a file for writing that replaces ``path`` atomically when the ``with`` block ends without error.

    Parameters
    ----------
    path : str or os.PathLike
        The target. Its directory must exist. A symlink is followed: the file it points to is replaced.
    mode : {"w", "wt", "wb"}
        Text or binary writing.
    encoding : str or None
        Text encoding (ignored in binary mode).
    newline : str or None
        As for :func:`open` in text mode (``""`` for the :mod:`csv` module).

    Yields
    ------
    file object
        Writes go to a temporary file ``TEMP_PREFIX + name + '.xxxxxxxx'`` in the same directory.

    Notes
    -----
    On normal exit the file is flushed, fsynced, given the old target's permission bits (when the target
    existed) and renamed over the target with :func:`os.replace`. On any exception the temporary file is
    removed, the target is left as it was, and the exception propagates.
    """
    if mode not in ("w", "wt", "wb"):
        raise ValueError(f"atomic_open supports modes 'w', 'wt' and 'wb', not {mode!r}")
    target = _target(path)
    fd, tmp = _create_temp(target)
    try:
        if mode == "wb":
            handle: IO[Any] = os.fdopen(fd, "wb")
        else:
            handle = os.fdopen(fd, "w", encoding=encoding, newline=newline)
    except BaseException:
        os.close(fd)
        tmp.unlink(missing_ok=True)
        raise
    try:
        with handle:
            yield handle
            handle.flush()
            os.fsync(handle.fileno())
        try:
            os.chmod(tmp, stat.S_IMODE(os.stat(target).st_mode))
        except FileNotFoundError:
            pass
        os.replace(tmp, target)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    _fsync_directory(target.parent)


def atomic_write_bytes(path: PathLike, data: bytes) -> None:
    """Replace ``path`` atomically by ``data`` (see :func:`atomic_open`)."""
    with atomic_open(path, "wb") as handle:
        handle.write(data)


def atomic_write_text(path: PathLike, text: str, encoding: str = "utf-8") -> None:
    """Replace ``path`` atomically by ``text`` written with ``encoding`` and no newline translation."""
    with atomic_open(path, "w", encoding=encoding, newline="") as handle:
        handle.write(text)


def clean_temp_files(path: PathLike) -> list[Path]:
    """Remove temporary files that interrupted atomic writes of ``path`` left behind; return what was removed.

    Only call this when no other process is writing ``path``: a running write's temporary file would go too.
    """
    target = _target(path)
    removed = []
    prefix = f"{TEMP_PREFIX}{target.name}."
    for stray in target.parent.iterdir():
        suffix = stray.name[len(prefix) :]
        if stray.name.startswith(prefix) and len(suffix) == 8 and all(c in "0123456789abcdef" for c in suffix):
            stray.unlink(missing_ok=True)
            removed.append(stray)
    return sorted(removed)


def _same_file(a: Path, b: Path) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:  # one of them does not exist (yet): compare where they would be
        return a.resolve() == b.resolve()


def check_output_path(path: PathLike, inputs: Sequence[PathLike] = (), force: bool = True) -> None:
    """Check that ``path`` may be written before any work is done.

    Parameters
    ----------
    path : str or os.PathLike
        The output file.
    inputs : sequence of str or os.PathLike
        Files the command reads; the output must be none of them (also through links or ``..``).
    force : bool
        Whether an existing output may be overwritten.

    Raises
    ------
    SdnnError
        OUT001 when the directory does not exist, OUT002 when the output is an input, OUT003 when it exists
        and ``force`` is False, OUT004 when it is a directory.
    """
    out = Path(os.fspath(path))
    name = os.fspath(path)
    directory = out.parent if str(out.parent) else Path(".")
    if not directory.is_dir():
        raise SdnnError.at(
            "OUT001",
            f"cannot write '{name}': directory '{directory}' does not exist",
            file=name,
            hint="create the directory first",
        )
    if out.is_dir():
        raise SdnnError.at("OUT004", f"cannot write '{name}': it is a directory (expected a file name)", file=name)
    for source in inputs:
        if _same_file(out, Path(os.fspath(source))):
            raise SdnnError.at(
                "OUT002",
                f"output '{name}' would overwrite its input '{os.fspath(source)}'",
                file=name,
                hint="choose another output file",
            )
    if not force and (out.exists() or out.is_symlink()):
        raise SdnnError.at(
            "OUT003", f"output '{name}' already exists", file=name, hint="use --force to overwrite it"
        )


def read_json(path: str | Path, unreadable: str, not_json: str) -> Any:
    """The JSON value in file `path`; SdnnError with code `unreadable` (missing or unreadable file) or `not_json`
    (with the line and column of the fault) naming the file otherwise."""
    import json

    name = str(path)
    try:
        return json.loads(Path(path).read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise SdnnError.at(unreadable, "no such file", name) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise SdnnError.at(unreadable, f"cannot read: {exc}", name) from None
    except json.JSONDecodeError as exc:
        raise SdnnError.at(not_json, f"not JSON: {exc.msg}", name, exc.lineno, exc.colno) from None

