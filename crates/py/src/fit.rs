//! `fit` and its `FitResult`.

use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::sync::{Arc, Mutex};

use pyo3::exceptions::{PyKeyError, PyRuntimeError};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use itaipu_calib::bounds::FreeBound;
use itaipu_calib::fit::{self as calib_fit, FitReport, Silent, StageOutput};
use itaipu_calib::job;
use itaipu_calib::spec::Strategy;
use itaipu_dynamics::unit::Unit;

use crate::args::{
    event_sources, load_events, source, str_or_list, swap_error, swapped_events_unit, worker_pool,
    Source,
};
use crate::diagnose::json_to_py;
use crate::errors::{request_error, Failure, IntoPyErr};
use crate::traces::PyTraces;
use crate::unit::PyUnit;
use crate::{interrupt, pandas, params};
use itaipu_calib::request::{FitRequest, Search, Stage};

/// Result of `fit`: the report, the calibrated unit, and per stage its parameters and traces.
///
/// `report` is the fit report as a dict (the `report.json` of the command line: a new dict on
/// each access; non-finite numbers such as an undetermined standard error are None). `unit` is
/// the calibrated full unit. `stages` lists the stages run, in order (`gen`, `avr`, `pss`, `tg`,
/// and `joint` for the final joint polish, `simultaneous` first with that strategy).
/// `parameters(stage)` gives a stage's calibrated free parameters, `fitness` the fitness table of
/// the command line, `traces(stage)` the start and calibrated traces of a stage.
#[pyclass(name = "FitResult", module = "itaipu_calib", frozen)]
pub(crate) struct PyFitResult {
    pub(crate) report: FitReport,
    /// The whole report as JSON text (`report.json`: [`FitSummary::to_json`]).
    pub(crate) report_json: String,
    /// The report as text ([`FitSummary::to_text`]).
    pub(crate) report_text: String,
    pub(crate) warnings: Vec<String>,
    pub(crate) unit: Arc<Unit>,
    /// The calibrated set with the calibration's prior, for `diagnose(..., fit=...)`.
    pub(crate) calibrated_set: Vec<FreeBound>,
    /// The finished fit (its stages' units and traces; what [`job::write_fit_files`] needs to
    /// write the fit's folder).
    pub(crate) run: Arc<job::FitRun>,
    pub(crate) spec_text: String,
    /// What the HTML report's figures play back and its provenance lists: the fitted and
    /// held-out events, and the input files (role, path).
    pub(crate) events: Arc<(
        Vec<itaipu_dynamics::event::Event>,
        Vec<itaipu_dynamics::event::Event>,
    )>,
    pub(crate) files: Vec<(String, PathBuf)>,
}

impl PyFitResult {
    fn unknown_stage(&self, stage: &str) -> PyErr {
        let names: Vec<&str> = self.run.stages.iter().map(|s| s.stage.as_str()).collect();
        PyKeyError::new_err(format!(
            "no stage '{stage}' in this fit (stages: {})",
            names.join(", ")
        ))
    }

    /// J = Σ(ΔP² + ΔQ²) summed over the fitted (not held-out) events.
    fn j_fitted(rows: &[calib_fit::EventFitness]) -> f64 {
        rows.iter().filter(|f| !f.held_out).map(|f| f.j_pq).sum()
    }
}

#[pymethods]
impl PyFitResult {
    /// The fit report (the command line's `report.json`): a dict (unit, events, held_out,
    /// strategy, seed, threads, start_fitness, stages: the stage reports with parameters, fit
    /// statistics, determination flags, correlations, fitness, phases...; warnings, noise,
    /// wall_s). Calling it, `result.report()`, gives the report as text (what the command line
    /// prints; also `fit_report()` and `print(result)`).
    #[getter]
    fn report<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let d = py
            .import("json")?
            .call_method1("loads", (&self.report_json,))?;
        py.import("itaipu_calib._report")?
            .getattr("Report")?
            .call1((d, &self.report_text))
    }

    /// The one sentence on how far the calibrated unit's residual lies above the noise: "at
    /// most X × the noise σ" (the library's, as `report["headline"]`, the command line's and
    /// the HTML report's; a diagnosis of the calibrated unit says the same).
    #[getter]
    fn headline(&self) -> String {
        self.run.report.headline.sentence.clone()
    }

    /// The plausibility warnings on the inputs (each a line naming the file, the sample or
    /// parameter, and the fix), as in the report's `warnings`.
    #[getter]
    fn warnings(&self) -> Vec<String> {
        self.warnings.clone()
    }

    /// Writes the fit's files into the folder `out` as the command line's `fit --out` does
    /// (report.json, calibrated.toml, datasheet.toml, calibration.toml, a folder per stage with
    /// its unit and traces, manifest.json last; no stage plots): through a temporary folder
    /// renamed into place, so that `out` is complete or absent. `html=True` writes the report a
    /// reviewer signs too, `report.html`, the command line's page (provenance, headline and
    /// verdict, stage and parameter tables, figures). An existing non-empty `out` is refused
    /// unless `overwrite=True` (and then only a folder of ours, replaced whole). Returns the
    /// folder. Raises OutputError.
    #[pyo3(signature = (out, *, overwrite = false, html = false))]
    fn write(
        &self,
        py: Python<'_>,
        out: PathBuf,
        overwrite: bool,
        html: bool,
    ) -> PyResult<PathBuf> {
        let run = self.run.clone();
        let spec_text = self.spec_text.clone();
        let events = self.events.clone();
        let files = self.files.clone();
        py.detach(move || -> Result<PathBuf, Failure> {
            Failure::catch("FitResult.write", || {
                let staging = itaipu_calib::output::prepare_out(Some(&out), "fit", overwrite)?;
                for st in &run.stages {
                    job::write_stage_files(staging.path(), st, |_| Ok(()))?;
                }
                job::write_fit_files(staging.path(), &run, &spec_text)?;
                if html {
                    use itaipu_calib_cli::report::InputFile;
                    let mut inputs: Vec<InputFile> = files
                        .iter()
                        .map(|(role, p)| InputFile::new(role, p))
                        .collect();
                    inputs.extend(events.0.iter().flat_map(|e| InputFile::event(e, false)));
                    inputs.extend(events.1.iter().flat_map(|e| InputFile::event(e, true)));
                    let page = itaipu_calib_cli::fit_cmd::fit_report_html(
                        &run.report.to_json()?,
                        &run,
                        &events.0,
                        &events.1,
                        inputs,
                        true,
                    );
                    itaipu_calib::output::write_synced(
                        &staging.path().join("report.html"),
                        page.as_bytes(),
                    )?;
                }
                staging.commit(
                    Some(run.options.seed),
                    vec![
                        "itaipu_calib.FitResult.write".into(),
                        out.display().to_string(),
                    ],
                )
            })
        })
        .map_err(|e| e.into_pyerr(py))
    }

    /// The calibrated full unit (every block, with every stage's results).
    #[getter]
    fn unit(&self) -> PyUnit {
        PyUnit {
            inner: self.unit.clone(),
            path: None,
        }
    }

    /// Names of the stages run, in order.
    #[getter]
    fn stages(&self) -> Vec<String> {
        self.run.stages.iter().map(|s| s.stage.clone()).collect()
    }

    /// Calibrated values of the free parameters of `stage`: `{"block.name": value}` in the
    /// spec's order. Raises KeyError for a stage that did not run.
    fn parameters<'py>(&self, py: Python<'py>, stage: &str) -> PyResult<Bound<'py, PyDict>> {
        let rep = self
            .report
            .stages
            .iter()
            .find(|s| s.stage == stage)
            .ok_or_else(|| self.unknown_stage(stage))?;
        let d = PyDict::new(py);
        for p in &rep.parameters {
            d.set_item(&p.param, p.result)?;
        }
        Ok(d)
    }

    /// The fitness table of the command line: `[("start", J), (stage, J), ...]` with
    /// J = Σ(ΔP² + ΔQ²) over the fit window on the system base (RaPId's J), summed over the
    /// fitted events (per-event and held-out values are in `report`).
    #[getter]
    fn fitness(&self) -> Vec<(String, f64)> {
        let mut rows = vec![(
            "start".to_string(),
            Self::j_fitted(&self.report.start_fitness),
        )];
        rows.extend(
            self.report
                .stages
                .iter()
                .map(|s| (s.stage.clone(), Self::j_fitted(&s.fitness))),
        );
        rows
    }

    /// `(start, calibrated)`: Traces of the stage's unit before and after the stage, on the
    /// first fitted event or on the event named `event`. Raises KeyError for an unknown stage or
    /// event.
    #[pyo3(signature = (stage, event = None))]
    fn traces(&self, stage: &str, event: Option<&str>) -> PyResult<(PyTraces, PyTraces)> {
        let st = self
            .run
            .stages
            .iter()
            .find(|s| s.stage == stage)
            .ok_or_else(|| self.unknown_stage(stage))?;
        let found = match event {
            None => st.traces.first(),
            Some(name) => st.traces.iter().find(|(e, _, _)| e == name),
        };
        let (_, start, end) = found.ok_or_else(|| {
            let names: Vec<&str> = st.traces.iter().map(|(e, _, _)| e.as_str()).collect();
            PyKeyError::new_err(format!(
                "no event '{}' in this fit (events: {})",
                event.unwrap_or(""),
                names.join(", ")
            ))
        })?;
        Ok((
            PyTraces {
                inner: start.clone(),
            },
            PyTraces { inner: end.clone() },
        ))
    }

    /// lmfit-like parameter objects `{name: Parameter}` (value, stderr, init_value, min, max,
    /// at_bound, correl, stage, units): of `stage`, or by default of the whole fit, each
    /// parameter from the last stage that freed it (the values of `unit`). Raises KeyError for
    /// a stage that did not run.
    #[pyo3(signature = (stage = None))]
    fn params<'py>(&self, py: Python<'py>, stage: Option<&str>) -> PyResult<Bound<'py, PyDict>> {
        let ps = match stage {
            None => params::final_params(&self.report.stages),
            Some(name) => params::of_stage(
                self.report
                    .stages
                    .iter()
                    .find(|s| s.stage == name)
                    .ok_or_else(|| self.unknown_stage(name))?,
            ),
        };
        params_dict(py, &ps)
    }

    /// The fit report as text (what `itaipu-calib fit` prints): per stage the phases, the
    /// parameter table (start, bounds, result, standard error, at bound), what the data do not
    /// determine; then J per event and stage. `print(result)` prints the same.
    fn fit_report(&self) -> String {
        self.report_text.clone()
    }

    fn __str__(&self) -> String {
        self.report_text.clone()
    }

    /// The parameters of `params()` as a pandas DataFrame indexed by name (columns stage,
    /// value, stderr (NaN: not determined), init_value, min, max, at_bound, units). Needs
    /// pandas.
    fn to_pandas<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let rows = params::final_params(&self.report.stages)
            .iter()
            .map(|p| p.row(py))
            .collect::<PyResult<Vec<_>>>()?;
        pandas::data_frame(py, pandas::rows(py, rows)?, Some("name"))
    }

    fn __repr__(&self) -> String {
        let r = &self.report;
        let rows = self.fitness();
        let (j0, j1) = (
            rows.first().map_or(f64::NAN, |r| r.1),
            rows.last().map_or(f64::NAN, |r| r.1),
        );
        format!(
            "<FitResult '{}' on {}: stages {}, J {:.5} -> {:.5}, {:.1} s>",
            r.unit,
            r.events.join(", "),
            self.stages().join(" -> "),
            j0,
            j1,
            r.wall_s
        )
    }
}

/// Calibrates `unit` against `events`, stage by stage (a parallel particle swarm, then
/// Levenberg-Marquardt, or L-BFGS with `local = "lbfgs"` in the spec),
/// as the command line's `fit`: the same library job ([`job::run_fit`]), so the same numbers,
/// warnings and report.
///
/// `events` (and `held_out`) are paths to event files or Event objects, or lists of them; the
/// objective sums over `events`, `held_out` events are only scored. `unit` is a path (a unit
/// TOML file, or a PSS/E `.dyr` with its `<stem>.bases.toml` beside it) or a Unit. `calib` is a
/// file with a `[calibration]` table; by default the unit file's own (a Unit that was not read
/// from a file, or a `.dyr`, then needs `calib`). `stages` is "all" (every stage the spec lists)
/// or some of gen, avr, pss, tg (a list or a comma-separated string), run in that order.
/// `strategy` ('sequential', 'incremental', 'simultaneous-first'), `seed`, `particles`,
/// `pso_iterations` and `local_iterations` (the local method's iterations: Levenberg-Marquardt
/// steps or L-BFGS iterations; `lbfgs_iterations` is the old name) override the spec (None:
/// the spec's, else `defaults()["fit"]`); `polish=False` skips the final joint refinement
/// ('joint') after several stages. `threads` sets the worker threads (default: all cores); same
/// seed, same numbers, whatever the number of threads. The GIL is released while files are
/// read and the fit runs. Plausibility warnings on the inputs are issued as `ItaipuWarning`s
/// and kept in `FitResult.warnings`.
///
/// Raises CalibrationError (bad spec, or a fit that cannot run), EventError, UnitModelError,
/// InitError (the unit cannot start at the measured operating point), ValueError for bad
/// options, TypeError for bad argument types.
#[pyfunction]
#[pyo3(
    signature = (events, unit, *, calib = None, stages = None, strategy = None, seed = None, particles = None,
                 pso_iterations = None, local_iterations = None, polish = true, held_out = None,
                 threads = None, lbfgs_iterations = None),
    text_signature = "(events, unit, *, calib=None, stages='all', strategy=None, seed=None, particles=None, \
                      pso_iterations=None, local_iterations=None, polish=True, held_out=(), threads=None)"
)]
#[allow(clippy::too_many_arguments)]
pub(crate) fn fit(
    py: Python<'_>,
    events: &Bound<'_, PyAny>,
    unit: &Bound<'_, PyAny>,
    calib: Option<PathBuf>,
    stages: Option<&Bound<'_, PyAny>>,
    strategy: Option<&str>,
    seed: Option<&Bound<'_, PyAny>>,
    particles: Option<&Bound<'_, PyAny>>,
    pso_iterations: Option<&Bound<'_, PyAny>>,
    local_iterations: Option<&Bound<'_, PyAny>>,
    polish: bool,
    held_out: Option<&Bound<'_, PyAny>>,
    threads: Option<&Bound<'_, PyAny>>,
    lbfgs_iterations: Option<&Bound<'_, PyAny>>,
) -> PyResult<PyFitResult> {
    if swapped_events_unit(py, events, unit)? {
        return Err(swap_error("fit"));
    }
    use crate::args::whole;
    let (seed, particles, pso_iterations, threads): (
        Option<u64>,
        Option<usize>,
        Option<usize>,
        Option<usize>,
    ) = (
        whole(py, seed, "seed")?,
        whole(py, particles, "particles")?,
        whole(py, pso_iterations, "pso_iterations")?,
        whole(py, threads, "threads")?,
    );
    let (local_iterations, lbfgs_iterations): (Option<u64>, Option<u64>) = (
        whole(py, local_iterations, "local_iterations")?,
        whole(py, lbfgs_iterations, "lbfgs_iterations")?,
    );
    let local_iterations = crate::args::renamed(
        py,
        "lbfgs_iterations",
        "local_iterations",
        lbfgs_iterations,
        local_iterations,
    )?;
    let events = event_sources(events, "events")?;
    let unit_src = source::<PyUnit, _>(unit, "unit", |u| u.inner.clone())?;
    let held_out = match held_out {
        Some(h) => event_sources(h, "held_out")?,
        None => vec![],
    };
    let unit_file: Option<PathBuf> = match &unit_src {
        Source::Path(p) => Some(p.clone()),
        Source::Loaded(_) => unit.cast::<PyUnit>()?.get().path.clone(),
    };
    let request = FitRequest {
        stages: stage_list(stages)?,
        strategy: strategy
            .map(str::parse::<Strategy>)
            .transpose()
            .map_err(request_error)?,
        search: Search {
            seed,
            particles,
            pso_iterations,
            local_iterations,
            threads,
        },
        no_polish: !polish,
    };
    request.search.validate().map_err(request_error)?;
    let pool = worker_pool(threads)?;
    // Inputs, options and warnings first (quick), with the GIL released.
    let prepared = py.detach(move || {
        Failure::catch("fit", || {
            let unit = match unit_src {
                Source::Loaded(u) => Arc::unwrap_or_clone(u),
                Source::Path(p) => job::load_unit(&p)?.unit,
            };
            let (spec, spec_path, spec_text) =
                job::FitInputs::read_spec(calib.as_deref(), unit_file.as_deref())?;
            let inputs = job::FitInputs {
                unit,
                unit_path: unit_file,
                spec,
                spec_path: Some(spec_path),
                spec_text: Some(spec_text),
                events: load_events(events)?,
                held_out: load_events(held_out)?,
            };
            let (opts, warnings) = job::prepare_fit(&inputs, &request)?;
            Ok((inputs, opts, warnings))
        })
    });
    let (inputs, opts, warnings) = prepared.map_err(|e| e.into_pyerr(py))?;
    crate::errors::warn_all(py, &warnings)?;
    let warned = warnings.clone();
    let kept_events = Arc::new((inputs.events.clone(), inputs.held_out.clone()));
    let mut files: Vec<(String, PathBuf)> = vec![];
    files.extend(
        inputs
            .unit_path
            .iter()
            .map(|p| ("unit".to_string(), p.clone())),
    );
    files.extend(
        inputs
            .spec_path
            .iter()
            .map(|p| ("calibration spec".to_string(), p.clone())),
    );
    // Ctrl-C (KeyboardInterrupt) stops the fit at its next candidate evaluation; the passes
    // finished by then are kept on the exception (see `fit`'s documentation).
    let cancel = Arc::new(AtomicBool::new(false));
    let worker_cancel = cancel.clone();
    let finished: Arc<Mutex<Vec<(calib_fit::StageReport, Unit)>>> = Arc::default();
    let worker_finished = finished.clone();
    let work = move || -> Result<(job::FitRun, String), Failure> {
        Failure::catch("fit", || {
            let on_stage = |rep: &calib_fit::StageReport,
                            _: &StageOutput,
                            master: &Unit|
             -> Result<(), calib_fit::FitError> {
                if let Ok(mut f) = worker_finished.lock() {
                    f.push((rep.clone(), master.clone()));
                }
                Ok(())
            };
            let control = calib_fit::FitControl {
                cancel: Some(worker_cancel),
                on_stage: Some(&on_stage),
                ..Default::default()
            };
            let run = || {
                job::run_fit(
                    &inputs,
                    &opts,
                    warnings,
                    &Silent,
                    &control,
                    Default::default(),
                )
            };
            let run = match &pool {
                Some(pool) => pool.install(run),
                None => run(),
            }?;
            Ok((run, inputs.spec_text.clone().unwrap_or_default()))
        })
    };
    let result = interrupt::interruptible(py, Some(cancel), work).inspect_err(|e| {
        if let Ok(f) = finished.lock() {
            let _ = keep_finished(py, e, &f);
        }
    })?;
    let (run, spec_text) = result.map_err(|e| e.into_pyerr(py))?;
    // The warnings the run added (the calibrated unit's plausibility), each once.
    let added: Vec<_> = run
        .report
        .warnings
        .iter()
        .filter(|w| !warned.contains(w))
        .cloned()
        .collect();
    crate::errors::warn_all(py, &added)?;
    let mut r = PyFitResult::new(run, spec_text)?;
    r.events = kept_events;
    r.files = files;
    Ok(r)
}

impl PyFitResult {
    /// The Python result of a finished fit.
    pub(crate) fn new(run: job::FitRun, spec_text: String) -> PyResult<Self> {
        let report_json = run
            .report
            .to_json()
            .and_then(|v| {
                serde_json::to_string(&v).map_err(|e| itaipu_calib::Error::Output(e.to_string()))
            })
            .map_err(|e| PyRuntimeError::new_err(format!("fit report: {e}")))?;
        Ok(PyFitResult {
            report: run.report.fit.clone(),
            report_json,
            report_text: run.report.to_text(),
            warnings: run.report.warnings.iter().map(|w| w.to_string()).collect(),
            unit: Arc::new(run.unit.clone()),
            calibrated_set: run.calibrated_set.clone(),
            spec_text,
            run: Arc::new(run),
            events: Arc::default(),
            files: vec![],
        })
    }
}

/// Puts what an interrupted fit finished on its KeyboardInterrupt: `finished_stages` (names,
/// in order), `unit` (the full unit after the last of them, or None), `params` (`{name:
/// Parameter}` of those stages) and `stage_reports` (their reports as dicts).
pub(crate) fn keep_finished(
    py: Python<'_>,
    e: &PyErr,
    finished: &[(calib_fit::StageReport, Unit)],
) -> PyResult<()> {
    let exc = e.value(py);
    let names: Vec<&str> = finished.iter().map(|(r, _)| r.stage.as_str()).collect();
    exc.setattr("finished_stages", names)?;
    exc.setattr(
        "unit",
        finished.last().map(|(_, u)| PyUnit {
            inner: Arc::new(u.clone()),
            path: None,
        }),
    )?;
    let reports: Vec<calib_fit::StageReport> = finished.iter().map(|(r, _)| r.clone()).collect();
    exc.setattr("params", params_dict(py, &params::final_params(&reports))?)?;
    let json = serde_json::to_value(&reports)
        .map_err(|e| PyRuntimeError::new_err(format!("fit report: {e}")))?;
    exc.setattr("stage_reports", json_to_py(py, &json)?)?;
    Ok(())
}

/// `{name: Parameter}` in order.
pub(crate) fn params_dict<'py>(
    py: Python<'py>,
    ps: &[params::PyParameter],
) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    for p in ps {
        d.set_item(p.name(), p.clone())?;
    }
    Ok(d)
}

/// The stages from the `stages` argument, as the command line's `--stage`: "all" (or None:
/// every stage the spec lists) or names among gen, avr, pss, tg (a list, or one string with
/// commas), checked by [`Stage::parse_list`].
fn stage_list(arg: Option<&Bound<'_, PyAny>>) -> PyResult<Vec<Stage>> {
    let Some(arg) = arg else { return Ok(vec![]) };
    let given = str_or_list(
        arg,
        "stages must be 'all', a stage name, a comma-separated string or a list of stage names",
    )?;
    Stage::parse_list(&given).map_err(request_error)
}
