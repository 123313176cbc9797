"""Time signals for the simulations: fast scalar evaluation of splines and linear tables, smooth
edges, and the coloured random processes the ambient background and the PMU noise use.

The ODE right-hand sides evaluate these once per call, so they are plain-Python scalar
functions (a numpy call per scalar would cost more than the whole right-hand side)."""

from __future__ import annotations

import bisect
import math

import numpy as np
from scipy.interpolate import CubicSpline
from scipy.signal import butter, sosfiltfilt


class UniformSpline:
    """A C2 cubic spline through samples on a uniform grid, evaluated in plain Python.

    Outside the grid the end polynomials are extended (the simulations never leave it by more
    than a step)."""

    def __init__(self, t0: float, dt: float, values: np.ndarray):
        n = len(values)
        t = t0 + dt * np.arange(n)
        cs = CubicSpline(t, values, bc_type="natural")
        c = cs.c
        self.t0 = float(t0)
        self.dt = float(dt)
        self.inv_dt = 1.0 / float(dt)
        self.n = n
        self.c3 = c[0].tolist()
        self.c2 = c[1].tolist()
        self.c1 = c[2].tolist()
        self.c0 = c[3].tolist()

    def __call__(self, t: float) -> float:
        i = int((t - self.t0) * self.inv_dt)
        if i < 0:
            i = 0
        elif i > self.n - 2:
            i = self.n - 2
        s = t - (self.t0 + i * self.dt)
        return ((self.c3[i] * s + self.c2[i]) * s + self.c1[i]) * s + self.c0[i]

    def slope(self, t: float) -> float:
        i = int((t - self.t0) * self.inv_dt)
        if i < 0:
            i = 0
        elif i > self.n - 2:
            i = self.n - 2
        s = t - (self.t0 + i * self.dt)
        return (3.0 * self.c3[i] * s + 2.0 * self.c2[i]) * s + self.c1[i]


class LinearTable:
    """Linear interpolation of samples at (possibly non-uniform) stamps, held at the ends: how a
    record's |V| and unwrapped angle are played back between its samples."""

    def __init__(self, t: np.ndarray, values: np.ndarray):
        self.t = [float(x) for x in t]
        self.v = [float(x) for x in values]
        self.n = len(self.t)

    def __call__(self, t: float) -> float:
        i = bisect.bisect_right(self.t, t) - 1
        if i < 0:
            return self.v[0]
        if i >= self.n - 1:
            return self.v[-1]
        t0 = self.t[i]
        w = (t - t0) / (self.t[i + 1] - t0)
        return self.v[i] + w * (self.v[i + 1] - self.v[i])


def smooth_step(t: np.ndarray, t_on: float, edge: float) -> np.ndarray:
    """0 before `t_on`, 1 after `t_on + edge`, a raised cosine between (C1 edges)."""
    x = np.clip((t - t_on) / edge, 0.0, 1.0)
    return 0.5 - 0.5 * np.cos(np.pi * x)


def pulse(t: np.ndarray, t_on: float, dur: float, edge: float) -> np.ndarray:
    """A trapezoid of height 1: rises over `edge` from `t_on`, holds for `dur`, falls over `edge`."""
    return smooth_step(t, t_on, edge) - smooth_step(t, t_on + edge + dur, edge)


def smooth_ramp(t: np.ndarray, t_on: float, dur: float, corner: float) -> np.ndarray:
    """0 before `t_on`, 1 after `t_on + dur`, linear between, with corners rounded over `corner`
    seconds (the integral of a smooth step of that width, rescaled)."""
    dt = t[1] - t[0] if len(t) > 1 else 1e-3
    s = smooth_step(t, t_on, corner) - smooth_step(t, t_on + dur, corner)
    r = np.cumsum(s) * dt
    return r / max(r[-1], 1e-12)


def lowpass_noise(rng: np.random.Generator, n: int, fs: float, f_hi: float, order: int = 2):
    """Unit-variance Gaussian noise band-limited below `f_hi` (zero-phase Butterworth)."""
    w = rng.standard_normal(n + 2000)
    sos = butter(order, f_hi / (fs / 2), btype="low", output="sos")
    y = sosfiltfilt(sos, w)[1000 : 1000 + n]
    return y / max(np.std(y), 1e-15)


def bandpass_noise(rng: np.random.Generator, n: int, fs: float, f_lo: float, f_hi: float):
    """Unit-variance Gaussian noise band-limited to [f_lo, f_hi] (zero-phase Butterworth)."""
    w = rng.standard_normal(n + 4000)
    sos = butter(3, [f_lo / (fs / 2), f_hi / (fs / 2)], btype="band", output="sos")
    y = sosfiltfilt(sos, w)[2000 : 2000 + n]
    return y / max(np.std(y), 1e-15)


def ou_process(rng: np.random.Generator, n: int, dt: float, tau: float, smooth_hz: float = 2.0):
    """Unit-variance Ornstein-Uhlenbeck process with time constant `tau`, then low-passed at
    `smooth_hz` so that an ODE solver can follow it (exact discretisation, stationary start)."""
    a = math.exp(-dt / tau)
    b = math.sqrt(1.0 - a * a)
    w = rng.standard_normal(n + 4000)
    y = np.empty(n + 4000)
    y[0] = w[0]
    for k in range(1, n + 4000):
        y[k] = a * y[k - 1] + b * w[k]
    sos = butter(2, smooth_hz / (0.5 / dt), btype="low", output="sos")
    y = sosfiltfilt(sos, y)[2000 : 2000 + n]
    return y / max(np.std(y), 1e-15)


def resonant_noise(rng: np.random.Generator, n: int, dt: float, f0: float, zeta: float):
    """Unit-variance output of a lightly damped second-order system at `f0` driven by white noise
    (an inter-area oscillation excited by load noise)."""
    w0 = 2 * math.pi * f0
    # Tustin discretisation of w0^2 / (s^2 + 2 zeta w0 s + w0^2).
    from scipy.signal import bilinear, lfilter

    b, a = bilinear([w0 * w0], [1.0, 2 * zeta * w0, w0 * w0], fs=1.0 / dt)
    x = rng.standard_normal(n + int(40.0 / (zeta * f0 * dt)) + 10)
    y = lfilter(b, a, x)[-n:]
    # smooth above the band (the ODE solver then follows it with ordinary steps)
    sos = butter(2, min(4.0 * f0, 0.2 / dt) / (0.5 / dt), btype="low", output="sos")
    y = sosfiltfilt(sos, y)
    return y / max(np.std(y), 1e-15)


def ar1_noise(rng: np.random.Generator, n: int, phi: float) -> np.ndarray:
    """Unit-variance AR(1) sequence with coefficient `phi` (stationary start)."""
    w = rng.standard_normal(n)
    y = np.empty(n)
    y[0] = w[0]
    b = math.sqrt(1.0 - phi * phi)
    for k in range(1, n):
        y[k] = phi * y[k - 1] + b * w[k]
    return y
