"""One case made in a worker process (importable, so that a spawned worker finds it)."""

from __future__ import annotations

import time


def make_one(args):
    cs, out = args
    from .case import Case

    t0 = time.time()
    try:
        c = Case(cs).build()
    except Exception as e:  # one case's failure is reported, the others are still made
        return cs["id"], time.time() - t0, float("nan"), f"FAILED: {e}"
    c.write(out)
    v = c.key["diagnostics"]["oracle"]["effect_visibility"]
    return cs["id"], time.time() - t0, v["misfit_without_effect_over_noise"], v["misfit_with_effect_over_noise"]
