"""run_batch(): identify one chart on many data files (a fleet of drives, day by day), resumably.

Each data file becomes one row of the results table (see :mod:`.results`). The parent process hashes and reads
each file (a file it cannot read becomes an error row at once) and sends a :class:`FileUnit` (the chart, the
data arrays and the settings: nothing that needs a shared file system) to the executor; :func:`identify_file`
runs :func:`~flowchart2sdnn.identify.offline.run.identify` in the worker and turns its result into a row. Any failure
of one file (bad data, a fit that raises, a worker that died) is a row with status "error" and the message.

Resuming: a file is skipped when the table already has a row for that path with the same sha256 and the same
configuration (chart after --fix-from, settings, column mapping). A file whose content was seen under another
path gets a copy of that row. Error rows are kept unless ``retry_errors``. A table written with another
configuration is refused (BATCH002) unless ``force``.
"""

from __future__ import annotations

import concurrent.futures as cf
import contextlib
import hashlib
import json
import math
import os
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field

from ..data.csvdata import Dataset, read_csv
from ..diagram.model import Diagram
from ..errors import SdnnError
from ..executors import Executor, SerialExecutor
from ..identify import Identification, IdentifySettings
from .results import Columns, ResultsWriter, columns_for, read_results

__all__ = ["BatchSettings", "BatchSummary", "FileUnit", "run_batch", "identify_file", "config_key"]


@dataclass(frozen=True)
class BatchSettings:
    """Options of a batch run.

    Attributes
    ----------
    identify : IdentifySettings   the same for every file
    mapping : tuple of (name, column)  ``--map`` items
    scales : tuple of (name, factor)   ``--unit`` conversions (see analysis.dataunits.unit_scales)
    retry_errors : bool           redo files whose row is an error
    force : bool                  discard a table written with another configuration
    diagnose : bool               also run flowchart2sdnn.diagnose on each file; its accepted effects go to the
                                  ``effects`` column ("none" when it accepted nothing)
    """

    identify: IdentifySettings = field(default_factory=IdentifySettings)
    mapping: tuple[tuple[str, str], ...] = ()
    scales: tuple[tuple[str, float], ...] = ()
    retry_errors: bool = False
    force: bool = False
    diagnose: bool = False


@dataclass(frozen=True)
class BatchSummary:
    """What a batch run did: counts, wall time, the table written."""

    output: str
    total: int
    identified: int
    failed: int
    skipped: int
    copied: int
    dropped_lines: int
    seconds: float

    @property
    def files_per_second(self) -> float:
        done = self.identified + self.failed
        return done / self.seconds if self.seconds > 0 else math.nan


@dataclass(frozen=True, eq=False)
class FileUnit:
    """One file's work: picklable, no callbacks, no paths the worker must open."""

    file: str
    sha256: str
    diagram: Diagram
    data: Dataset
    settings: IdentifySettings
    config: str
    columns: Columns
    diagnose: bool = False


def config_key(diagram: Diagram, settings: BatchSettings) -> str:
    """A short hash of what makes two rows comparable: the chart (after --fix-from) and the settings."""
    from ..diagram.dump import dump_diagram

    h = hashlib.sha256(dump_diagram(diagram).encode())
    h.update(json.dumps(asdict(settings.identify), sort_keys=True, default=list).encode())
    h.update(json.dumps(sorted(settings.mapping)).encode())
    if settings.scales:  # absent from the key without --unit: tables written before it stay valid
        h.update(json.dumps(sorted(settings.scales)).encode())
    if settings.diagnose:
        h.update(b"diagnose")
    return h.hexdigest()[:16]


def _sha256_file(path: str) -> str | None:
    h = hashlib.sha256()
    try:
        with open(path, "rb") as handle:
            for block in iter(lambda: handle.read(1 << 20), b""):
                h.update(block)
    except OSError:
        return None  # read_csv will explain
    return h.hexdigest()


def _error_row(file: str, sha: str | None, config: str, message: str, seconds: float = 0.0) -> dict:
    return {"file": file, "sha256": sha, "status": "error", "error": message, "seconds": seconds, "config": config}


def _message(exc: BaseException) -> str:
    if isinstance(exc, SdnnError):
        return exc.diagnostics[0].one_line()
    return f"{type(exc).__name__}: {' '.join(str(exc).split())[:500]}"


def _row_from_result(result: Identification, unit: FileUnit) -> dict:
    data = unit.data
    if data.time is not None and data.n_rows:
        t_start, t_end = float(data.time[0]), float(data.time[-1])
    else:
        t_start, t_end = 0.0, (data.n_rows - 1) * float(unit.diagram.sample_time)
    train = result.fit.train
    row = {"file": unit.file, "sha256": unit.sha256, "status": result.status, "error": None,
           "t_start": t_start, "t_end": t_end, "rows": data.n_rows, "cost": train.cost,
           "iterations": result.optimizer.iterations if result.optimizer else None, "starts": unit.settings.starts,
           "warnings": " | ".join(result.warnings) or None, "config": unit.config}
    for o in unit.columns.outputs:
        row[f"fit_{o}"] = train.fit_percent.get(o)
    for p in unit.columns.parameters:
        est = result.parameters.get(p)
        ci = (est.ci95 if est else None) or (None, None)
        row[p], row[f"{p}_lo"], row[f"{p}_hi"] = est.value if est else None, ci[0], ci[1]
    return row


def _effects(unit: FileUnit) -> str:
    """The effects diagnose() accepts on this file, as "label; label", or "none"."""
    from ..diagnose import loop  # looked up per call: diagnose is replaceable (tests stand in for it)

    try:
        s = unit.settings
        found = loop.diagnose(unit.diagram, unit.data, (), loop.DiagnoseSettings(max_iter=s.max_iter, alignment=s.alignment,
                                                                      seed=s.seed))
        accepted = found.report.get("accepted") or []
    except Exception as exc:  # noqa: BLE001 - the identification row stands; say why diagnosis failed
        return f"diagnose failed: {_message(exc)}"
    def name(a: dict) -> str:
        text = f"{a.get('effect')}@{a.get('at')}"
        label = a.get("label")  # the chosen option, e.g. "n=6" for a dead time
        return f"{text} ({label})" if label else text

    return "; ".join(name(a) for a in accepted) or "none"


def identify_file(unit: FileUnit) -> dict:
    """Identify one file and return its row (module-level: runs in any worker). Never raises for a bad file.

    Parameters
    ----------
    unit : FileUnit

    Returns
    -------
    dict
        Column -> value; ``status`` is the optimizer's status, "interrupted", or "error" with ``error`` set.
    """
    from ..identify import identify

    t0 = time.perf_counter()
    try:
        outcome = identify(unit.diagram, unit.data, None, unit.settings)
        row = _row_from_result(outcome, unit)
    except Exception as exc:  # noqa: BLE001 - a failed file is a row, never a lost run
        row = _error_row(unit.file, unit.sha256, unit.config, _message(exc))
    if unit.diagnose and row["status"] not in ("error", "interrupted"):
        row["effects"] = _effects(unit)
    row["seconds"] = time.perf_counter() - t0
    return row


def _existing(output: str, columns: Columns, config: str, force: bool) -> tuple[list[dict], int]:
    if force or not os.path.exists(output):
        return [], 0
    header, rows, dropped = read_results(output)
    if not header:
        return [], dropped
    other = {r.get("config") for r in rows} - {config}
    if tuple(header) != columns.names or other:
        raise SdnnError.at("BATCH002", "this results table holds results of another chart or other settings",
                           output, hint="write to another file, or add --force to start it over")
    last: dict[str, dict] = {}
    for r in rows:  # a file redone after a crash may appear twice in the journal: the later row wins
        last[r["file"]] = r
    return list(last.values()), dropped


@contextlib.contextmanager
def _exclusive(output: str):
    """Refuse a second batch writing the same table at the same time (POSIX advisory lock on OUTPUT.lock)."""
    try:
        import fcntl
    except ImportError:  # Windows: no advisory locks here; one run per table is the user's job
        yield
        return
    lock = f"{output}.lock"
    with open(lock, "w") as handle:
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            raise SdnnError.at("BATCH006", "another sdnn batch is writing this results table", output,
                               hint="wait for it, or write to another file") from None
        try:
            yield
        finally:
            with contextlib.suppress(OSError):
                os.remove(lock)


def run_batch(diagram: Diagram, files: Sequence[str], output: str, settings: BatchSettings = BatchSettings(),
              executor: Executor | None = None,
              progress: Callable[[int, int, dict | None], None] | None = None) -> BatchSummary:
    """Identify `diagram` on every file and keep the results table `output` up to date after each file.

    Parameters
    ----------
    diagram : Diagram
        The chart (with --fix-from already applied).
    files : sequence of str
        Data files (CSV), in the order to process them.
    output : str
        RESULTS.csv or RESULTS.parquet; created, or resumed when it exists.
    settings : BatchSettings
    executor : Executor, optional
        Where the fits run (:func:`flowchart2sdnn.executors.make_executor`); serial when None.
    progress : callable ``progress(done, total, row)``, optional
        Called after each file (``row`` None for a skipped file).

    Returns
    -------
    BatchSummary

    Raises
    ------
    SdnnError
        BATCH002 when `output` holds another configuration's results, BATCH005 when the workers died.
    KeyboardInterrupt
        After the rows finished so far are safely written.
    """
    with _exclusive(output):
        return _run(diagram, files, output, settings, executor or SerialExecutor(), progress)


def _run(diagram: Diagram, files: Sequence[str], output: str, settings: BatchSettings, executor: Executor,
         progress) -> BatchSummary:
    from ..identify import required_columns

    t0 = time.perf_counter()
    columns = columns_for(diagram.parameter_names, diagram.output_names, diagnose=settings.diagnose)
    config = config_key(diagram, settings)
    kept, dropped = _existing(output, columns, config, settings.force)
    by_file = {r["file"]: r for r in kept}
    by_sha = {r["sha256"]: r for r in kept if r.get("status") != "error" and r.get("sha256")}
    needed = required_columns(diagram)
    mapping = dict(settings.mapping)
    counts = {"identified": 0, "failed": 0, "skipped": 0, "copied": 0}
    total = len(files)
    done = 0
    writer = ResultsWriter(output, columns, kept)

    def record(row: dict | None, kind: str) -> None:
        nonlocal done
        done += 1
        counts[kind] += 1
        if row is not None:
            writer.append(row)
            if row.get("status") != "error" and row.get("sha256"):
                by_sha.setdefault(row["sha256"], row)
        if progress:
            progress(done, total, row)

    def prepare(file: str) -> FileUnit | None:
        sha = _sha256_file(file)
        old = by_file.get(file)
        if old is not None and sha is not None and old.get("sha256") == sha:
            if old.get("status") != "error" or not settings.retry_errors:
                record(None, "skipped")
                return None
        if sha is not None and sha in by_sha:
            record({**by_sha[sha], "file": file, "seconds": 0.0}, "copied")
            return None
        try:
            data = read_csv(file, needed, mapping, diagram.sample_time, scale=dict(settings.scales))
        except SdnnError as exc:
            record(_error_row(file, sha, config, _message(exc)), "failed")
            return None
        return FileUnit(file, data.sha256, diagram, data, settings.identify, config, columns, settings.diagnose)

    limit = 1 if executor.kind == "serial" else 2 * executor.workers
    pending = iter(files)
    inflight: dict = {}
    try:
        while True:
            while len(inflight) < limit:
                file = next(pending, None)
                if file is None:
                    break
                unit = prepare(file)
                if unit is None:
                    continue
                try:
                    inflight[executor.submit(identify_file, unit)] = unit
                except cf.BrokenExecutor:
                    raise SdnnError.at("BATCH005", f"the worker processes died (killed, or out of memory?) after "
                                       f"{done} of {total} files; rerun the same command to resume", output,
                                       hint="--retry-errors also redoes the files that were in progress") from None
            if not inflight:
                break
            future = next(iter(executor.as_completed(list(inflight))))
            unit = inflight.pop(future)
            try:
                row = executor.result(future)
            except Exception as exc:  # noqa: BLE001 - the worker died or could not run the unit
                row = _error_row(unit.file, unit.sha256, config, f"worker failed: {_message(exc)}")
            if row.get("status") == "interrupted":
                raise KeyboardInterrupt  # never record a half-done fit as done
            record(row, "failed" if row.get("status") == "error" else "identified")
    finally:
        for future in inflight:
            future.cancel()
        writer.close()
    return BatchSummary(output, total, counts["identified"], counts["failed"], counts["skipped"],
                        counts["copied"], dropped, time.perf_counter() - t0)
