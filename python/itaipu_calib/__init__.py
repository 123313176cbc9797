"""Playback simulation and calibration of generating-unit models against PMU recordings.

``itaipu_calib`` plays the measured terminal-voltage phasor of an *event* (a PMU recording,
described by a TOML file that names a CSV) into a *unit* model (machine, exciter, stabiliser,
governor; a TOML unit file) and records the simulated response next to the measured one.

Quick start::

    import itaipu_calib as ic
    tr = ic.simulate("data/itaipu/event.toml", "data/itaipu/unit.toml")
    tr.time_s, tr.p_pu, tr.p_meas_pu          # numpy float64 arrays, one value per sample

Units and conventions
---------------------
* Time in seconds (``time_s``), on the time axis of the recording.
* ``p_pu``, ``q_pu`` (simulated) and ``p_meas_pu``, ``q_meas_pu`` (measured) are per unit on the
  event's **system** base (``Event.system_mva``), generator convention (power out > 0).
* Signals of the unit (``pe``, ``qe``, ``te``, ``efd``, ``pm``, ``speed``, ``vs``, ...) are per
  unit on the **machine** base (``Unit.machine_mva``); ``p_mach_pu``/``q_mach_pu`` are ``pe``/``qe``.
  ``speed`` is the per-unit speed deviation.
* Angles (``v_ang_rad``, ``theta_term``, ``delta``) are in radians, in the PMU's rotating frame at
  the nominal frequency; the measured angle is unwrapped.
* ``v_term``/``v_mag_pu`` is |V| in pu of rated voltage; frequencies are in Hz.

Calibration
-----------
:func:`fit` calibrates a unit against one or more events, stage by stage (``gen``: the machine
with E_fd and P_m held; then ``avr``, ``pss``, ``tg``), each by a parallel particle swarm, then
Levenberg-Marquardt (L-BFGS with ``local = "lbfgs"`` in the spec), exactly as the
``itaipu-calib fit`` command line::

    r = ic.fit("data/itaipu/event.toml", "data/itaipu/unit.toml",
               calib="data/itaipu/calibration.toml", stages="gen,avr,pss", seed=1)
    r.stages                    # ['gen', 'avr', 'pss', 'joint']
    r.fitness                   # [('start', J), ('gen', J), ...]: J = sum(dP^2 + dQ^2)
    r.parameters("gen")         # {'machine.x_d': ..., ...}: the stage's calibrated values
    r.unit.to_toml()            # the calibrated full unit
    start, cal = r.traces("avr")  # Traces before and after the stage (first event)
    r.report                    # the full report (report.json of the command line) as a dict
    r.headline                  # "Residual of unit ...: at most X × the noise σ (...)"
    r.write("out/fit", html=True)  # the command line's folder, report.html included

A PMU recording imports straight into an Event ``fit`` takes (its report, the command line's
``import.json``, is ``ev.import_report``; its warnings are ``ItaipuWarning``\ s)::

    ev = ic.import_pmu("data/itaipu/pmu/itaipu.cfg", 1000, 60, v_base_kv=18)
    r = ic.fit(ev, "data/itaipu/unit.dyr", calib="data/itaipu/calibration.toml")

* ``calib`` is a file with a ``[calibration]`` table (stages, free parameters and bounds,
  objectives, optimiser settings); by default the unit file's own table, so a :class:`Unit` that
  was not read from a file (``FitResult.unit``) needs ``calib``.
* ``stages`` is ``"all"`` (every stage the spec lists) or some of ``gen``, ``avr``, ``pss``,
  ``tg`` as a list or a comma-separated string; they always run in that order, each from the
  previous result. With several stages a final joint pass over all their parameters on the
  full unit (a swarm from the staged result, then the local method) is reported as stage
  ``joint`` (``polish=False`` skips it).
* ``strategy``, ``seed``, ``particles``, ``pso_iterations`` and ``local_iterations`` override
  the spec; ``threads`` sets the worker threads (default: all cores). The same seed gives the
  same numbers on any number of threads.
* ``held_out`` events are not fitted; their fitness is reported per stage in ``report``.
* ``FitResult.fitness`` sums J over the fitted events; a stage's row is the fitness of that
  stage's unit (``gen`` runs without exciter, stabiliser and governor). Non-finite numbers in
  ``report`` (e.g. the standard error of an undetermined parameter) are ``None``.
* ``r.params()`` gives lmfit-like :class:`Parameter` objects ``{name: Parameter}`` (``value``,
  ``stderr`` (None: not determined by the data), ``init_value``, ``min``, ``max``,
  ``at_bound``, ``correl`` ``{other: rho}``, ``stage``, ``units``), each from the last stage that
  freed it; ``r.params("gen")`` those of one stage. ``print(r)`` or ``r.fit_report()`` prints
  the command line's report; ``r.to_pandas()`` is the parameter table.
* The GIL is released during the fit (a full fit of the bundled problem takes some tens of
  seconds); Ctrl-C stops it at its next candidate evaluation and raises ``KeyboardInterrupt``
  within a second. The stages finished by then are kept on the exception:
  ``e.finished_stages``, ``e.unit`` (the unit after the last of them, or None), ``e.params``,
  ``e.stage_reports``.

Editing a unit
--------------
``unit.with_params({"machine.h": 5.0, "exciter.K": 120.0})`` returns a new :class:`Unit`
(this one is unchanged), checked by the library as a unit file is: an unknown parameter or a
value outside the model's domain raises :class:`UnitModelError` naming the parameter
(``kind`` ``"unknown_param"`` or ``"bad_param"``).

Tables and figures
------------------
``to_pandas()`` on :class:`Traces` (indexed by ``time_s``), :class:`FitResult` (the parameter
table) and :class:`Diagnosis` (the candidates and their gains) needs pandas (``pip install
pandas``; without it an ImportError says so). :mod:`itaipu_calib.plot` draws the standard
figures with matplotlib: ``plot_pq(traces)`` (measured against simulated P and Q) and
``plot_residuals(traces)`` (residuals with the noise band, ``noise_sigma`` of the measured
signal).

Command line
------------
Installing the wheel installs the ``itaipu-calib`` command (the same Rust code as the binary
built by cargo, run in process): ``itaipu-calib fit --help``.

Plausibility
------------
:func:`check` runs the checks the command line runs on every event before using it (time gaps,
dropouts, an angle in radians, frequency outside 45-65 Hz, a unit absorbing P, P and Q above
the unit's rating, absurd samples, spikes; with a unit, its parameters against the library's
ranges) and returns the findings, each a dict naming the file, the CSV line, the column and the
fix; ``severity == "error"`` is what stops the command line (exit 3)::

    [f for f in ic.check("event.toml", "unit.toml") if f["severity"] == "error"]

:func:`simulate`, :func:`fit` and :func:`diagnose` do not run it themselves.

Diagnosis
---------
:func:`diagnose` asks what a (calibrated) unit still gets wrong on some events: it analyses the
residuals, re-fits each cause of the catalog as a model extension (torsional mode, exciter
limits, saturation, governor, measurement skew, terminal load, PSS state, OEL) and names the
cause whose gain is significant (ΔBIC, fitted and held-out χ²), as ``itaipu-calib diagnose``::

    ev = ic.synth("data/synthetic/unit_gensae_sexs_stab3_hygov.toml", duration=8.0,
                  hide=[("measurement_skew", {"measurement.pq_delay_s": 0.012})])
    d = ic.diagnose(ev, "data/synthetic/unit_gensae_sexs_stab3_hygov.toml",
                    causes=["measurement_skew", "terminal_load"])
    d.cause                     # 'measurement_skew' (or 'none', 'unexplained')
    d.verdict                   # cause, title, statement, key_parameters, gains, where, grade, probability, competing
    d.candidates, d.evidence    # every cause tried with its gain; the residual evidence
    d.extended_unit_toml        # the extended, re-fitted unit of the named cause (or None)
    d.traces_before[ev.name]    # {'time_s': array, 'p_pu': array, ...}; also traces_after
    d.report, d.to_json()       # the whole report as a dict / JSON text

* ``held_out`` events judge the candidates; without them each event is split into alternating
  0.5 s blocks, fitted and held out.
* The arguments come in the order of :func:`fit` and :func:`simulate`: events first, then the
  unit. The old order ``diagnose(unit, events)`` still works with a ``DeprecationWarning``.
* ``seed``, ``particles``, ``pso_iterations``, ``lbfgs_iterations`` set every re-fit;
  ``threads`` the worker threads (default: all cores). The GIL is released while it runs;
  Ctrl-C stops the re-fits at their next candidate evaluation and raises ``KeyboardInterrupt``
  within a second (nothing is kept: a verdict needs every cause). :func:`synth` also raises it
  at once.
* An unknown cause raises :class:`CalibrationError` (``kind`` ``"setup"``); a unit that does not
  simulate on an event :class:`SimulationError` (``kind`` ``"simulation"``).

Synthetic events
----------------
:func:`synth` makes an in-memory Event by playing a grid-side voltage profile into a true unit,
with PMU noise and quantisation (the generator behind ``itaipu-calib synth``):
``synth(unit, kind="dip"|"frequency"|"step"|"ambient", duration=..., rate=..., pq_sigma=...,
v_sigma=..., quantum=..., skew_ms=..., seed=..., hide=None, return_truth=False)`` (the defaults:
``help(synth)`` or :func:`options`). ``hide`` hides catalog causes in the truth, in order, as the command
line's ``--hide``: ``[(cause, {param: value}), ...]`` or ``{cause: {param: value}}``
(parameters not given keep the extension's starting values; an unknown cause or parameter
raises ``ValueError``, a truth that cannot initialise :class:`InitError`). With
``return_truth=True`` it returns ``(event, truth_unit)``.

Fleets
------
:mod:`itaipu_calib.fleet` runs many (unit, events) jobs, fit then optionally diagnose, in
parallel on a Dask cluster (``pip install 'itaipu-calib[fleet]'``) or one after another in
process, and gathers one row per job (J before and after, the named cause, or the error of a
job that failed, without stopping the others)::

    from itaipu_calib.fleet import Job, jobs_from_csv, run_fleet
    result = run_fleet(jobs_from_csv("fleet.csv"), client)   # client: dask.distributed.Client
    result.to_pandas(), result.failed

A job's folder (``Job(..., out=...)``) holds ``fit/`` and ``diagnose/``, written by
:meth:`FitResult.write` and :meth:`Diagnosis.write`, then ``row.json``; :func:`run_fleet` shows
its progress on stderr when it is a terminal (``progress=``).

Errors
------
Every error is an :class:`ItaipuError`; its message is exactly the message of the Rust library
(what the ``itaipu-calib`` command line prints), and ``kind`` identifies the variant where the
library defines one:

* :class:`EventError`: bad event TOML or CSV (``kind`` e.g. ``"io"``, ``"unknown_column"``).
* :class:`UnitModelError`: bad unit file (``kind``: ``"io"``, ``"syntax"``, ``"field"``,
  ``"model"``, ``"wiring"``).
* :class:`InitError`: the unit cannot start at the measured operating point, or the unit's and
  the event's nominal frequencies differ (``kind``: ``"init"``, ``"bad_param"``, ``"wiring"``,
  ``"unknown_param"`` or ``"frequency_mismatch"``).
* :class:`SimulationError`: the integration failed (``kind``: ``"solve"``; ``"simulation"`` from
  :func:`diagnose` when the unit does not simulate on an event as given).
* :class:`CalibrationError`: bad calibration spec (``kind``: ``"io"``, ``"syntax"``,
  ``"missing"`` for a file without a ``[calibration]`` table, ``"field"``: bounds upside down, an
  unknown stage or key...), a spec that does not fit the unit (``"spec"``: e.g. an unknown
  parameter in ``free``), a fit that cannot run (``"stage"``, ``"setup"``), or a diagnosis that
  cannot run (``"setup"``, e.g. an unknown cause).
* :class:`OutputError`: an output file or folder could not be written, or would overwrite one.
* :class:`InternalError`: a bug (an internal invariant broken; a Rust panic is caught and
  raised as this, never as ``PanicException``): please report it with the message.

Bad options raise ``ValueError``; arguments of the wrong type ``TypeError``.
"""

import functools as _functools
import inspect as _inspect
from typing import Any as _Any, Callable as _Callable, TypeVar as _TypeVar

from . import _core
from ._core import (
    CalibrationError,
    Diagnosis,
    Event,
    EventError,
    FitResult,
    InitError,
    InternalError,
    ItaipuError,
    ItaipuWarning,
    OutputError,
    Parameter,
    SimulationError,
    Traces,
    Unit,
    UnitModelError,
    __version__,
    causes,
    check,
    defaults,
    diagnose,
    fit,
    import_pmu,
    load_event,
    load_unit,
    models,
    noise_sigma,
    options,
    read_dyr,
    stages,
    write_dyr,
)

_F = _TypeVar("_F", bound=_Callable[..., _Any])


def _declared(func: _F, command: str) -> _F:
    """``func`` with the defaults its signature shows read from the option declaration
    (:func:`options`), where the compiled function takes them from: ``help()`` and
    :func:`inspect.signature` then show the values, not ``...``."""
    declared = {o["python"]: o["default"] for o in _core.options()
                if o["command"] == command and o["python"]}
    sig = _inspect.signature(func)
    params = [p.replace(default=declared[p.name]) if p.default is Ellipsis and p.name in declared
              else p for p in sig.parameters.values()]

    @_functools.wraps(func)
    def call(*args: _Any, **kwargs: _Any) -> _Any:
        return func(*args, **kwargs)

    call.__signature__ = sig.replace(parameters=params)  # type: ignore[attr-defined]
    return call  # type: ignore[return-value]


simulate = _declared(_core.simulate, "simulate")
synth = _declared(_core.synth, "synth")

__all__ = [
    "CalibrationError",
    "Diagnosis",
    "Event",
    "EventError",
    "FitResult",
    "InitError",
    "InternalError",
    "ItaipuError",
    "ItaipuWarning",
    "OutputError",
    "Parameter",
    "SimulationError",
    "Traces",
    "Unit",
    "UnitModelError",
    "__version__",
    "causes",
    "check",
    "defaults",
    "diagnose",
    "fit",
    "import_pmu",
    "load_event",
    "load_unit",
    "models",
    "noise_sigma",
    "options",
    "read_dyr",
    "simulate",
    "stages",
    "synth",
    "write_dyr",
]
