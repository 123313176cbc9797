"""itaipu_calib.fleet (issues 14, 25): many (unit, events) jobs on a local Dask cluster of two
worker processes, one task per job; rows in the jobs' order, failures per job, the same numbers
as a direct fit and diagnosis, the in-process path, job tables, the library's stage list and
defaults, output folders written by the library's writers, progress."""

import hashlib
import io
import json
import operator
import os
import pickle
import re
import shutil
import signal
import subprocess
import sys
import threading
import time
import types
import warnings
from pathlib import Path

import pytest

import itaipu_calib as ic
from itaipu_calib import _core
import itaipu_calib.fleet as fleet_mod
from itaipu_calib.fleet import COLUMNS, FleetResult, Job, jobs_from_csv, run_fleet, run_job

distributed = pytest.importorskip("distributed")  # installed by scripts/test.sh
dask = pytest.importorskip("dask")

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT / "data"
TRUTH = DATA / "synthetic" / "unit_gensae_sexs_stab3_hygov.toml"
CALIB = DATA / "itaipu" / "calibration.toml"
ITAIPU_EVENT = DATA / "itaipu" / "event.toml"
ITAIPU_UNIT = DATA / "itaipu" / "unit.toml"
# Small and quick: a generator-stage fit of a 4 s, 30 samples/s event takes well under a second.
QUICK = dict(particles=4, pso_iterations=2, local_iterations=2, polish=False)
DQUICK = dict(diagnose_particles=8, diagnose_pso_iterations=4, diagnose_local_iterations=3)
# The same settings as fit's and diagnose's arguments (a direct run of a job).
FIT_QUICK = dict(particles=4, pso_iterations=2, local_iterations=2, polish=False)
DIAG_QUICK = dict(particles=8, pso_iterations=4, local_iterations=3)
# Keys of a report that are no result: the wall time, the worker threads.
VOLATILE = ("wall_s", "threads")


def _cores():
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover
        return os.cpu_count() or 1


def _tree(d):
    """Every file under ``d``, relative, ``/``-separated, sorted."""
    return sorted(p.relative_to(d).as_posix() for p in Path(d).rglob("*") if p.is_file())


def _snapshot(d):
    """{relative path: bytes} of every file under ``d``."""
    return {rel: (Path(d) / rel).read_bytes() for rel in _tree(d)}


def _verify(d):
    """Checks a folder against its manifest.json, independently of the library: every file
    listed with its size and SHA-256, and no other file. Returns the manifest."""
    m = json.loads((Path(d) / "manifest.json").read_text())
    listed = {f["path"]: (f["bytes"], f["sha256"]) for f in m["files"]}
    present = [rel for rel in _tree(d) if rel != "manifest.json"]
    assert sorted(listed) == present, (d, sorted(listed), present)
    for rel in present:
        data = (Path(d) / rel).read_bytes()
        assert listed[rel] == (len(data), hashlib.sha256(data).hexdigest()), (d, rel)
    return m


def _no_temporary(d):
    """No temporary file or folder (a name starting with '.') in ``d``, under it or beside it."""
    d = Path(d)
    left = [p for p in d.rglob(".*")] + [p for p in d.parent.glob(f".{d.name}*")]
    assert left == [], left


def _same(a, b, rel=1e-12, path=""):
    """``a`` and ``b`` (JSON-like) equal, floats to ``rel``, the VOLATILE keys skipped."""
    if isinstance(a, dict):
        assert isinstance(b, dict) and sorted(a) == sorted(b), (path, sorted(a), sorted(b))
        for k in a:
            if k not in VOLATILE:
                _same(a[k], b[k], rel, f"{path}/{k}")
    elif isinstance(a, (list, tuple)):
        assert isinstance(b, (list, tuple)) and len(a) == len(b), (path, a, b)
        for i, (x, y) in enumerate(zip(a, b)):
            _same(x, y, rel, f"{path}/{i}")
    elif (isinstance(a, float) or isinstance(b, float)) and all(
            isinstance(x, (int, float)) and not isinstance(x, bool) for x in (a, b)):
        assert b == pytest.approx(a, rel=rel, abs=1e-300), (path, a, b)
    else:
        assert a == b, (path, a, b)


def _synth(out, seed, *extra):
    """An event folder written by `itaipu-calib synth` (event.toml + CSV), in process."""
    code = _core._cli_main(["itaipu-calib", "synth", "--unit", str(TRUTH), "--duration", "4",
                            "--rate", "30", "--seed", str(seed), "--out", str(out), *extra])
    assert code == 0
    return out / "event.toml"


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("fleet")
    ev1 = _synth(d / "events" / "dip1", 1)
    ev2 = _synth(d / "events" / "dip2", 2)
    ev3 = _synth(d / "events" / "skew3", 3, "--hide", "measurement_skew:measurement.pq_delay_s=0.02")
    # A nominal unit off the truth (inertia and transient reactance), so that the fit has work.
    nominal = d / "units" / "nominal.toml"
    nominal.parent.mkdir()
    text = TRUTH.read_text().replace("h = 4.5", "h = 5.4").replace("x_d_prime = 0.30", "x_d_prime = 0.36")
    assert text != TRUTH.read_text()
    nominal.write_text(text)
    no_spec = d / "units" / "no_spec.toml"  # a calibration file without [calibration]
    no_spec.write_text("[other]\nx = 1\n")
    return dict(dir=d, ev1=ev1, ev2=ev2, ev3=ev3, nominal=nominal, no_spec=no_spec)


@pytest.fixture(scope="module")
def jobs(files):
    d = files["dir"]
    return [
        Job("u1", files["nominal"], [files["ev1"]], calib=CALIB, stages="gen", seed=7, **QUICK),
        Job("missing-unit", d / "units" / "nope.toml", [files["ev1"]], calib=CALIB, stages="gen",
            seed=1, **QUICK),
        Job("u2-held-out", files["nominal"], [files["ev2"]], held_out=[files["ev1"]], calib=CALIB,
            stages="gen", seed=3, **QUICK),
        Job("bad-calib", files["nominal"], files["ev1"], calib=files["no_spec"], stages="gen",
            out=d / "out" / "bad-calib", **QUICK),
        # The true unit on an event whose power channels lag by 20 ms: the skew is named.
        Job("u3-diagnosed", TRUTH, [files["ev3"]], calib=CALIB, stages="gen", seed=5,
            diagnose=True, causes=["measurement_skew"], out=d / "out" / "u3", **QUICK, **DQUICK),
    ]


@pytest.fixture(scope="module")
def cluster():
    # allowed-failures 0: a task whose worker dies fails at once (KilledWorker) instead of being
    # retried on another worker (see test_a_dead_worker_is_a_failed_row).
    with dask.config.set({"distributed.scheduler.allowed-failures": 0}):
        with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                      dashboard_address=None) as cl:
            with distributed.Client(cl) as client:
                yield client


@pytest.fixture(scope="module")
def finished_rows():
    """The rows the fleet's progress callable received, in completion order."""
    return []


@pytest.fixture(scope="module")
def fleet(cluster, jobs, finished_rows):
    return run_fleet(jobs, cluster, progress=finished_rows.append)


# --- the distributed run --------------------------------------------------------------------


def test_failures_are_rows_and_the_others_run(fleet, jobs):
    assert [r["job"] for r in fleet.rows] == [j.name for j in jobs]  # the jobs' order
    status = {r["job"]: r["status"] for r in fleet.rows}
    assert status == {"u1": "ok", "missing-unit": "failed", "u2-held-out": "ok",
                      "bad-calib": "failed", "u3-diagnosed": "ok"}
    missing = fleet["missing-unit"]
    assert missing["step"] == "fit"
    assert missing["error_type"] == "UnitModelError" and missing["error_kind"] == "io"
    assert "nope.toml" in missing["error"] and "\n" not in missing["error"]
    bad = fleet["bad-calib"]
    assert bad["error_type"] == "CalibrationError" and bad["error_kind"] == "missing"
    assert "no_spec.toml" in bad["error"]
    assert bad["j_fit"] is None and bad["out"] is None
    assert [r["job"] for r in fleet.failed] == ["missing-unit", "bad-calib"]
    assert [r["job"] for r in fleet.ok] == ["u1", "u2-held-out", "u3-diagnosed"]
    for r in fleet.rows:
        assert list(r) == list(COLUMNS)
        assert r["wall_s"] > 0 and r["host"]
    for r in fleet.ok:
        assert r["step"] is None and r["error"] is None and r["error_type"] is None
    assert repr(fleet).startswith("FleetResult(5 jobs: 3 ok, 2 failed: missing-unit (UnitModelError io")


def test_jobs_ran_in_the_worker_processes(fleet, cluster):
    workers = set(cluster.run(os.getpid).values())
    assert len(workers) == 2
    pids = {r["pid"] for r in fleet.rows}
    assert pids <= workers and os.getpid() not in pids


def test_the_rust_pool_is_shared_among_the_workers(fleet):
    # 2 worker processes of 1 Dask thread each on this host: each job gets cores // 2 threads.
    expected = max(1, _cores() // 2)
    assert {r["threads"] for r in fleet.ok} == {expected}


def test_a_row_holds_the_fit_numbers_of_a_direct_fit(fleet, jobs, files):
    # The same seed gives the same J whatever the number of threads (here 3, the workers' 1).
    for name in ("u1", "u2-held-out"):
        job = next(j for j in jobs if j.name == name)
        direct = ic.fit(list(job.events), job.unit, calib=CALIB, stages="gen", seed=job.seed,
                        held_out=list(job.held_out), threads=3, **QUICK)
        assert direct.report["threads"] == 3
        row = fleet[name]
        assert row["j_start"] == pytest.approx(direct.fitness[0][1], rel=1e-12)
        assert row["j_fit"] == pytest.approx(direct.fitness[-1][1], rel=1e-12)
        assert row["j_fit"] < row["j_start"]  # the fit moved the nominal unit towards the truth
        assert row["stages"] == "gen" and row["seed"] == job.seed
        assert row["n_events"] == 1
    held = fleet["u2-held-out"]
    assert held["n_held_out"] == 1 and held["j_held_out"] > 0
    assert fleet["u1"]["n_held_out"] == 0 and fleet["u1"]["j_held_out"] is None


def test_the_diagnosed_job_names_a_cause(fleet, jobs):
    row = fleet["u3-diagnosed"]
    assert row["cause"] == "measurement_skew"
    assert abs(row["key_parameters"]["measurement.pq_delay_s"] - 0.02) < 0.005
    assert row["delta_bic"] > 0 and row["fit_drop"] > 0
    # The row's numbers are the verdict's (the diagnosis.json written in the job's folder).
    d = json.loads((Path(row["out"]) / "diagnose" / "diagnosis.json").read_text())
    assert row["cause"] == d["verdict"]["cause"]
    gains = d["verdict"]["gains"] or {}
    assert row["delta_bic"] == gains.get("delta_bic")
    assert row["key_parameters"] == {p[0]: p[1] for p in d["verdict"]["key_parameters"]}
    assert [c["cause"] for c in d["candidates"]] == ["measurement_skew"]
    # Not diagnosed: no diagnosis columns.
    assert fleet["u1"]["cause"] is None and fleet["u1"]["delta_bic"] is None


def test_to_pandas_has_one_row_per_job(fleet, jobs):
    df = fleet.to_pandas()
    assert len(df) == len(jobs)
    assert list(df.columns) == list(COLUMNS)
    assert list(df["job"]) == [j.name for j in jobs]
    assert list(df["status"]) == [r["status"] for r in fleet.rows]
    assert df.loc[df["job"] == "u1", "j_fit"].item() == fleet["u1"]["j_fit"]


def test_to_pandas_without_pandas_says_so(fleet, monkeypatch):
    monkeypatch.setitem(sys.modules, "pandas", None)
    with pytest.raises(ImportError, match="pip install pandas"):
        fleet.to_pandas()


# --- the same jobs in process ---------------------------------------------------------------


def test_in_process_gives_the_same_rows(fleet, jobs, files):
    seen = []
    # Other folders for the written jobs (the cluster's run wrote into the jobs' own).
    local = [Job(**{**j.__dict__, "out": str(files["dir"] / "out-local" / j.name)})
             if j.out else j for j in jobs]
    res = run_fleet(local, threads_per_job=3, on_row=seen.append)
    assert isinstance(res, FleetResult)
    assert [r["job"] for r in res.rows] == [j.name for j in jobs]
    assert [r["job"] for r in seen] == [j.name for j in jobs]
    numbers = ("status", "step", "error_type", "error_kind", "stages", "n_events", "n_held_out",
               "seed", "j_start", "j_fit", "j_held_out", "cause", "delta_bic", "fit_drop",
               "held_drop", "key_parameters")
    for a, b in zip(fleet.rows, res.rows):
        assert {k: a[k] for k in numbers} == {k: b[k] for k in numbers}, a["job"]
        assert b["pid"] == os.getpid()
    assert {r["threads"] for r in res.ok} == {3}


def test_the_module_imports_and_runs_without_dask(files):
    code = (
        "import sys\n"
        "sys.modules['dask'] = None\nsys.modules['distributed'] = None\n"
        "from itaipu_calib.fleet import Job, run_fleet\n"
        f"r = run_fleet([Job('x', {str(files['dir'] / 'nope.toml')!r}, ['e.toml'])])\n"
        "print(r.rows[0]['status'], r.rows[0]['error_type'])\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["failed", "UnitModelError"]


# --- failures outside run_job ---------------------------------------------------------------


class _Unpicklable(Job):
    """A job that cannot be unpickled out of this process (ZeroDivisionError there: in the
    scheduler, which reads the task graph, or in the worker)."""

    def __reduce__(self):
        return (operator.truediv, (1, 0))


def test_an_exception_outside_run_job_is_a_failed_row(cluster, files):
    bad = _Unpicklable("unpicklable", files["nominal"], [files["ev1"]])
    good = Job("good", files["nominal"], [files["ev1"]], calib=CALIB, stages="gen", seed=7, **QUICK)
    res = run_fleet([bad, good], cluster)
    assert [r["job"] for r in res.rows] == ["unpicklable", "good"]
    row = res["unpicklable"]
    assert row["status"] == "failed" and row["step"] == "worker"
    assert row["error_type"] and row["error"] and "\n" not in row["error"]
    assert row["j_fit"] is None and row["pid"] is None
    assert res["good"]["status"] == "ok"
    assert res["good"]["j_fit"] > 0


def test_a_dead_worker_is_a_failed_row(cluster, files):
    """The worker running a long job is killed (SIGKILL) as soon as the job is on it: that job's
    row says KilledWorker (the cluster fixture allows no retry), the other job is ok."""
    pids = cluster.run(os.getpid)  # {worker address: pid}
    long = Job("crash", files["nominal"], [files["ev1"]], calib=CALIB, stages="gen", seed=1,
               particles=40, pso_iterations=400, local_iterations=50)
    good = Job("good", files["nominal"], [files["ev1"]], calib=CALIB, stages="gen", seed=7, **QUICK)
    killed = []

    def killer():
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and not killed:
            for addr, keys in cluster.processing().items():
                if any(str(k).endswith("-crash") for k in keys) and addr in pids:
                    os.kill(pids[addr], signal.SIGKILL)
                    killed.append(pids[addr])
                    return
            time.sleep(0.02)

    t = threading.Thread(target=killer)
    t.start()
    try:
        res = run_fleet([long, good], cluster, threads_per_job=1)
    finally:
        killed.append(None)  # stops the killer if it has not fired
        t.join()
    assert killed[0] is not None, "the long job was never seen on a worker"
    assert [r["job"] for r in res.rows] == ["crash", "good"]
    crash = res["crash"]
    assert crash["status"] == "failed" and crash["step"] == "worker"
    assert crash["error_type"] == "KilledWorker"
    assert res["good"]["status"] == "ok" and res["good"]["pid"] != killed[0]
    assert repr(res) == "FleetResult(2 jobs: 1 ok, 1 failed: crash (KilledWorker in worker))"


# --- output folders -------------------------------------------------------------------------

# What FitResult.write (fit --out) writes at the top of a fit's folder, besides a folder per stage.
FIT_TOP = ["calibrated.toml", "calibration.toml", "datasheet.toml", "manifest.json", "report.json"]


def _u3(jobs):
    return next(j for j in jobs if j.name == "u3-diagnosed")


def test_the_job_folder_holds_the_library_s_folders(fleet, jobs, tmp_path):
    job = _u3(jobs)
    row = fleet["u3-diagnosed"]
    out = Path(row["out"])
    assert out == Path(job.out)
    # Exactly: the fit's folder, the diagnosis' folder, the row; no temporary file left.
    assert sorted(p.name for p in out.iterdir()) == ["diagnose", "fit", "row.json"]
    _no_temporary(out)
    # Each sub-folder is complete: its manifest lists every file with its size and SHA-256.
    assert _verify(out / "fit")["seed"] == 5
    assert _verify(out / "diagnose")["seed"] == 5
    # The fit's folder is what FitResult.write writes for the same fit run directly, and its
    # report.json is that fit's report (J to 1e-12).
    direct = ic.fit(list(job.events), job.unit, calib=CALIB, stages="gen", seed=5, threads=1,
                    **FIT_QUICK)
    report = json.loads((out / "fit" / "report.json").read_text())
    _same(direct.report, report)
    direct.write(tmp_path / "direct-fit")
    assert _tree(out / "fit") == _tree(tmp_path / "direct-fit")
    assert [f for f in _tree(out / "fit") if "/" not in f] == FIT_TOP
    assert "gen/unit.toml" in _tree(out / "fit")
    unit = ic.load_unit(out / "fit" / "calibrated.toml")
    for p in report["stages"][-1]["parameters"]:
        assert unit.parameters()[p["param"]] == pytest.approx(p["result"], rel=1e-12)
    # The diagnosis' folder: diagnosis.json, the named cause's re-fitted unit (extended.toml),
    # and the report is the same diagnosis run directly.
    names = set(_tree(out / "diagnose"))
    assert {"diagnosis.json", "extended.toml", "manifest.json"} <= names
    assert names <= {"diagnosis.json", "extended.toml", "manifest.json", "warnings.json"}
    assert "measurement" in ic.load_unit(out / "diagnose" / "extended.toml").blocks()
    d = ic.diagnose(list(job.events), fit=direct, causes=["measurement_skew"], seed=5, threads=1,
                    **DIAG_QUICK)
    _same(d.report, json.loads((out / "diagnose" / "diagnosis.json").read_text()))
    # row.json, last, is the row.
    written = json.loads((out / "row.json").read_text())
    assert {k: v for k, v in written.items() if k != "wall_s"} == {
        k: v for k, v in row.items() if k != "wall_s"}
    # A job that failed wrote nothing into its folder.
    assert list(Path(jobs[3].out).iterdir()) == []


def test_an_existing_job_folder_is_not_overwritten(fleet, jobs, tmp_path):
    job = _u3(jobs)
    out = Path(job.out)
    before = _snapshot(out)
    row = run_job(job)
    assert row["status"] == "failed" and row["step"] == "output"
    assert row["error_type"] == "FileExistsError" and "overwrite=True" in row["error"]
    assert row["j_fit"] is None  # refused before the fit
    assert _snapshot(out) == before
    # A folder holding only a fit (a job that stopped before its row) is not replaced either.
    part = tmp_path / "only-fit"
    shutil.copytree(out / "fit", part / "fit")
    kept = _snapshot(part)
    row = run_job(Job(**{**job.__dict__, "out": str(part)}))
    assert row["status"] == "failed" and row["step"] == "output" and "fit" in row["error"]
    assert _snapshot(part) == kept
    # An empty folder is no result: written into.
    (tmp_path / "empty" / "fit").mkdir(parents=True)
    quick = Job("empty", job.unit, job.events, calib=CALIB, stages="gen", seed=5,
                out=tmp_path / "empty", **QUICK)
    assert run_job(quick, threads=1)["status"] == "ok"
    _verify(tmp_path / "empty" / "fit")


def test_overwrite_replaces_the_sub_folders_whole(fleet, jobs, tmp_path):
    job = _u3(jobs)
    out = tmp_path / "u3"
    shutil.copytree(job.out, out)  # a copy: the module's folders stay as the fleet wrote them
    before = _snapshot(out)
    # A file of the user's in fit/ makes it no folder of ours: refused before the work (the
    # library's rule, as fit --force), nothing changed.
    (out / "fit" / "notes.txt").write_text("mine")
    row = run_job(Job(**{**job.__dict__, "out": str(out), "overwrite": True}), threads=1)
    assert row["status"] == "failed" and row["step"] == "output" and row["j_fit"] is None
    assert row["error_type"] == "OutputError" and "notes.txt" in row["error"]
    (out / "fit" / "notes.txt").unlink()
    assert _snapshot(out) == before
    # Overwritten by a job with two stages and no diagnosis: fit/ replaced whole (now with
    # avr/), diagnose/ of the earlier run removed, a new row.
    two = Job(**{**job.__dict__, "out": str(out), "overwrite": True, "stages": "gen,avr",
                 "diagnose": False, "causes": None})
    row = run_job(two, threads=1)
    assert row["status"] == "ok", row["error"]
    assert sorted(p.name for p in out.iterdir()) == ["fit", "row.json"]
    assert "avr/unit.toml" in _tree(out / "fit")
    _verify(out / "fit")
    assert json.loads((out / "row.json").read_text())["stages"] == "gen,avr"
    # And back: the diagnosed one-stage job; avr/ is gone, diagnose/ is back, the same numbers.
    row = run_job(Job(**{**job.__dict__, "out": str(out), "overwrite": True}), threads=1)
    assert row["status"] == "ok", row["error"]
    assert sorted(p.name for p in out.iterdir()) == ["diagnose", "fit", "row.json"]
    assert not any(f.startswith("avr/") for f in _tree(out / "fit"))
    _verify(out / "fit")
    _verify(out / "diagnose")
    _no_temporary(out)
    assert row["j_fit"] == pytest.approx(fleet["u3-diagnosed"]["j_fit"], rel=1e-12)
    assert row["cause"] == fleet["u3-diagnosed"]["cause"]
    assert (out / "row.json").read_bytes() != before["row.json"]  # a new row (pid, times)


def _fail_at_row(monkeypatch, exc):
    real = fleet_mod._commit

    def commit(tmp, final, overwrite):
        if final.name == "row.json":
            raise exc
        real(tmp, final, overwrite)

    monkeypatch.setattr(fleet_mod, "_commit", commit)


def test_a_job_failing_while_writing_leaves_no_row(files, monkeypatch, tmp_path):
    _fail_at_row(monkeypatch, OSError("disk full"))
    out = tmp_path / "failing"
    row = run_job(Job("i", files["nominal"], [files["ev1"]], calib=CALIB, stages="gen", out=out,
                      **QUICK))
    assert row["status"] == "failed" and row["step"] == "write" and row["error"] == "disk full"
    assert row["out"] is None
    assert sorted(p.name for p in out.iterdir()) == ["fit"]  # no row.json: not complete
    _verify(out / "fit")  # the fit's own folder is complete
    _no_temporary(out)


def test_an_interrupted_job_leaves_no_row(files, monkeypatch, tmp_path):
    out = tmp_path / "interrupted"
    job = Job("i", files["nominal"], [files["ev1"]], calib=CALIB, stages="gen", seed=1, out=out,
              **QUICK)
    assert run_job(job, threads=1)["status"] == "ok"
    # Interrupted while its row is written, overwriting: the earlier row went first, so the
    # folder is not complete (no old row beside the new fit), and no temporary file is left.
    _fail_at_row(monkeypatch, KeyboardInterrupt())
    with pytest.raises(KeyboardInterrupt):
        run_job(Job(**{**job.__dict__, "seed": 2, "overwrite": True}), threads=1)
    assert sorted(p.name for p in out.iterdir()) == ["fit"]
    assert json.loads((out / "fit" / "report.json").read_text())["seed"] == 2  # the new fit
    _verify(out / "fit")
    _no_temporary(out)


def test_ctrl_c_during_a_job_leaves_no_row(files, tmp_path):
    out = tmp_path / "ctrl-c"
    code = (
        "from itaipu_calib.fleet import Job, run_job\n"
        f"job = Job('long', {str(files['nominal'])!r}, [{str(files['ev1'])!r}], "
        f"calib={str(CALIB)!r}, stages='gen', seed=1, particles=40, pso_iterations=400, "
        f"local_iterations=50, out={str(out)!r})\n"
        "print('ready', flush=True)\n"
        "run_job(job, threads=1)\n"
        "print('finished', flush=True)\n"
    )
    proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().strip() == "ready"
        time.sleep(1.0)  # the fit runs
        proc.send_signal(signal.SIGINT)
        stdout, stderr = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert "finished" not in stdout and "KeyboardInterrupt" in stderr, stderr
    assert out.is_dir() and list(out.iterdir()) == []  # checked, then nothing written
    _no_temporary(out)


def test_a_one_job_fleet_is_the_direct_fit_and_diagnosis(tmp_path):
    """The bundled Itaipu record: one job (fit then diagnosis) gives the fit's J and the
    diagnosis' verdict of ic.fit + ic.diagnose called directly with the same seed; its fit
    folder is one the command line's diagnose --fit reads, to the same verdict. (Every stage:
    diagnose --fit DIR re-frees the parameters of every stage of the folder's calibration.toml,
    so only then is it the fit's calibrated set.)"""
    causes = ["measurement_skew", "terminal_load"]
    job = Job("itaipu", ITAIPU_UNIT, [ITAIPU_EVENT], calib=CALIB, stages="all", seed=3,
              particles=6, pso_iterations=3, local_iterations=3, diagnose=True, causes=causes,
              diagnose_particles=8, diagnose_pso_iterations=4, diagnose_local_iterations=3,
              out=tmp_path / "itaipu")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ic.ItaipuWarning)  # the record's end drop-out
        res = run_fleet([job], threads_per_job=2, progress=False)
        r = ic.fit(ITAIPU_EVENT, ITAIPU_UNIT, calib=CALIB, stages="all", seed=3, particles=6,
                   pso_iterations=3, local_iterations=3, threads=1)
        d = ic.diagnose(ITAIPU_EVENT, fit=r, causes=causes, seed=3, particles=8, pso_iterations=4,
                        local_iterations=3, threads=1)
    row = res["itaipu"]
    assert row["status"] == "ok", row["error"]
    assert row["threads"] == 2 and r.report["threads"] == 1
    assert row["j_start"] == pytest.approx(r.fitness[0][1], rel=1e-12)
    assert row["j_fit"] == pytest.approx(r.fitness[-1][1], rel=1e-12)
    assert row["j_fit"] < row["j_start"]
    assert row["stages"] == ",".join(r.stages) == "gen,avr,pss,tg,joint"
    assert row["cause"] == d.cause
    gains = d.verdict.get("gains") or {}
    for key in ("delta_bic", "fit_drop", "held_drop"):
        assert row[key] == (None if gains.get(key) is None else pytest.approx(gains[key], rel=1e-12))
    out = Path(row["out"])
    _same(r.report, json.loads((out / "fit" / "report.json").read_text()))
    diagnosis = json.loads((out / "diagnose" / "diagnosis.json").read_text())
    _same(d.report, diagnosis)
    assert sorted(c["cause"] for c in diagnosis["candidates"]) == sorted(causes)
    _verify(out / "fit")
    _verify(out / "diagnose")
    # The command line's diagnose --fit on the job's fit folder: the same verdict.
    code = _core._cli_main([
        "itaipu-calib", "diagnose", "--fit", str(out / "fit"), "--event", str(ITAIPU_EVENT),
        "--cause", ",".join(causes), "--seed", "3", "--particles", "8", "--pso-iterations", "4",
        "--local-iterations", "3", "--threads", "1", "--no-plot", "--out", str(tmp_path / "cli")])
    assert code == 0
    cli = json.loads((tmp_path / "cli" / "diagnosis.json").read_text())
    _same(diagnosis["verdict"], cli["verdict"])
    _same(diagnosis["candidates"], cli["candidates"])


# --- progress -------------------------------------------------------------------------------

LINE = r"fleet: (\d+)/(\d+) jobs done, (\d+) failed, \d+:\d\d elapsed"


class _Terminal(io.StringIO):
    def isatty(self):
        return True


def _two_jobs(files):
    return [Job("p1", files["nominal"], [files["ev1"]], calib=CALIB, stages="gen", seed=7, **QUICK),
            Job("p-missing", files["dir"] / "units" / "nope.toml", [files["ev1"]])]


def test_progress_on_stderr_one_line_per_job(files, capsys):
    res = run_fleet(_two_jobs(files), progress=True)
    assert [r["status"] for r in res.rows] == ["ok", "failed"]
    captured = capsys.readouterr()
    assert captured.out == ""
    lines = captured.err.splitlines()
    assert len(lines) == 2, lines
    assert re.fullmatch(LINE.replace(r"(\d+)/(\d+)", "1/2").replace(r"(\d+) failed", "0 failed")
                        + "; last: p1 ok", lines[0]), lines[0]
    assert re.fullmatch(LINE.replace(r"(\d+)/(\d+)", "2/2").replace(r"(\d+) failed", "1 failed")
                        + r"; last: p-missing failed \(UnitModelError in fit\)", lines[1]), lines[1]


def test_progress_by_default_only_on_a_terminal(files, monkeypatch):
    jobs = _two_jobs(files)
    tty = _Terminal()
    monkeypatch.setattr(sys, "stderr", tty)
    run_fleet(jobs)  # progress=None: stderr is a terminal
    text = tty.getvalue()
    # One line, rewritten in place, ended once.
    assert text.startswith("\rfleet: 0/2 jobs done, 0 failed, 0:00 elapsed") and text.endswith("\n")
    assert text.count("\n") == 1
    states = [re.match(LINE, t).groups() for t in text.rstrip("\n").split("\r")[1:]]
    assert states[0] == ("0", "2", "0") and states[-1] == ("2", "2", "1")
    assert ("1", "2", "0") in states
    assert text.rstrip().endswith("last: p-missing failed (UnitModelError in fit)")
    # Not a terminal: nothing. A terminal with progress=False: nothing.
    plain = io.StringIO()
    monkeypatch.setattr(sys, "stderr", plain)
    run_fleet(jobs)
    assert plain.getvalue() == ""
    tty = _Terminal()
    monkeypatch.setattr(sys, "stderr", tty)
    run_fleet(jobs, progress=False)
    assert tty.getvalue() == ""


def test_progress_clock_runs_during_a_long_job(monkeypatch):
    """On a terminal the line is refreshed every second while a job runs."""
    def slow_job(job, *, threads=None):
        time.sleep(2.5)
        row = dict.fromkeys(COLUMNS)
        row.update(job=job.name, status="ok")
        return row

    monkeypatch.setattr(fleet_mod, "run_job", slow_job)
    tty = _Terminal()
    monkeypatch.setattr(sys, "stderr", tty)
    run_fleet([Job("slow", "u.toml", "e.toml")])
    shown = [t.rstrip() for t in tty.getvalue().rstrip("\n").split("\r")[1:]]
    # Refreshed while the job ran (the clock past 0:00), then the job's line.
    assert any(re.fullmatch(r"fleet: 0/1 jobs done, 0 failed, 0:0[1-9] elapsed", t)
               for t in shown), shown
    assert re.fullmatch(r"fleet: 1/1 jobs done, 0 failed, 0:0[2-9] elapsed; last: slow ok",
                        shown[-1]), shown


def test_progress_callable_and_on_row_get_each_row(files):
    seen, also = [], []
    res = run_fleet(_two_jobs(files), progress=seen.append, on_row=also.append)
    assert seen == also == res.rows
    with pytest.raises(TypeError, match="progress must be"):
        run_fleet([], progress="yes")


def test_progress_on_the_dask_path(fleet, finished_rows, cluster, files, capsys):
    # The fixture's callable got each row once, as it finished.
    assert sorted(r["job"] for r in finished_rows) == sorted(r["job"] for r in fleet.rows)
    for r in finished_rows:
        assert r == fleet[r["job"]]
    res = run_fleet(_two_jobs(files), cluster, progress=True)
    lines = [ln for ln in capsys.readouterr().err.splitlines() if ln.startswith("fleet:")]
    assert [re.match(LINE, ln).groups() for ln in lines][-1] == ("2", "2", "1")
    assert len(lines) == 2 and [r["job"] for r in res.rows] == ["p1", "p-missing"]


# --- jobs ------------------------------------------------------------------------------------


def test_jobs_are_plain_picklable_data(files):
    j = Job("a", files["nominal"], files["ev1"], held_out=[files["ev2"]], stages=["avr", "gen"],
            diagnose=True, causes="measurement_skew;terminal_load")
    assert j.unit == str(files["nominal"]) and j.events == (str(files["ev1"]),)
    assert j.held_out == (str(files["ev2"]),) and j.stages == "gen,avr"
    assert j.causes == ("measurement_skew", "terminal_load")
    assert pickle.loads(pickle.dumps(j)) == j
    with pytest.raises(ValueError, match="unknown stage 'exciter'"):
        Job("a", "u.toml", "e.toml", stages="gen,exciter")
    with pytest.raises(ValueError, match="events is empty"):
        Job("a", "u.toml", [])
    with pytest.raises(ValueError, match="diagnose is False"):
        Job("a", "u.toml", "e.toml", causes=["oel"])
    with pytest.raises(ValueError, match="particles must be at least 2"):
        Job("a", "u.toml", "e.toml", particles=1)
    with pytest.raises(TypeError, match="seed must be an integer"):
        Job("a", "u.toml", "e.toml", seed=1.5)
    with pytest.raises(ValueError, match="two jobs are called 'a'"):
        run_fleet([Job("a", "u.toml", "e.toml"), Job("a", "v.toml", "e.toml")])
    with pytest.raises(TypeError, match="Job objects"):
        run_fleet([{"name": "a"}])


def test_stages_are_the_library_s(monkeypatch):
    names = ic.stages()
    assert names[-1] == "all"
    for name in names:
        assert Job("a", "u.toml", "e.toml", stages=name).stages == name
    with pytest.raises(ValueError) as e:
        Job("a", "u.toml", "e.toml", stages="gen,exciter")
    assert str(e.value).endswith(
        "unknown stage 'exciter' (" + ", ".join(names[:-1]) + " or " + names[-1] + ")")
    # A stage the library adds is known to the fleet, in the library's order.
    monkeypatch.setattr(_core, "stages", lambda: ["gen", "avr", "pss", "tg", "hydro", "all"])
    assert Job("a", "u.toml", "e.toml", stages="hydro+gen").stages == "gen,hydro"
    monkeypatch.undo()
    with pytest.raises(ValueError, match="unknown stage 'hydro'"):
        Job("a", "u.toml", "e.toml", stages="hydro")


class _Stop(Exception):
    pass


def _spy(monkeypatch, name, calls, stop):
    """fleet's _core with ``name`` recording its keyword arguments (and raising _Stop if
    ``stop``, before any work)."""
    real = getattr(_core, name)

    def spy(*args, **kwargs):
        calls[name] = kwargs
        if stop:
            raise _Stop(name)
        return real(*args, **kwargs)

    proxy = fleet_mod._core
    if not isinstance(proxy, types.SimpleNamespace):
        proxy = types.SimpleNamespace(**{k: getattr(_core, k) for k in dir(_core)
                                         if not k.startswith("__")})
        monkeypatch.setattr(fleet_mod, "_core", proxy)
    setattr(proxy, name, spy)


def test_unset_settings_are_left_to_the_library(files, monkeypatch):
    """None is passed on (the library's defaults: the spec's, or ic.defaults()), never a value
    of the fleet's own; the fit's polish only when given."""
    calls = {}
    _spy(monkeypatch, "fit", calls, stop=True)
    row = run_job(Job("d", TRUTH, [files["ev3"]], calib=CALIB))
    assert row["status"] == "failed" and row["step"] == "fit" and row["error_type"] == "_Stop"
    kw = calls["fit"]
    assert "polish" not in kw and "lbfgs_iterations" not in kw
    assert {k: kw[k] for k in ("seed", "particles", "pso_iterations", "local_iterations")} == dict.fromkeys(
        ("seed", "particles", "pso_iterations", "local_iterations"))
    _spy(monkeypatch, "fit", calls, stop=False)
    _spy(monkeypatch, "diagnose", calls, stop=True)
    row = run_job(Job("d", TRUTH, [files["ev3"]], calib=CALIB, stages="gen", diagnose=True,
                      causes=["measurement_skew"], **QUICK), threads=1)
    assert row["status"] == "failed" and row["step"] == "diagnose" and row["j_fit"] > 0
    assert calls["fit"]["polish"] is False and calls["fit"]["local_iterations"] == 2
    kw = calls["diagnose"]
    assert {k: kw[k] for k in ("seed", "particles", "pso_iterations", "local_iterations")} == dict.fromkeys(
        ("seed", "particles", "pso_iterations", "local_iterations"))
    assert "lbfgs_iterations" not in kw and kw.get("unit") is None
    assert isinstance(kw["fit"], ic.FitResult) and kw["causes"] == ["measurement_skew"]


def test_old_option_names_still_work_with_a_warning(tmp_path):
    with pytest.warns(DeprecationWarning) as rec:
        j = Job("a", "u.toml", "e.toml", lbfgs_iterations=3, diagnose=True,
                diagnose_lbfgs_iterations=4)
    assert [str(w.message) for w in rec] == [
        "lbfgs_iterations is deprecated: it is now local_iterations (it caps the local method, "
        "Levenberg-Marquardt or L-BFGS)",
        "diagnose_lbfgs_iterations is deprecated: it is now diagnose_local_iterations (it caps "
        "the local method, Levenberg-Marquardt or L-BFGS)",
    ]
    assert {w.filename for w in rec} == {__file__}  # the warning points at the Job(...) call
    assert j == Job("a", "u.toml", "e.toml", local_iterations=3, diagnose=True,
                    diagnose_local_iterations=4)
    assert pickle.loads(pickle.dumps(j)) == j
    with pytest.warns(DeprecationWarning, match="Job.lbfgs_iterations is deprecated"):
        assert j.lbfgs_iterations == 3
    with pytest.warns(DeprecationWarning, match="Job.diagnose_lbfgs_iterations is deprecated"):
        assert j.diagnose_lbfgs_iterations == 4
    with pytest.raises(TypeError, match="local_iterations and lbfgs_iterations .its old name. were both given"):
        Job("a", "u.toml", "e.toml", local_iterations=2, lbfgs_iterations=2)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the new names: no warning
        assert Job("a", "u.toml", "e.toml", local_iterations=3).local_iterations == 3
    # The job table's old column name.
    table = tmp_path / "old.csv"
    table.write_text("name,unit,events,lbfgs_iterations\na,u.toml,e.toml,5\n")
    with pytest.warns(DeprecationWarning, match="column lbfgs_iterations is deprecated: it is now local_iterations"):
        (old,) = jobs_from_csv(table)
    assert old.local_iterations == 5
    table.write_text("name,unit,events,lbfgs_iterations\na,u.toml,e.toml,x\n")
    with pytest.warns(DeprecationWarning), pytest.raises(ValueError, match="line 2, column lbfgs_iterations: not an integer"):
        jobs_from_csv(table)
    table.write_text("name,unit,events,lbfgs_iterations,local_iterations\na,u.toml,e.toml,5,5\n")
    with pytest.raises(ValueError, match="line 1, column lbfgs_iterations: the old name of column local_iterations"):
        jobs_from_csv(table)


def test_jobs_from_csv_resolves_relative_paths(files, tmp_path):
    table = tmp_path / "tables" / "fleet.csv"
    table.parent.mkdir()
    ev1, ev2 = (os.path.relpath(files[k], table.parent) for k in ("ev1", "ev2"))
    unit = os.path.relpath(files["nominal"], table.parent)
    table.write_text(
        "name,unit,events,held_out,calib,stages,seed,diagnose,particles,pso_iterations,local_iterations,out\n"
        "# a comment line\n"
        f"u1,{unit},{ev1};{ev2},,{CALIB},gen,7,,4,2,2,out/u1\n"
        "\n"
        f'u2,{unit},{ev2},{ev1},,"gen,avr",,measurement_skew;terminal_load,,,,\n'
        f"u3,{files['nominal']},{ev1},,,,,yes,,,,\n"
    )
    jobs = jobs_from_csv(table)
    assert [j.name for j in jobs] == ["u1", "u2", "u3"]
    u1, u2, u3 = jobs
    assert Path(u1.unit) == (table.parent / unit) and Path(u1.unit).resolve() == files["nominal"].resolve()
    assert [Path(e).resolve() for e in u1.events] == [files["ev1"].resolve(), files["ev2"].resolve()]
    assert u1.calib == str(CALIB) and u1.stages == "gen" and u1.seed == 7 and u1.particles == 4
    assert (u1.pso_iterations, u1.local_iterations) == (2, 2)
    assert Path(u1.out) == table.parent / "out" / "u1" and not u1.diagnose
    assert [Path(e).resolve() for e in u2.held_out] == [files["ev1"].resolve()]
    assert u2.stages == "gen,avr" and u2.seed is None and u2.calib is None and u2.out is None
    assert u2.diagnose and u2.causes == ("measurement_skew", "terminal_load")
    assert u3.unit == str(files["nominal"]) and u3.diagnose and u3.causes is None
    # The jobs run: u1 in process gives the numbers of the same Job written by hand.
    row = run_job(Job(**{**u1.__dict__, "out": None}), threads=1)
    direct = ic.fit([files["ev1"], files["ev2"]], files["nominal"], calib=CALIB, stages="gen", seed=7,
                    particles=4, pso_iterations=2, local_iterations=2)
    assert row["status"] == "ok" and row["n_events"] == 2
    assert row["j_fit"] == pytest.approx(direct.fitness[-1][1], rel=1e-12)


@pytest.mark.parametrize(
    "text, line, column, what",
    [
        ("name,unit,events,seed\na,u.toml,e.toml,1\nb,u.toml,e.toml,x\n", 3, "seed", "not an integer"),
        ("name,unit,events\n\n# c\na,u.toml,\n", 4, "events", "no event"),
        ("name,unit,events,colour\na,u.toml,e.toml,red\n", 1, "colour", "unknown column"),
        ("name,unit\na,u.toml\n", 1, "events", "missing column"),
        ("name,unit,events,stages\na,u.toml,e.toml,gen+exciter\n", 2, "stages", "unknown stage 'exciter'"),
        ("name,unit,events,diagnose\na,u.toml,e.toml,earthquake\n", 2, "diagnose", "unknown cause 'earthquake'"),
        ("name,unit,events\na,u.toml,e.toml\na,v.toml,e.toml\n", 3, "name", "already the name of line 2"),
        ("name,unit,events,particles\na,u.toml,e.toml,1\n", 2, "particles", "at least 2"),
    ],
)
def test_jobs_from_csv_names_the_line_of_a_bad_row(tmp_path, text, line, column, what):
    table = tmp_path / "fleet.csv"
    table.write_text(text)
    with pytest.raises(ValueError) as e:
        jobs_from_csv(table)
    msg = str(e.value)
    assert msg.startswith(f"{table}, line {line}, column {column}: "), msg
    assert what in msg


def test_jobs_from_csv_counts_cells(tmp_path):
    table = tmp_path / "fleet.csv"
    table.write_text("name,unit,events\na,u.toml,e.toml,extra\n")
    with pytest.raises(ValueError, match=r"fleet.csv, line 2: 4 cells, the header has 3"):
        jobs_from_csv(table)
