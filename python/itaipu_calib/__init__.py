"""Playback simulation of generating-unit models against PMU recordings.

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
* :class:`SimulationError`: the integration failed (``kind``: ``"solve"``).

Bad options raise ``ValueError``; arguments of the wrong type ``TypeError``.
"""

from ._core import (
    Event,
    EventError,
    InitError,
    ItaipuError,
    SimulationError,
    Traces,
    Unit,
    UnitModelError,
    __version__,
    load_event,
    load_unit,
    models,
    simulate,
)

__all__ = [
    "Event",
    "EventError",
    "InitError",
    "ItaipuError",
    "SimulationError",
    "Traces",
    "Unit",
    "UnitModelError",
    "__version__",
    "load_event",
    "load_unit",
    "models",
    "simulate",
]
