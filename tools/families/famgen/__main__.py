"""Command line: make a family (or some of its cases), or run the independence check of made
cases against the project's engine.

    python -m famgen make FAMILY [--out data/families] [--cases o01,o05] [--jobs 1]
    python -m famgen index FAMILY [--out data/families]        (index.json + README only)
    python -m famgen check FAMILY [--out data/families] [--cases ...] [--engine target/release/itaipu-calib]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from concurrent.futures import ProcessPoolExecutor

from .families import FAMILIES
from .make import make_one


def _report(r):
    if isinstance(r[3], str):
        print(f"{r[0]}: {r[3]}", flush=True)
    else:
        print(f"{r[0]}: {r[1]:.0f} s, misfit without/with effect {r[2]:.2f}/{r[3]:.2f} sd", flush=True)


def cmd_make(a):
    cases = FAMILIES[a.family]
    if a.cases:
        want = set(a.cases.split(","))
        cases = [c for c in cases if c["id"] in want]
    out = os.path.join(a.out, a.family)
    jobs = [(cs, out) for cs in cases]
    # A fresh process per case: scipy's LSODA wrapper keeps a few kB per solve, and a record's
    # playback solves once per interval between its stamps.
    with ProcessPoolExecutor(max(1, a.jobs), max_tasks_per_child=1) as ex:
        for r in ex.map(make_one, jobs):
            _report(r)
    cmd_index(a)


def cmd_index(a):
    from .readme import write_index_and_readme

    write_index_and_readme(os.path.join(a.out, a.family), a.family)


def cmd_check(a):
    from .enginecheck import check_family

    check_family(os.path.join(a.out, a.family), a.family, a.cases.split(",") if a.cases else None,
                 a.engine)


def main(argv=None):
    p = argparse.ArgumentParser(prog="famgen")
    sub = p.add_subparsers(dest="cmd", required=True)
    for name in ("make", "index", "check"):
        s = sub.add_parser(name)
        s.add_argument("family", choices=sorted(FAMILIES))
        s.add_argument("--out", default="data/families")
        s.add_argument("--cases", default="")
        s.add_argument("--jobs", type=int, default=1)
        s.add_argument("--engine", default="target/release/itaipu-calib")
    a = p.parse_args(argv)
    {"make": cmd_make, "index": cmd_index, "check": cmd_check}[a.cmd](a)


if __name__ == "__main__":
    sys.exit(main())
