"""Fleets: calibrate and diagnose many (unit, events) jobs, one machine or a Dask cluster.

A utility validating hundreds of units over many events describes each calibration as a
:class:`Job` (plain data: paths and numbers), runs them all with :func:`run_fleet` and gets one
row per job back, in the jobs' order, as a :class:`FleetResult` (``.rows``, ``.failed``,
``.to_pandas()``)::

    from dask.distributed import Client, LocalCluster
    from itaipu_calib.fleet import jobs_from_csv, run_fleet

    jobs = jobs_from_csv("fleet.csv")          # name, unit, events, held_out, calib, stages, ...
    with LocalCluster(n_workers=2, threads_per_worker=1) as cluster, Client(cluster) as client:
        result = run_fleet(jobs, client)       # one task per job
    result.to_pandas()                         # one row per job
    result.failed                              # the rows of the jobs that failed

The same code runs on a cluster with ``Client("tcp://scheduler:8786")``: every worker needs
the wheel installed and must see the job's paths (shared storage). Without a client the jobs
run one after another in this process, with the same rows.

* Each job runs :func:`itaipu_calib.fit` and, if asked, :func:`itaipu_calib.diagnose` of the
  calibrated unit (``fit=`` the fit, so the whole calibrated set is re-freed) in the worker.
  Every decision is the library's: the stage names (:func:`itaipu_calib.stages`), the search
  settings left None (:func:`itaipu_calib.defaults`, or the calibration spec's), the reports
  and the files written.
* A job that fails (a bad file, a unit that cannot initialise, a worker that died) is a row
  with ``status == "failed"``, the step it failed in, the error's type, ``kind`` and message on
  one line; the other jobs go on.
* Each job's Rust worker pool is sized so that the jobs do not oversubscribe the cores
  (``threads_per_job``; by default, with a client, the cores of each host shared among the
  Dask worker threads on it). The numbers do not depend on it: same seed, same J.
* ``Job.out`` is a folder for the job's results, written by the library's writers, after the
  work::

      out/fit/        FitResult.write: what ``itaipu-calib fit --out`` writes (report.json,
                      calibrated.toml, datasheet.toml, calibration.toml, a folder per stage,
                      manifest.json last), without plots or HTML
      out/diagnose/   Diagnosis.write, when diagnosed: what ``itaipu-calib diagnose --out``
                      writes (diagnosis.json, extended.toml when a cause is named,
                      warnings.json, manifest.json last), without plots or HTML
      out/row.json    the job's row, last (a temporary name, then a rename)

  The job's folder is complete if and only if it holds ``row.json``; each sub-folder is
  complete if and only if it holds its ``manifest.json`` (each comes through a temporary folder
  renamed into place). Without ``overwrite`` a job whose folder already holds any of them fails
  before the work and replaces nothing; with ``overwrite=True`` ``row.json`` goes first, then
  the sub-folders are replaced whole (only folders of ours: the library's rule).
* :func:`run_fleet` shows its progress on stderr (jobs done / total, failures so far, elapsed
  time) when stderr is a terminal, or as asked by ``progress=``.

Dask (``pip install dask distributed`` or ``'itaipu-calib[fleet]'``) is needed only by the
client; this module imports without it.
"""

from __future__ import annotations

import csv
import importlib
import json
import math
import os
import shutil
import socket
import sys
import threading
import time
import uuid
import warnings
from dataclasses import InitVar, dataclass, field
from pathlib import Path
from typing import Any, Callable, Dict, Iterable, Iterator, List, Optional, TextIO, Tuple, Union

from . import _core

__all__ = ["COLUMNS", "FleetResult", "Job", "jobs_from_csv", "run_fleet", "run_job"]

_PathLike = Union[str, "os.PathLike[str]"]
_Row = Dict[str, Any]

#: The columns of a row, in order (see :func:`run_job`).
COLUMNS: Tuple[str, ...] = (
    "job",
    "status",
    "step",
    "error_type",
    "error_kind",
    "error",
    "stages",
    "n_events",
    "n_held_out",
    "seed",
    "j_start",
    "j_fit",
    "j_held_out",
    "cause",
    "delta_bic",
    "fit_drop",
    "held_drop",
    "key_parameters",
    "out",
    "threads",
    "host",
    "pid",
    "wall_s",
)

# A job's folder: the fit's folder (FitResult.write), the diagnosis' (Diagnosis.write), and the
# row, written last: the job's folder is complete if and only if it holds row.json.
_FIT_DIR = "fit"
_DIAGNOSE_DIR = "diagnose"
_ROW_FILE = "row.json"


def _stage_names() -> Tuple[str, ...]:
    """The library's stage names, in the order they run, then ``all``
    (:func:`itaipu_calib.stages`; asked each time: it is cheap)."""
    return tuple(_core.stages())


def _stage_choices() -> str:
    names = _stage_names()
    return ", ".join(names[:-1]) + " or " + names[-1] if len(names) > 1 else ", ".join(names)


def _stages(value: Any, what: str) -> Tuple[str, ...]:
    """The stages named in ``value`` (a string or a list of names), checked against the
    library's list; ``()`` when none is named. ValueError naming the first unknown one."""
    names = _names(value, what)
    bad = [n for n in names if n not in _stage_names()]
    if bad:
        raise ValueError(f"{what}: unknown stage {bad[0]!r} ({_stage_choices()})")
    return names


def _stage_text(names: Tuple[str, ...]) -> str:
    """``all``, or the named stages comma-separated in the order they run."""
    if "all" in names:
        return "all"
    return ",".join(s for s in _stage_names() if s in names)


def _renamed(old: str, new: str, old_value: Any, new_value: Any, where: str,
             stacklevel: int) -> Any:
    """The value of an option given under its old name (a DeprecationWarning, as the module's
    functions give) or its new one; TypeError when both are given."""
    if old_value is None:
        return new_value
    if new_value is not None:
        raise TypeError(f"{where}{new} and {old} (its old name) were both given: give {new} only")
    warnings.warn(
        f"{old} is deprecated: it is now {new} (it caps the local method, Levenberg-Marquardt "
        "or L-BFGS)",
        DeprecationWarning,
        stacklevel=stacklevel + 1,
    )
    return old_value


def _paths(value: Any, what: str) -> Tuple[str, ...]:
    if value is None:
        return ()
    if isinstance(value, (str, os.PathLike)):
        return (os.fspath(value),)
    try:
        items = list(value)
    except TypeError:
        raise TypeError(f"{what} must be a path or a list of paths (got {value!r})") from None
    out = []
    for v in items:
        if not isinstance(v, (str, os.PathLike)):
            raise TypeError(f"{what} must be a path or a list of paths (got {v!r} in it)")
        out.append(os.fspath(v))
    return tuple(out)


def _names(value: Any, what: str) -> Tuple[str, ...]:
    """A comma/semicolon/plus-separated string or a list of names, as a tuple of names."""
    if isinstance(value, str):
        parts = value.replace(";", ",").replace("+", ",").split(",")
    else:
        try:
            parts = [str(v) for v in value]
        except TypeError:
            raise TypeError(f"{what} must be a string or a list of names (got {value!r})") from None
    return tuple(p.strip() for p in parts if p.strip())


def _check_int(value: Any, what: str, minimum: int) -> None:
    if value is None:
        return
    if isinstance(value, bool) or not isinstance(value, int):
        raise TypeError(f"{what} must be an integer (got {value!r})")
    if value < minimum:
        raise ValueError(f"{what} must be at least {minimum} (got {value})")


@dataclass(frozen=True)
class Job:
    """One calibration (and optionally diagnosis) of a unit on some events: plain, picklable
    data (paths and numbers), so that it travels to a Dask worker.

    ``unit``, ``events``, ``held_out``, ``calib`` and ``out`` are paths (``events`` and
    ``held_out`` a path or a list of paths), stored as strings; they are read in the worker, so
    on a cluster they must be visible there. ``stages`` (names of :func:`itaipu_calib.stages`),
    ``seed``, ``particles``, ``pso_iterations``, ``local_iterations`` and ``polish`` are
    :func:`itaipu_calib.fit`'s; None leaves the choice to the library (the calibration spec's,
    else ``itaipu_calib.defaults()["fit"]``; ``polish``: the final joint pass).
    ``diagnose=True`` diagnoses the calibrated unit after the fit (``causes``: the causes to
    try, default the whole catalog; ``seed`` and ``diagnose_particles``,
    ``diagnose_pso_iterations``, ``diagnose_local_iterations``: the re-fits' settings, None:
    ``itaipu_calib.defaults()["diagnose"]``). ``out``: a folder for the job's files
    (``fit/``, ``diagnose/``, ``row.json``: see :mod:`itaipu_calib.fleet`); ``overwrite=True``
    lets them replace an earlier run's.

    ``lbfgs_iterations`` and ``diagnose_lbfgs_iterations`` are the old names of
    ``local_iterations`` and ``diagnose_local_iterations``: still accepted, with a
    DeprecationWarning.
    """

    name: str
    unit: str
    events: Tuple[str, ...]
    held_out: Tuple[str, ...] = ()
    calib: Optional[str] = None
    stages: str = "all"
    seed: Optional[int] = None
    particles: Optional[int] = None
    pso_iterations: Optional[int] = None
    local_iterations: Optional[int] = None
    polish: Optional[bool] = None
    diagnose: bool = False
    causes: Optional[Tuple[str, ...]] = None
    diagnose_particles: Optional[int] = None
    diagnose_pso_iterations: Optional[int] = None
    diagnose_local_iterations: Optional[int] = None
    out: Optional[str] = None
    overwrite: bool = False
    # The old names (deprecated): not fields, folded into the new ones.
    lbfgs_iterations: InitVar[Optional[int]] = None
    diagnose_lbfgs_iterations: InitVar[Optional[int]] = None

    def __post_init__(self, lbfgs_iterations: Optional[int],
                      diagnose_lbfgs_iterations: Optional[int]) -> None:
        def put(name: str, value: Any) -> None:
            object.__setattr__(self, name, value)

        if not isinstance(self.name, str) or not self.name.strip():
            raise ValueError(f"Job.name must be a non-empty string (got {self.name!r})")
        # stacklevel 3: the warning points at the Job(...) call (through __init__).
        put("local_iterations", _renamed("lbfgs_iterations", "local_iterations",
                                         lbfgs_iterations, self.local_iterations,
                                         f"Job {self.name}: ", 3))
        put("diagnose_local_iterations", _renamed(
            "diagnose_lbfgs_iterations", "diagnose_local_iterations", diagnose_lbfgs_iterations,
            self.diagnose_local_iterations, f"Job {self.name}: ", 3))
        if not isinstance(self.unit, (str, os.PathLike)):
            raise TypeError(f"Job {self.name}: unit must be a path (got {self.unit!r})")
        put("unit", os.fspath(self.unit))
        put("events", _paths(self.events, f"Job {self.name}: events"))
        if not self.events:
            raise ValueError(f"Job {self.name}: events is empty")
        put("held_out", _paths(self.held_out, f"Job {self.name}: held_out"))
        for key in ("calib", "out"):
            v = getattr(self, key)
            if v is not None:
                if not isinstance(v, (str, os.PathLike)):
                    raise TypeError(f"Job {self.name}: {key} must be a path or None (got {v!r})")
                put(key, os.fspath(v))
        stages = _stages(self.stages, f"Job {self.name}: stages")
        if not stages:
            raise ValueError(f"Job {self.name}: stages is empty")
        put("stages", _stage_text(stages))
        _check_int(self.seed, f"Job {self.name}: seed", 0)
        _check_int(self.particles, f"Job {self.name}: particles", 2)
        _check_int(self.diagnose_particles, f"Job {self.name}: diagnose_particles", 2)
        for key in ("pso_iterations", "local_iterations", "diagnose_pso_iterations",
                    "diagnose_local_iterations"):
            _check_int(getattr(self, key), f"Job {self.name}: {key}", 0)
        if self.polish is not None and not isinstance(self.polish, bool):
            raise TypeError(f"Job {self.name}: polish must be True, False or None")
        for key in ("diagnose", "overwrite"):
            if not isinstance(getattr(self, key), bool):
                raise TypeError(f"Job {self.name}: {key} must be True or False")
        if self.causes is not None:
            put("causes", _names(self.causes, f"Job {self.name}: causes") or None)
            if not self.diagnose:
                raise ValueError(f"Job {self.name}: causes given but diagnose is False")


def _old_name(old: str, new: str) -> property:
    def get(self: Job) -> Optional[int]:
        warnings.warn(f"Job.{old} is deprecated: it is now Job.{new}", DeprecationWarning,
                      stacklevel=2)
        value: Optional[int] = getattr(self, new)
        return value

    return property(get, doc=f"The old name of :attr:`{new}` (deprecated).")


# Reading an old name gives the new field, with a warning (the InitVars' defaults are already
# in __init__).
for _old, _new in (("lbfgs_iterations", "local_iterations"),
                   ("diagnose_lbfgs_iterations", "diagnose_local_iterations")):
    setattr(Job, _old, _old_name(_old, _new))
del _old, _new


def _one_line(e: BaseException) -> str:
    text = " ".join(str(e).split())
    return text or type(e).__name__


def _empty_row(job: Job) -> Dict[str, Any]:
    row: Dict[str, Any] = dict.fromkeys(COLUMNS)
    row["job"] = job.name
    row["status"] = "failed"
    return row


def _failed_row(job: Job, e: BaseException, step: str) -> Dict[str, Any]:
    row = _empty_row(job)
    row.update(step=step, error_type=type(e).__name__, error_kind=getattr(e, "kind", None),
               error=_one_line(e))
    return row


def _fill_fit(row: Dict[str, Any], fit: _core.FitResult) -> None:
    rep = fit.report
    fitness = fit.fitness
    row["stages"] = ",".join(fit.stages)
    row["n_events"] = len(rep["events"])
    row["n_held_out"] = len(rep["held_out"])
    row["seed"] = rep["seed"]
    row["threads"] = rep["threads"]
    row["j_start"] = fitness[0][1]
    row["j_fit"] = fitness[-1][1]
    if rep["held_out"] and rep["stages"]:
        row["j_held_out"] = sum(f["j_pq"] for f in rep["stages"][-1]["fitness"] if f["held_out"])


def _fill_diagnosis(row: Dict[str, Any], d: _core.Diagnosis) -> None:
    v = d.verdict
    row["cause"] = d.cause
    gains = v.get("gains") or {}
    for key in ("delta_bic", "fit_drop", "held_drop"):
        row[key] = gains.get(key)
    row["key_parameters"] = {p[0]: p[1] for p in v.get("key_parameters") or []}


def _json(value: Any) -> str:
    def clean(x: Any) -> Any:
        if isinstance(x, float) and not math.isfinite(x):
            return None
        if isinstance(x, dict):
            return {k: clean(v) for k, v in x.items()}
        if isinstance(x, (list, tuple)):
            return [clean(v) for v in x]
        return x

    return json.dumps(clean(value), indent=2, allow_nan=False) + "\n"


def _check_out(job: Job) -> Path:
    """Creates the job's folder and checks, before any computation, that it is writable and
    that the job may write its files there: without ``overwrite``, none of them exists (an
    empty folder is no result); with it, each sub-folder to replace is one of ours (the
    library's rule, as ``fit --out --force``)."""
    assert job.out is not None
    out = Path(job.out)
    if out.exists() and not out.is_dir():
        raise FileExistsError(f"{out} exists and is not a folder")
    out.mkdir(parents=True, exist_ok=True)
    for name in (_ROW_FILE, _FIT_DIR, _DIAGNOSE_DIR):
        p = out / name
        if not job.overwrite:
            if p.exists() and not (p.is_dir() and not any(p.iterdir())):
                raise FileExistsError(
                    f"{p} exists: not overwritten (Job(..., overwrite=True) replaces the job's "
                    "files, or give the job another out folder)"
                )
        elif name != _ROW_FILE:
            _core._check_out(p, True)
        elif p.is_dir():
            raise FileExistsError(f"{p} is a folder: not replaced")
    probe = out / f".fleet-probe-{os.getpid()}-{uuid.uuid4().hex[:8]}"
    probe.write_text("")
    probe.unlink()
    return out


def _commit(tmp: Path, final: Path, overwrite: bool) -> None:
    """Renames ``tmp`` to ``final``; without ``overwrite``, never over an existing file."""
    if overwrite:
        os.replace(tmp, final)
        return
    try:
        os.link(tmp, final)  # atomic, and fails if final exists
    except FileExistsError:
        raise FileExistsError(f"{final} appeared while the job ran: not overwritten") from None
    except OSError:  # no hard links on this file system
        if final.exists():
            raise FileExistsError(f"{final} appeared while the job ran: not overwritten") from None
        os.replace(tmp, final)
        return
    tmp.unlink()


def _write_row(out: Path, row: _Row, overwrite: bool) -> None:
    """Writes ``row.json`` through a temporary name then a rename (the job's folder is then
    complete); no temporary file is left, whatever happens."""
    tmp = out / f".{_ROW_FILE}.partial-{os.getpid()}-{uuid.uuid4().hex[:8]}"
    try:
        with open(tmp, "w", encoding="utf-8", newline="\n") as f:
            f.write(_json(row))
            f.flush()
            os.fsync(f.fileno())
        _commit(tmp, out / _ROW_FILE, overwrite)
    finally:
        if tmp.exists():
            tmp.unlink()


def _write_out(out: Path, job: Job, fit: _core.FitResult, diagnosis: Optional[_core.Diagnosis],
               row: _Row) -> None:
    """Writes the job's folder after the work: ``fit/`` and ``diagnose/`` by the library's
    writers (each through a temporary folder renamed into place, manifest.json last), then
    ``row.json``. With ``overwrite``, the earlier ``row.json`` goes first (the folder is
    incomplete until the new one is in), and an earlier ``diagnose/`` that this job does not
    write is removed."""
    if job.overwrite and (out / _ROW_FILE).exists():
        (out / _ROW_FILE).unlink()
    fit.write(out / _FIT_DIR, overwrite=job.overwrite)
    if diagnosis is not None:
        diagnosis.write(out / _DIAGNOSE_DIR, overwrite=job.overwrite)
    elif job.overwrite and (out / _DIAGNOSE_DIR).exists():
        _core._check_out(out / _DIAGNOSE_DIR, True)  # ours (checked before the work too)
        shutil.rmtree(out / _DIAGNOSE_DIR)
    _write_row(out, row, job.overwrite)


def run_job(job: Job, *, threads: Optional[int] = None) -> _Row:
    """Runs one job in this process and returns its row (a dict with the keys of
    :data:`COLUMNS`). It never raises for a failing job (only for KeyboardInterrupt).

    * ``job``, ``status`` (``"ok"`` or ``"failed"``); when failed, ``step`` (``"output"``: the
      folder check, ``"fit"``, ``"diagnose"``, ``"write"``; ``"worker"`` from
      :func:`run_fleet` when the task itself failed), ``error_type`` (e.g.
      ``"UnitModelError"``), ``error_kind`` (the :class:`~itaipu_calib.ItaipuError`'s
      ``kind``, or None) and ``error`` (the message on one line);
    * the fit: ``stages`` (run, comma-separated), ``n_events`` (fitted), ``n_held_out``,
      ``seed``, ``j_start`` and ``j_fit`` (J = Σ(ΔP² + ΔQ²) over the fitted events, of the
      starting and of the calibrated unit: ``FitResult.fitness[0]`` and ``[-1]``),
      ``j_held_out`` (J of the calibrated unit over the held-out events, or None);
    * the diagnosis (None without): ``cause`` (a cause id, ``none`` or ``unexplained``),
      ``delta_bic``, ``fit_drop``, ``held_drop`` (the named cause's gains) and
      ``key_parameters`` ({parameter: value} of the named cause);
    * ``out`` (the job's folder, when written), ``threads`` (the fit's worker threads),
      ``host``, ``pid``, ``wall_s``.

    ``threads``: the worker threads of the fit and the diagnosis (None: all cores, or
    ``RAYON_NUM_THREADS``). With ``job.out``, the folder is checked before the work and written
    after it (see :mod:`itaipu_calib.fleet`); a job that fails writes no ``row.json``.
    """
    t0 = time.perf_counter()
    row = _empty_row(job)
    row["host"] = socket.gethostname()
    row["pid"] = os.getpid()
    step = "output"
    try:
        out = _check_out(job) if job.out is not None else None
        step = "fit"
        fit_kw: Dict[str, Any] = {}
        if job.polish is not None:
            fit_kw["polish"] = job.polish
        fit = _core.fit(
            list(job.events),
            job.unit,
            calib=job.calib,
            stages=job.stages,
            seed=job.seed,
            particles=job.particles,
            pso_iterations=job.pso_iterations,
            local_iterations=job.local_iterations,
            held_out=list(job.held_out),
            threads=threads,
            **fit_kw,
        )
        _fill_fit(row, fit)
        diagnosis = None
        if job.diagnose:
            step = "diagnose"
            diagnosis = _core.diagnose(
                list(job.events),
                held_out=list(job.held_out) or None,
                causes=list(job.causes) if job.causes else None,
                seed=job.seed,
                particles=job.diagnose_particles,
                pso_iterations=job.diagnose_pso_iterations,
                local_iterations=job.diagnose_local_iterations,
                threads=threads,
                fit=fit,
            )
            _fill_diagnosis(row, diagnosis)
        if out is not None:
            step = "write"
            row["out"] = str(out)
            row["status"] = "ok"
            row["wall_s"] = time.perf_counter() - t0
            _write_out(out, job, fit, diagnosis, row)
        row["status"] = "ok"
    except Exception as e:
        if row["status"] == "ok":  # failed while writing
            row["out"] = None
        row.update(status="failed", step=step, error_type=type(e).__name__,
                   error_kind=getattr(e, "kind", None), error=_one_line(e))
    row["wall_s"] = time.perf_counter() - t0
    return row


@dataclass
class FleetResult:
    """The rows of a fleet, one per job, in the jobs' order (see :func:`run_job` for a row's
    keys)."""

    rows: List[Dict[str, Any]] = field(default_factory=list)

    @property
    def ok(self) -> List[Dict[str, Any]]:
        """The rows of the jobs that succeeded."""
        return [r for r in self.rows if r["status"] == "ok"]

    @property
    def failed(self) -> List[Dict[str, Any]]:
        """The rows of the jobs that failed."""
        return [r for r in self.rows if r["status"] != "ok"]

    def __len__(self) -> int:
        return len(self.rows)

    def __iter__(self) -> Iterator[Dict[str, Any]]:
        return iter(self.rows)

    def __getitem__(self, name: str) -> Dict[str, Any]:
        """The row of the job called ``name``."""
        for r in self.rows:
            if r["job"] == name:
                return r
        raise KeyError(name)

    def to_pandas(self) -> Any:
        """The rows as a pandas DataFrame, one row per job in the jobs' order, the columns of
        :data:`COLUMNS` (needs pandas)."""
        try:
            pd = importlib.import_module("pandas")  # (pandas ships no type information)
        except ImportError as e:
            raise ImportError(
                "FleetResult.to_pandas() needs pandas, which is not installed: pip install pandas "
                "(or pip install 'itaipu-calib[pandas]')"
            ) from e
        return pd.DataFrame(self.rows, columns=list(COLUMNS))

    def __repr__(self) -> str:
        failed = self.failed
        text = f"FleetResult({len(self.rows)} jobs: {len(self.rows) - len(failed)} ok, {len(failed)} failed"
        if failed:
            shown = ", ".join(
                f"{r['job']} ({r['error_type']}"
                + (f" {r['error_kind']}" if r["error_kind"] else "")
                + f" in {r['step']})"
                for r in failed[:5]
            )
            text += ": " + shown + (", ..." if len(failed) > 5 else "")
        return text + ")"


def _cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not Linux
        return os.cpu_count() or 1


def _probe(dask_worker: Any) -> Tuple[str, int, int]:
    """Run on every worker by ``client.run``: its host, cores and Dask threads."""
    return socket.gethostname(), _cores(), int(dask_worker.state.nthreads)


def _threads_by_host(client: Any) -> Dict[str, int]:
    """The Rust threads per job on each host: the host's cores shared among the Dask worker
    threads on it (at least 1)."""
    cores: Dict[str, int] = {}
    dask_threads: Dict[str, int] = {}
    for host, n, nthreads in client.run(_probe).values():
        cores[host] = n
        dask_threads[host] = dask_threads.get(host, 0) + nthreads
    return {h: max(1, cores[h] // max(1, dask_threads[h])) for h in cores}


def _run_task(job: Job, threads: Optional[int], by_host: Dict[str, int]) -> Dict[str, Any]:
    """The task a worker runs: :func:`run_job` with the threads of its host."""
    if threads is None:
        threads = by_host.get(socket.gethostname(), 1)
    return run_job(job, threads=threads)


def _clock(seconds: float) -> str:
    """Elapsed time as m:ss or h:mm:ss."""
    s = int(max(0.0, seconds))
    h, rest = divmod(s, 3600)
    m, s = divmod(rest, 60)
    return f"{h}:{m:02d}:{s:02d}" if h else f"{m}:{s:02d}"


def _is_terminal(stream: Any) -> bool:
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):  # no isatty, or closed
        return False


class _Progress:
    """A fleet's progress on a stream (stderr): jobs done / total, failures so far, elapsed
    time, and the last job finished. On a terminal one line, rewritten in place and refreshed
    every second (the clock runs while a long job does); elsewhere one line per finished job."""

    def __init__(self, total: int, stream: TextIO) -> None:
        self.total = total
        self.stream = stream
        self.live = _is_terminal(stream)
        self.done = 0
        self.failed = 0
        self.last: Optional[_Row] = None
        self.t0 = time.monotonic()
        self._width = 0
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._ticker: Optional[threading.Thread] = None
        if self.live:
            self._show()
            self._ticker = threading.Thread(target=self._tick, name="itaipu-fleet-progress",
                                            daemon=True)
            self._ticker.start()

    def line(self) -> str:
        text = (f"fleet: {self.done}/{self.total} jobs done, {self.failed} failed, "
                f"{_clock(time.monotonic() - self.t0)} elapsed")
        r = self.last
        if r is not None:
            text += f"; last: {r.get('job')} {r.get('status')}"
            if r.get("status") != "ok":
                text += f" ({r.get('error_type')} in {r.get('step')})"
        return text

    def _show(self) -> None:
        text = self.line()
        try:
            if self.live:
                self.stream.write("\r" + text + " " * max(0, self._width - len(text)))
                self._width = len(text)
            else:
                self.stream.write(text + "\n")
            self.stream.flush()
        except (OSError, ValueError):  # a closed or broken stream: no progress, the fleet goes on
            pass

    def _tick(self) -> None:
        while not self._stop.wait(1.0):
            with self._lock:
                self._show()

    def __call__(self, row: _Row) -> None:
        with self._lock:
            self.done += 1
            if row.get("status") != "ok":
                self.failed += 1
            self.last = row
            self._show()

    def close(self) -> None:
        self._stop.set()
        if self._ticker is not None:
            self._ticker.join()
        if self.live:
            try:
                self.stream.write("\n")
                self.stream.flush()
            except (OSError, ValueError):
                pass


_ProgressArg = Union[bool, None, Callable[[_Row], Any]]


def _progress_sinks(progress: _ProgressArg, on_row: Optional[Callable[[_Row], Any]],
                    total: int) -> Tuple[List[Callable[[_Row], Any]], Optional[_Progress]]:
    """What receives each finished row: the progress display on stderr (``progress`` True, or
    None with stderr a terminal), a callable given as ``progress``, and ``on_row``."""
    sinks: List[Callable[[_Row], Any]] = []
    display: Optional[_Progress] = None
    if progress is None:
        progress = _is_terminal(sys.stderr)
    if progress is True:
        display = _Progress(total, sys.stderr)
        sinks.append(display)
    elif progress is not False:
        if not callable(progress):
            raise TypeError("progress must be True, False, None (True when stderr is a "
                            f"terminal) or a callable taking a row (got {progress!r})")
        sinks.append(progress)
    if on_row is not None:
        sinks.append(on_row)
    return sinks, display


def run_fleet(
    jobs: Iterable[Job],
    client: Any = None,
    *,
    threads_per_job: Optional[int] = None,
    progress: _ProgressArg = None,
    on_row: Optional[Callable[[_Row], Any]] = None,
) -> FleetResult:
    """Runs every job and returns their rows, in the jobs' order.

    With ``client`` (a ``dask.distributed.Client``) each job is one task; rows are gathered as
    they complete, and a task that fails outside :func:`run_job` (a worker that died, a job
    that cannot be unpickled, a cancelled task) becomes a failed row with ``step ==
    "worker"``: it never stops the others. Without a client the jobs run one after another in
    this process (the same rows).

    ``threads_per_job``: the Rust worker threads of each job. Default: with a client, each
    host's cores divided among the Dask worker threads on it (so that 2 workers of 1 thread on
    2 cores run 1 thread each); without, all cores. The numbers do not depend on it.

    ``progress``: True shows the progress on stderr (jobs done / total, failures so far,
    elapsed time, the last job finished: one line rewritten in place on a terminal, refreshed
    every second, else one line per job); False shows nothing; None (the default) is True when
    stderr is a terminal. A callable is called with each job's row as it finishes instead
    (in completion order), as is ``on_row`` in any case. KeyboardInterrupt cancels the jobs
    not yet finished.
    """
    jobs = list(jobs)
    for j in jobs:
        if not isinstance(j, Job):
            raise TypeError(f"run_fleet takes Job objects (got {type(j).__name__})")
    seen: Dict[str, int] = {}
    for i, j in enumerate(jobs):
        if j.name in seen:
            raise ValueError(f"two jobs are called {j.name!r} (jobs {seen[j.name]} and {i})")
        seen[j.name] = i
    _check_int(threads_per_job, "threads_per_job", 1)
    sinks, display = _progress_sinks(progress, on_row, len(jobs))

    def finished(row: _Row) -> None:
        for sink in sinks:
            sink(row)

    try:
        if client is None:
            rows = []
            for job in jobs:
                row = run_job(job, threads=threads_per_job)
                rows.append(row)
                finished(row)
            return FleetResult(rows)
        return _run_on_client(jobs, client, threads_per_job, finished)
    finally:
        if display is not None:
            display.close()


def _run_on_client(jobs: List[Job], client: Any, threads_per_job: Optional[int],
                   finished: Callable[[_Row], None]) -> FleetResult:
    """:func:`run_fleet` on a Dask client: one task per job."""
    from distributed import as_completed  # a client means distributed is installed

    by_host = _threads_by_host(client) if threads_per_job is None else {}
    token = uuid.uuid4().hex[:12]
    futures = [
        client.submit(_run_task, job, threads_per_job, by_host,
                      key=f"itaipu-fleet-{token}-{i}-{job.name}", pure=False)
        for i, job in enumerate(jobs)
    ]
    index = {f.key: i for i, f in enumerate(futures)}
    slots: List[Optional[_Row]] = [None] * len(jobs)
    try:
        for fut in as_completed(futures):
            i = index[fut.key]
            try:
                row = fut.result()
                if not isinstance(row, dict):
                    raise TypeError(f"the task returned {type(row).__name__}, not a row")
            except (KeyboardInterrupt, SystemExit):
                raise
            except BaseException as e:  # CancelledError is not an Exception
                row = _failed_row(jobs[i], e, "worker")
            slots[i] = row
            fut.release()
            finished(row)
    finally:
        pending = [f for f in futures if not f.done()]
        if pending:
            client.cancel(pending)
    return FleetResult([r for r in slots if r is not None])


# -------------------------------------------------------------------------------------------
# Job tables
# -------------------------------------------------------------------------------------------

_REQUIRED = ("name", "unit", "events")
_OPTIONAL = ("held_out", "calib", "stages", "seed", "diagnose", "particles", "pso_iterations",
             "local_iterations", "out")
# Old column names still read (a DeprecationWarning): {old: new}.
_RENAMED = {"lbfgs_iterations": "local_iterations"}
_NO = ("", "no", "false", "0", "n")
_YES = ("yes", "true", "1", "y", "all")


def jobs_from_csv(path: _PathLike, *, overwrite: bool = False) -> List[Job]:
    """Reads a job table, a CSV file a utility keeps next to its data, into :class:`Job`\\ s.

    Columns (a header line first; the order is free): ``name``, ``unit``, ``events`` (paths
    separated by ``;``) are required; ``held_out`` (paths separated by ``;``), ``calib``,
    ``stages`` (e.g. ``gen+avr`` or ``all``; default all), ``seed``, ``diagnose`` (empty or
    ``no``: no diagnosis; ``yes``: the whole catalog; or cause ids separated by ``;``),
    ``particles``, ``pso_iterations``, ``local_iterations`` (old name ``lbfgs_iterations``:
    still read, with a DeprecationWarning) and ``out`` (a folder for the job's files) are
    optional; an empty cell leaves the choice to the library. Paths are relative to the table's
    folder. Blank lines and lines starting with ``#`` are skipped. ``overwrite`` is given to
    every job.

    A bad table raises ``ValueError`` naming the file, the line and the column (an unknown
    column, a missing one, a bad number, an unknown stage or cause, two jobs with one name).
    Files are not opened here: a missing unit file fails that job only, when it runs.
    """
    path = Path(path)
    base = path.resolve().parent

    def fail(line: int, col: Optional[str], what: str) -> ValueError:
        where = f"{path}, line {line}" + (f", column {col}" if col else "")
        return ValueError(f"{where}: {what}")

    def resolve(p: str) -> str:
        q = Path(p).expanduser()
        return str(q if q.is_absolute() else base / q)

    known_causes: Optional[List[str]] = None
    jobs: List[Job] = []
    names: Dict[str, int] = {}
    header: Optional[List[str]] = None
    label: Dict[str, str] = {}  # a column's name in the table (an old name, renamed)
    with open(path, newline="", encoding="utf-8-sig") as f:
        reader = csv.reader(f)
        last = 0
        for cells in reader:
            line, last = last + 1, reader.line_num
            cells = [c.strip() for c in cells]
            if not any(cells) or cells[0].startswith("#"):
                continue
            if header is None:
                header = [c.lower() for c in cells]
                for old, new in _RENAMED.items():
                    if old in header:
                        if new in header:
                            raise fail(line, old, f"the old name of column {new}, which is "
                                       "there too: keep one")
                        warnings.warn(f"{path}: column {old} is deprecated: it is now {new}",
                                      DeprecationWarning, stacklevel=2)
                        header[header.index(old)] = new
                        label[new] = old
                for c in header:
                    if c not in _REQUIRED + _OPTIONAL:
                        raise fail(line, c or "(empty)", "unknown column (columns: "
                                   + ", ".join(_REQUIRED + _OPTIONAL) + ")")
                    if header.count(c) > 1:
                        raise fail(line, c, "the column appears twice")
                for c in _REQUIRED:
                    if c not in header:
                        raise fail(line, c, "missing column (required: name, unit, events)")
                continue
            if len(cells) != len(header):
                raise fail(line, None, f"{len(cells)} cells, the header has {len(header)}")
            row = dict(zip(header, cells))

            def integer(col: str, minimum: int) -> Optional[int]:
                text = row.get(col, "")
                if not text:
                    return None
                try:
                    n = int(text)
                except ValueError:
                    raise fail(line, label.get(col, col), f"not an integer: {text!r}") from None
                if n < minimum:
                    raise fail(line, label.get(col, col), f"must be at least {minimum} (got {n})")
                return n

            def listed(col: str) -> List[str]:
                return [p.strip() for p in row.get(col, "").split(";") if p.strip()]

            name = row["name"]
            if not name:
                raise fail(line, "name", "empty")
            if name in names:
                raise fail(line, "name", f"{name!r} is already the name of line {names[name]}")
            names[name] = line
            if not row["unit"]:
                raise fail(line, "unit", "empty")
            events = listed("events")
            if not events:
                raise fail(line, "events", "no event (paths separated by ';')")
            try:
                stages = _stages(row.get("stages", ""), "stages") or ("all",)
            except ValueError as e:
                raise fail(line, "stages", str(e).split(": ", 1)[1]) from None
            diag_text = row.get("diagnose", "")
            causes: Optional[List[str]] = None
            if diag_text.lower() in _NO:
                diagnose = False
            elif diag_text.lower() in _YES:
                diagnose = True
            else:
                diagnose = True
                causes = [c.strip() for c in diag_text.replace(",", ";").split(";") if c.strip()]
                if known_causes is None:
                    known_causes = [c["id"] for c in _core.causes()]
                for c in causes:
                    if c not in known_causes:
                        raise fail(line, "diagnose", f"unknown cause {c!r} (yes, no, or causes "
                                   "separated by ';': " + ", ".join(known_causes) + ")")
            spec: Dict[str, Any] = dict(
                name=name,
                unit=resolve(row["unit"]),
                events=tuple(resolve(e) for e in events),
                held_out=tuple(resolve(e) for e in listed("held_out")),
                calib=resolve(row["calib"]) if row.get("calib") else None,
                stages=_stage_text(stages),
                seed=integer("seed", 0),
                particles=integer("particles", 2),
                pso_iterations=integer("pso_iterations", 0),
                local_iterations=integer("local_iterations", 0),
                diagnose=diagnose,
                causes=tuple(causes) if causes else None,
                out=resolve(row["out"]) if row.get("out") else None,
                overwrite=overwrite,
            )
            try:
                jobs.append(Job(**spec))
            except (TypeError, ValueError) as e:  # pragma: no cover - every cell checked above
                raise fail(line, None, str(e)) from None
    if header is None:
        raise ValueError(f"{path}: no header line (columns name, unit, events, ...)")
    return jobs
