"""The standard figures with matplotlib (optional: ``pip install matplotlib``).

* :func:`plot_pq`: measured against simulated P and Q over time;
* :func:`plot_residuals`: the residuals P and Q (simulated minus measured) with the noise band
  (± ``k`` noise standard deviations, the noise estimated from the measured signal by
  :func:`itaipu_calib.noise_sigma`, as the fit's prior weight).

Each takes :class:`~itaipu_calib.Traces` (from ``simulate`` or ``FitResult.traces``) or a dict
of columns (``Diagnosis.traces_before[event]``), draws into ``axes`` (two Axes) or a new
figure, and returns the Figure.
"""

from typing import Any, Mapping, Optional, Sequence, Union

import numpy as np

from ._core import Traces, noise_sigma

_Columns = Union[Traces, Mapping[str, Any]]


def _pyplot() -> Any:
    try:
        import matplotlib.pyplot as plt
    except ImportError as e:  # pragma: no cover - depends on the environment
        raise ImportError(
            "itaipu_calib.plot needs matplotlib, which is not installed: pip install matplotlib "
            "(or pip install 'itaipu-calib[plot]')"
        ) from e
    return plt


def _col(traces: _Columns, name: str) -> np.ndarray:
    return np.asarray(traces[name], dtype=float)


def _axes(axes: Optional[Sequence[Any]], title: Optional[str]) -> Any:
    plt = _pyplot()
    if axes is None:
        fig, axes = plt.subplots(2, 1, sharex=True, figsize=(8, 5.5))
    else:
        if len(axes) != 2:
            raise ValueError(f"axes must be two matplotlib Axes (P, Q), got {len(axes)}")
        fig = axes[0].figure
    if title:
        fig.suptitle(title)
    return fig, axes


def plot_pq(traces: _Columns, axes: Optional[Sequence[Any]] = None, title: Optional[str] = None) -> Any:
    """Measured (``p_meas_pu``, ``q_meas_pu``) and simulated (``p_pu``, ``q_pu``) P and Q
    against ``time_s``, pu on the event's system base. Returns the Figure."""
    fig, (ax_p, ax_q) = _axes(axes, title)
    t = _col(traces, "time_s")
    for ax, sig in ((ax_p, "p"), (ax_q, "q")):
        ax.plot(t, _col(traces, f"{sig}_meas_pu"), color="0.3", lw=1.0, label="measured")
        ax.plot(t, _col(traces, f"{sig}_pu"), color="C0", lw=1.2, label="simulated")
        ax.set_ylabel(f"{sig.upper()} [pu]")
        ax.grid(True, alpha=0.3)
        ax.legend(loc="best")
    ax_q.set_xlabel("time [s]")
    return fig


def plot_residuals(
    traces: _Columns, axes: Optional[Sequence[Any]] = None, k: float = 2.0, title: Optional[str] = None
) -> Any:
    """Residuals ΔP and ΔQ (simulated minus measured) against ``time_s`` with the noise band
    ±``k``·σ shaded, σ = :func:`itaipu_calib.noise_sigma` of the measured signal. Returns the
    Figure; each Axes' ``noise_sigma`` attribute holds the σ drawn."""
    if not (k > 0 and np.isfinite(k)):
        raise ValueError(f"k must be a positive number of noise standard deviations (got {k})")
    fig, (ax_p, ax_q) = _axes(axes, title)
    t = _col(traces, "time_s")
    for ax, sig in ((ax_p, "p"), (ax_q, "q")):
        meas = _col(traces, f"{sig}_meas_pu")
        sigma = noise_sigma(meas.tolist())
        ax.fill_between(t, -k * sigma, k * sigma, color="C2", alpha=0.25, label=f"noise ±{k:g}σ")
        ax.plot(t, _col(traces, f"{sig}_pu") - meas, color="C3", lw=1.0, label="simulated − measured")
        ax.axhline(0.0, color="0.5", lw=0.6)
        ax.set_ylabel(f"Δ{sig.upper()} [pu]")
        ax.grid(True, alpha=0.3)
        ax.legend(loc="best")
        ax.noise_sigma = sigma
    ax_q.set_xlabel("time [s]")
    return fig
