"""Terminal concerns of the `sdnn` commands: progress on stderr and Ctrl-C.

Layer: cli (the rule is in the package docstring). They report progress through plain callables
(``progress(text, fraction)``, ``on_file(done, total, row)``) and poll ``stop()``; the classes here are such
callables.
"""

from __future__ import annotations

import signal
import sys
import threading
import time

import click

__all__ = ["Progress", "CtrlC", "BatchBar"]


class CtrlC:
    """The first Ctrl-C only asks the run to stop (it then writes the best result so far); a second one aborts.

    A KeyboardInterrupt raised at an arbitrary point (inside numba code, while computing the uncertainty)
    could lose the whole run, so SIGINT sets a flag that the trainer polls between iterations instead.
    Only the main thread can own signal handlers; elsewhere this is an inert flag.
    """

    def __init__(self) -> None:
        self.requested = False
        self._previous = None
        if threading.current_thread() is threading.main_thread():
            self._previous = signal.signal(signal.SIGINT, self._handle)

    def _handle(self, signum, frame) -> None:
        if self.requested:
            self.restore()
            raise KeyboardInterrupt
        self.requested = True

    def __call__(self) -> bool:
        return self.requested

    def restore(self) -> None:
        if self._previous is not None:
            signal.signal(signal.SIGINT, self._previous)
            self._previous = None


class Progress:
    """Progress on stderr: a redrawn line on a terminal, an occasional plain line elsewhere; silent if quiet."""

    def __init__(self, quiet: bool, min_interval: float = 1.0):
        self.quiet = quiet
        self.tty = sys.stderr.isatty()
        self.start = time.monotonic()
        self.last = 0.0
        self.min_interval = min_interval if self.tty else 5.0
        self.drawn = False

    def __call__(self, text: str, fraction: float | None = None) -> None:
        if self.quiet:
            return
        now = time.monotonic()
        if now - self.start < 1.0 or now - self.last < self.min_interval:
            return  # nothing for runs shorter than a second
        self.last = now
        bar = ""
        if fraction is not None:
            filled = int(round(20 * max(0.0, min(1.0, fraction))))
            bar = "[" + "#" * filled + "." * (20 - filled) + f"] {100 * fraction:3.0f}% "
        line = f"{bar}{text} ({now - self.start:.0f} s)"
        if self.tty:
            click.echo("\r" + line[:150].ljust(150), nl=False, err=True)
            self.drawn = True
        else:
            click.echo(line, err=True)

    def close(self) -> None:
        if self.drawn:
            click.echo("\r" + " " * 150 + "\r", nl=False, err=True)


class BatchBar:
    """A progress bar over files on stderr: redrawn on a terminal, a plain line every few seconds elsewhere."""

    def __init__(self, total: int, quiet: bool):
        self.total, self.quiet = total, quiet
        self.tty = sys.stderr.isatty()
        self.start = time.monotonic()
        self.last = 0.0
        self.failed = self.skipped = self.worked = 0

    def __call__(self, done: int, total: int, row: dict | None) -> None:
        if row is None:
            self.skipped += 1
        else:
            self.worked += 1
            self.failed += row.get("status") == "error"
        if self.quiet:
            return
        now = time.monotonic()
        if done < total and now - self.last < (0.2 if self.tty else 5.0):
            return
        self.last = now
        elapsed = now - self.start
        rate = self.worked / elapsed if elapsed > 0 else 0.0
        left = total - done
        eta = f", about {left / rate:.0f} s left" if rate > 0 and left else ""
        filled = int(round(24 * done / max(1, total)))
        line = (f"[{'#' * filled}{'.' * (24 - filled)}] {done}/{total} files ({self.skipped} already done, "
                f"{self.failed} failed) {rate:.2f} files/s{eta}")
        if self.tty:
            click.echo("\r" + line[:150].ljust(150), nl=done >= total, err=True)
        else:
            click.echo(line, err=True)
