"""The PMU chain: point samples from t = 0, additive noise (white, AR(1) or band-limited; the
stated sd is the marginal sd), optional quantisation, drop-outs (rows missing from the export,
as a PDC archive has them), the frequency channel derived from the measured angle."""

from __future__ import annotations

import math

import numpy as np

from . import signals as S


def coloured(rng: np.random.Generator, n: int, colour: dict, rate: float) -> np.ndarray:
    """Unit-variance noise sequence of `n` samples with the colour `colour`:
    {"kind": "white"} | {"kind": "ar1", "phi": p} | {"kind": "band", "f_hi": f} (Butterworth
    low-pass of white noise at f Hz, zero phase)."""
    kind = colour.get("kind", "white")
    if kind == "white":
        return rng.standard_normal(n)
    if kind == "ar1":
        return S.ar1_noise(rng, n, colour["phi"])
    if kind == "band":
        return S.lowpass_noise(rng, n, rate, colour["f_hi"], order=3)
    raise ValueError(kind)


def derive_freq(t: np.ndarray, vr: np.ndarray, vi: np.ndarray, fn: float) -> np.ndarray:
    """Frequency from the measured voltage angle: central difference over the stamps, then a
    5-sample centred moving average (shrinking at the ends)."""
    ang = np.unwrap(np.arctan2(vi, vr))
    n = len(t)
    d = np.empty(n)
    d[1:-1] = (ang[2:] - ang[:-2]) / (t[2:] - t[:-2])
    d[0] = (ang[1] - ang[0]) / (t[1] - t[0])
    d[-1] = (ang[-1] - ang[-2]) / (t[-1] - t[-2])
    f = fn + d / (2 * math.pi)
    out = np.empty(n)
    for k in range(n):
        a, b = max(0, k - 2), min(n, k + 3)
        out[k] = f[a:b].mean()
    return out


def quantise(x: np.ndarray, step: float | None) -> np.ndarray:
    if not step:
        return x
    return np.round(x / step) * step


def drop_mask(rng: np.random.Generator, n: int, drops: dict, rate: float, protect_s: float = 1.2):
    """Boolean mask of the samples kept: `single` isolated missing samples and `gaps` (count,
    (min, max) length in samples) missing runs, never in the first `protect_s` seconds (the init
    window) nor at the last sample."""
    keep = np.ones(n, bool)
    lo = int(math.ceil(protect_s * rate))
    placed = []
    for _ in range(drops.get("gaps", 0)):
        for _try in range(200):
            ln = int(rng.integers(drops["gap_len"][0], drops["gap_len"][1] + 1))
            s = int(rng.integers(lo, n - ln - 2))
            if all(s + ln + 3 < a or s > b + 3 for a, b in placed):
                keep[s : s + ln] = False
                placed.append((s, s + ln))
                break
    k = 0
    while k < drops.get("single", 0):
        s = int(rng.integers(lo, n - 1))
        if keep[s - 1] and keep[s] and keep[s + 1]:
            keep[s] = False
            k += 1
    return keep
