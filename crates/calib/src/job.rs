//! The jobs every front end runs, decided here once: reading the inputs, the plausibility layer,
//! the fit and its report (`report.json`), the diagnosis and its report (`diagnosis.json`), and
//! the files of their output folders. The command line, the Python module and a fleet's jobs
//! only gather their arguments into these types, call them, and render what they return, so
//! that the same record and unit give the same numbers, warnings and verdict whatever the path.
//!
//! * [`load_unit`], [`load_event`]: a unit file (TOML, or PSS/E `.dyr` with the bases file
//!   beside it) and an event file.
//! * [`check_inputs`]: the plausibility layer on the events and the unit (an error stops the
//!   run; warnings go into the report).
//! * [`FitInputs`], [`run_fit`] → [`FitRun`] with its [`FitSummary`] (`report.json`);
//!   [`write_fit_files`], [`write_stage_files`].
//! * [`diagnose_inputs`] (the unit and the re-freed calibrated set of a fit, from a
//!   [`FitRun`] or a fit folder), [`run_diagnose`] → [`DiagnoseRun`];
//!   [`write_diagnosis_files`].

use std::path::{Path, PathBuf};

use itaipu_dynamics::dyr::{read_dyr, resolve_bases, side_file, PartialBases};
use itaipu_dynamics::event::Event;
use itaipu_dynamics::plausibility::{self, Finding, Severity};
use itaipu_dynamics::simulate::{simulate, SimError};
use itaipu_dynamics::unit::Unit;
use itaipu_dynamics::unit_file::{read_unit, unit_to_toml};

use crate::bounds::FreeBound;
use crate::diagnose::{self, DiagnoseOptions, DiagnoseResult, Diagnosis};
use crate::fit::{fit_with, FitControl, FitOptions, FitReport, Progress, StageOutput};
use crate::output::write_synced;
use crate::request::{DiagnoseRequest, FitRequest};
use crate::spec::CalibSpec;
use crate::Error;

// -------------------------------------------------------------------------------------------
// Inputs
// -------------------------------------------------------------------------------------------

/// A unit read from a file, with what reading it had to say.
#[derive(Clone)]
pub struct LoadedUnit {
    pub unit: Unit,
    /// Warnings of the reader (a `.dyr` record that lost something, a base assumed).
    pub warnings: Vec<String>,
}

/// Reads a unit file: a PSS/E `.dyr` (any case of the extension) with the bases of
/// `<stem>.bases.toml` beside it, otherwise a unit TOML file.
pub fn load_unit(path: &Path) -> Result<LoadedUnit, Error> {
    let is_dyr = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("dyr"));
    if !is_dyr {
        return Ok(LoadedUnit {
            unit: read_unit(path)?,
            warnings: vec![],
        });
    }
    let bases = resolve_bases(path, None, &PartialBases::default()).map_err(|e| match e {
        itaipu_dynamics::dyr::DyrError::Bases {
            path: p,
            field,
            msg,
        } if p == path => itaipu_dynamics::dyr::DyrError::Bases {
            path: p,
            field,
            msg: format!(
                "{msg} (a .dyr needs its bases: write them beside it as {}, or read it with `itaipu-calib dyr read` and its --mbase/--nominal-hz options)",
                side_file(path).display()
            ),
        },
        e => e,
    })?;
    let d = read_dyr(path, None, &bases)?;
    Ok(LoadedUnit {
        unit: d.unit,
        warnings: d.warnings.iter().map(|w| w.to_string()).collect(),
    })
}

/// Reads an event file (TOML and its recording).
pub fn load_event(path: &Path) -> Result<Event, Error> {
    Ok(Event::from_toml_file(path)?)
}

/// The plausibility layer ([`itaipu_dynamics::plausibility`]) on `events` (against the unit's
/// rating) and on the unit's parameters (`unit_path` names the file in the findings): an error
/// stops the run ([`Error::Implausible`], every error listed with file, line, column and fix);
/// the warnings are returned, for the report.
pub fn check_inputs(
    events: &[&Event],
    unit: &Unit,
    unit_path: Option<&Path>,
) -> Result<Vec<Finding>, Error> {
    let mut all = vec![];
    for e in events {
        all.extend(plausibility::check_event(e, Some(unit.machine_mva)));
    }
    let file = unit_path
        .map(Path::to_path_buf)
        .unwrap_or_else(|| PathBuf::from(format!("unit '{}'", unit.name)));
    all.extend(plausibility::check_unit(unit, &file));
    let errors: Vec<String> = all
        .iter()
        .filter(|f| f.severity == Severity::Error)
        .map(|f| f.to_string())
        .collect();
    if !errors.is_empty() {
        return Err(Error::Implausible(errors));
    }
    Ok(all)
}

/// One playback of `unit` on `event` (milliseconds): a unit that does not initialise or
/// integrate on an event as given stops here, with the sample or the operating point the
/// failure comes from ([`explain`]).
pub fn preflight(unit: &Unit, event: &Event) -> Result<(), Error> {
    simulate(unit, event, &Default::default())
        .map(|_| ())
        .map_err(|e| explain(e, event, unit))
}

/// [`preflight`] in the diagnosis's playback (a mode's for a record without an angle).
pub fn preflight_in(unit: &Unit, event: &Event, pb: &diagnose::Playback) -> Result<(), Error> {
    if pb.is_pq_phasor() {
        return preflight(unit, event);
    }
    let ev = itaipu_dynamics::simulate::PreparedEvent::new(event);
    itaipu_dynamics::mode::simulate_mode(unit, &ev, pb.mode, &Default::default())
        .map(|_| ())
        .map_err(|e| explain(e, event, unit))
}

/// A simulation error traced back to the data: an integration failure at time t names the
/// samples around t, an initialisation failure the operating point it was given.
pub fn explain(e: SimError, event: &Event, unit: &Unit) -> Error {
    use itaipu_dynamics::integrate::SolveError;
    let t = match &e {
        SimError::Solve(
            SolveError::NonFinite { t, .. }
            | SolveError::StepUnderflow { t, .. }
            | SolveError::TooManySteps { t, .. }
            | SolveError::EventLoop { t },
        )
        | SimError::ModeSolve { t, .. } => Some(*t),
        _ => None,
    };
    let detail = match (&e, t) {
        (_, Some(t)) => Some(plausibility::locate_time(event, t)),
        (SimError::Init(_), None) => Some(plausibility::describe_operating_point(
            event,
            unit.machine_mva,
        )),
        _ => None,
    };
    match detail {
        Some(detail) => Error::Located { error: e, detail },
        None => Error::Sim(e),
    }
}

// -------------------------------------------------------------------------------------------
// Noise
// -------------------------------------------------------------------------------------------

pub use crate::noise::{Headline, NoiseRow};

/// What a fit's report compares the calibrated unit's residual with the noise on: the playback
/// of the fit's last pass (the joint pass's when it runs, else the last stage's) and its
/// compared channels; P and Q for a historical phasor pass.
pub fn headline_playback(
    spec: &CalibSpec,
    opts: &FitOptions,
    events: &[Event],
    held_out: &[Event],
) -> (
    itaipu_dynamics::mode::PlaybackMode,
    Vec<itaipu_dynamics::event::Channel>,
) {
    use itaipu_dynamics::event::Channel;
    let fitted: Vec<&Event> = events.iter().collect();
    let held: Vec<&Event> = held_out.iter().collect();
    let resolved = spec.resolve_recorded(&fitted, &held);
    let last = crate::fit::pass_labels(opts).pop().unwrap_or_default();
    let cmp = if last == "joint" || last == "simultaneous" {
        resolved.joint_compare_of(&opts.stages)
    } else {
        resolved.stage(&last).and_then(|st| st.compare())
    };
    match cmp {
        Some(c) => {
            let mut ch: Vec<Channel> = c
                .weights
                .iter()
                .filter(|(_, w)| *w > 0.0)
                .map(|(c, _)| *c)
                .collect();
            ch.sort();
            (c.mode, ch)
        }
        None => (
            itaipu_dynamics::mode::PlaybackMode::Phasor,
            vec![Channel::P, Channel::Q],
        ),
    }
}

/// Fills every stage's fit statistics from its fitness and the noise floors `noise`.
pub fn fill_statistics(stages: &mut [crate::fit::StageReport], noise: &[NoiseRow]) {
    let sigma = |ev: &str| {
        noise
            .iter()
            .find(|n| n.event == ev)
            .and_then(|n| Some((n.sigma_p?, n.sigma_q?)))
    };
    // A stage of a playback mode compares other channels: its statistics are its own
    // (computed by the stage on those channels).
    for st in stages.iter_mut().filter(|st| st.compare.is_none()) {
        st.statistics =
            crate::fit::FitStatistics::of_fitness(&st.fitness, st.parameters.len(), sigma);
    }
}

// -------------------------------------------------------------------------------------------
// Fit
// -------------------------------------------------------------------------------------------

/// What a fit is given: the unit (with the file it came from, for messages), the calibration
/// spec (with its file and text, kept in the output folder), the fitted and held-out events.
#[derive(Clone)]
pub struct FitInputs {
    pub unit: Unit,
    pub unit_path: Option<PathBuf>,
    pub spec: CalibSpec,
    pub spec_path: Option<PathBuf>,
    /// The spec file's text, written into the output folder as `calibration.toml`.
    pub spec_text: Option<String>,
    pub events: Vec<Event>,
    pub held_out: Vec<Event>,
}

impl FitInputs {
    /// Reads the spec of a fit: `calib` when given, else the unit file's own `[calibration]`
    /// table, else (a unit without one, a `.dyr`) the default spec by roles
    /// ([`crate::default_spec`]).
    pub fn read_spec(
        calib: Option<&Path>,
        unit_path: Option<&Path>,
    ) -> Result<(CalibSpec, PathBuf, String), Error> {
        let path = calib.or(unit_path).ok_or_else(|| {
            crate::request::RequestError::new(
                "calib",
                " is required: the unit was not read from a file, so it has no [calibration] \
                 table; give a file with a [calibration] table",
            )
        })?;
        let text = std::fs::read_to_string(path).map_err(|source| crate::spec::SpecError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        // No spec given and none in the unit (a unit file without [calibration], a .dyr): the
        // default spec by roles (crate::default_spec), its text kept as the fit's spec.
        let is_dyr = path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("dyr"));
        let has_table = || {
            text.parse::<toml::Table>()
                .is_ok_and(|t| t.contains_key("calibration"))
        };
        if calib.is_none() && (is_dyr || !has_table()) {
            let unit = load_unit(path)?.unit;
            let text = crate::default_spec::default_spec_text(&unit);
            let spec = CalibSpec::parse(&text, path)?;
            return Ok((spec, path.to_path_buf(), text));
        }
        let spec = CalibSpec::parse(&text, path)?;
        Ok((spec, path.to_path_buf(), text))
    }

    /// Every input file (unit, spec, events), for hashes and provenance.
    pub fn files(&self) -> Vec<PathBuf> {
        let mut v: Vec<PathBuf> = self.unit_path.iter().cloned().collect();
        v.extend(self.spec_path.iter().cloned());
        for e in self.events.iter().chain(&self.held_out) {
            v.extend(e.toml_path.iter().cloned());
        }
        v
    }
}

/// `report.json`: the fit's report, the plausibility warnings on its inputs, the noise of every
/// event, and (after `--resume`) the stages an earlier run finished ([`FitSummary::to_json`]).
#[derive(Debug, Clone)]
pub struct FitSummary {
    pub fit: FitReport,
    /// Plausibility warnings on the inputs, and starting values the spec's bounds clamp.
    pub warnings: Vec<Finding>,
    pub noise: Vec<NoiseRow>,
    /// The calibrated unit's residual against the noise, in one sentence ([`crate::noise`]).
    pub headline: Headline,
    /// Stages finished by an interrupted run and not run again ([`FitControl::resume`]): their
    /// names and their reports as that run wrote them.
    pub resumed_stages: Vec<String>,
    pub resumed_reports: Vec<serde_json::Value>,
    /// What each event declares beyond its samples ([`Event::declaration_notes`]: channels
    /// without an angle, a non-uniform time base kept as recorded, set-point steps), per event
    /// with notes; `report.json` `event_notes` when any.
    pub event_notes: Vec<(String, Vec<String>)>,
}

impl FitSummary {
    /// The report as JSON (`report.json`, Python's `FitResult.report`): the fit's fields, its
    /// stages headed by the resumed ones, `warnings`, `noise`, and `resumed_stages` after a
    /// resume. Non-finite numbers (an undetermined standard error) are `null`.
    pub fn to_json(&self) -> Result<serde_json::Value, Error> {
        let err = |e: serde_json::Error| Error::Output(format!("report.json: {e}"));
        let mut v = serde_json::to_value(&self.fit).map_err(err)?;
        if !self.resumed_reports.is_empty() {
            let mut stages = self.resumed_reports.clone();
            if let Some(now) = v["stages"].as_array() {
                stages.extend(now.iter().cloned());
            }
            v["stages"] = serde_json::Value::Array(stages);
            v["resumed_stages"] = serde_json::json!(self.resumed_stages);
        }
        v["warnings"] = serde_json::to_value(&self.warnings).map_err(err)?;
        v["noise"] = serde_json::to_value(&self.noise).map_err(err)?;
        v["headline"] = serde_json::to_value(&self.headline).map_err(err)?;
        if !self.event_notes.is_empty() {
            let notes: serde_json::Map<String, serde_json::Value> = self
                .event_notes
                .iter()
                .map(|(e, n)| (e.clone(), serde_json::json!(n)))
                .collect();
            v["event_notes"] = serde_json::Value::Object(notes);
        }
        Ok(v)
    }

    /// The report as text (what `itaipu-calib fit` prints and `FitResult.report()` returns):
    /// the stages with their fit statistics and parameters, then the warnings.
    pub fn to_text(&self) -> String {
        self.to_text_after(&[])
    }

    /// [`FitSummary::to_text`] for a front end that has shown the warnings `shown` already
    /// (before the run): each warning is said once, the others are counted.
    pub fn to_text_after(&self, shown: &[Finding]) -> String {
        let mut out = String::new();
        for (e, notes) in &self.event_notes {
            for n in notes {
                out.push_str(&format!("event {e}: {n}\n"));
            }
        }
        out.push_str(&self.fit.to_text());
        out.push_str(&format!("\nheadline: {}\n", self.headline.sentence));
        let new: Vec<&Finding> = self
            .warnings
            .iter()
            .filter(|w| !shown.contains(w))
            .collect();
        let before = self.warnings.len() - new.len();
        if !new.is_empty() {
            out.push_str(&format!(
                "\n{} warning(s){}:\n",
                new.len(),
                if before > 0 {
                    format!(" (and the {before} above)")
                } else {
                    String::new()
                }
            ));
            for w in new {
                out.push_str(&format!("  {w}\n"));
            }
        } else if before > 0 {
            out.push_str(&format!("\n{before} warning(s), above\n"));
        }
        out
    }
}

/// A finished fit: its report, the calibrated unit (described as calibrated), the unit as given
/// (the datasheet the prior is centred on), the stages' units and traces, the options it ran
/// with, and the calibrated set a diagnosis re-frees ([`diagnose::calibrated_set`]).
pub struct FitRun {
    pub report: FitSummary,
    pub unit: Unit,
    pub datasheet: Unit,
    pub stages: Vec<StageOutput>,
    pub options: FitOptions,
    pub calibrated_set: Vec<FreeBound>,
}

/// The options of a fit from the spec and the request, and the warnings known before it runs
/// (plausibility of the inputs, starting values clamped into the spec's bounds): what a front
/// end shows before the (long) run. Errors here are the request's or the inputs'.
pub fn prepare_fit(
    inputs: &FitInputs,
    request: &FitRequest,
) -> Result<(FitOptions, Vec<Finding>), Error> {
    let mut opts = FitOptions::from_spec(&inputs.spec);
    request.apply(&mut opts)?;
    // Every event holds what the stages play back and compare (file, channel and spec field
    // named), before the plausibility layer and anything written.
    crate::fit::check_events(
        &inputs.spec,
        inputs.spec_path.as_deref(),
        &opts.stages,
        opts.polish && opts.stages.len() > 1,
        &inputs.events,
        &inputs.held_out,
    )?;
    let all: Vec<&Event> = inputs.events.iter().chain(&inputs.held_out).collect();
    let mut warnings = check_inputs(&all, &inputs.unit, inputs.unit_path.as_deref())?;
    let spec_file = inputs
        .spec_path
        .clone()
        .unwrap_or_else(|| PathBuf::from("calibration spec"));
    warnings.extend(start_warnings(
        &inputs.unit,
        &inputs.spec,
        &opts.stages,
        &spec_file,
    ));
    warnings.extend(field_warnings(&all, &inputs.spec, &opts.stages, &spec_file));
    Ok((opts, warnings))
}

/// A phasor stage to run that compares P and Q alone on events that all record the field
/// (E_fd, X_ad I_fd): said, with `channels = "recorded"` as the fix. P and Q alone leave X_d and
/// the exciter's gain free to bend until the simulated field runs off the recorded one by many
/// noise widths (nothing in P and Q pins the field's own scale), which can hide a ceiling or a
/// saturation inside the calibration.
pub fn field_warnings(
    events: &[&Event],
    spec: &CalibSpec,
    stages: &[String],
    calib_path: &Path,
) -> Vec<Finding> {
    let field = diagnose::playback::field_recorded_by_all(events.iter().copied());
    if field.is_empty() {
        return vec![];
    }
    let names = field
        .iter()
        .map(|c| c.name())
        .collect::<Vec<_>>()
        .join(", ");
    spec.stages
        .iter()
        .enumerate()
        .filter(|(_, st)| stages.contains(&st.name))
        .filter(|(_, st)| {
            st.mode == itaipu_dynamics::mode::PlaybackMode::Phasor && st.channels.is_none()
        })
        .map(|(k, st)| Finding {
            severity: Severity::Warning,
            kind: "field_not_compared",
            file: calib_path.to_path_buf(),
            line: None,
            time_s: None,
            column: format!("calibration.stage[{k}] (stage {})", st.name),
            message: format!(
                "every event records the field ({names}) but the stage compares P and Q alone: \
                 the calibration may bend X_d and the exciter's gain until the simulated field \
                 runs off the recorded one"
            ),
            fix: "channels = \"recorded\" in the stage compares them too, each weighted by its \
                  noise (a joint pass without channels of its own then compares them as well)"
                .into(),
        })
        .collect()
}

/// Every channel a pass of `fit` made far worse than an earlier pass left it
/// ([`crate::fit::worsening`]), as a warning on the spec's pass.
pub fn worsening_warnings(fit: &FitReport, spec_path: Option<&Path>) -> Vec<Finding> {
    fit.stages
        .iter()
        .flat_map(|s| &s.worsened)
        .map(|w| Finding {
            severity: Severity::Warning,
            kind: "pass_worsened_channel",
            file: spec_path.map_or_else(|| PathBuf::from("calibration spec"), Path::to_path_buf),
            line: None,
            time_s: None,
            column: if w.pass == "joint" || w.pass == "simultaneous" {
                "calibration.joint".to_string()
            } else {
                format!("calibration.stage (stage {})", w.pass)
            },
            message: w.sentence(),
            fix: format!(
                "compare {} in that pass too (a joint pass without channels of its own compares \
                 what its stages compared), or check the stages' bounds: a channel one pass \
                 fits and the next gives up is a trade-off the model cannot make at the noise",
                w.channel
            ),
        })
        .collect()
}

/// Runs a fit ([`fit_with`]) with options and warnings from [`prepare_fit`], and builds its
/// report. `resumed` are the names and reports (as written then) of the stages an interrupted
/// run finished (with [`FitControl::resume`]): they head the report's stages.
pub fn run_fit(
    inputs: &FitInputs,
    opts: &FitOptions,
    warnings: Vec<Finding>,
    progress: &dyn Progress,
    control: &FitControl<'_>,
    resumed: (Vec<String>, Vec<serde_json::Value>),
) -> Result<FitRun, Error> {
    let result = fit_with(
        &inputs.unit,
        &inputs.spec,
        &inputs.events,
        &inputs.held_out,
        opts,
        progress,
        control,
    )?;
    let mut unit = result.unit;
    unit.description = format!(
        "{} (calibrated by itaipu-calib fit, stages {}, seed {})",
        inputs.unit.description,
        opts.stages.join("+"),
        opts.seed
    );
    let calibrated_set = diagnose::calibrated_set(&inputs.spec, &opts.stages, &inputs.unit, &unit);
    // The calibrated unit's own plausibility: a value far outside its typical range, a machine
    // pressed against the order of its reactances or time constants.
    let mut warnings = warnings;
    warnings.extend(
        itaipu_dynamics::plausibility::check_unit(&unit, Path::new("calibrated.toml"))
            .into_iter()
            .map(|mut f| {
                f.message = format!("the calibrated unit: {}", f.message);
                f
            }),
    );
    let (mode, channels) = headline_playback(&inputs.spec, opts, &inputs.events, &inputs.held_out);
    let (noise, headline) =
        crate::noise::assess(&unit, &inputs.events, &inputs.held_out, mode, &channels);
    let mut fit = result.report;
    fill_statistics(&mut fit.stages, &noise);
    // A pass that made a channel an earlier pass compared far worse, among the warnings.
    warnings.extend(worsening_warnings(&fit, inputs.spec_path.as_deref()));
    // Stages an interrupted run finished: their statistics with the same noise floors.
    let resumed_reports: Vec<serde_json::Value> = resumed
        .1
        .into_iter()
        .map(|mut v| {
            let fitness: Vec<crate::fit::EventFitness> =
                serde_json::from_value(v["fitness"].clone()).unwrap_or_default();
            let k = v["parameters"].as_array().map_or(0, Vec::len);
            let stats = crate::fit::FitStatistics::of_fitness(&fitness, k, |ev| {
                noise
                    .iter()
                    .find(|n| n.event == ev)
                    .and_then(|n| Some((n.sigma_p?, n.sigma_q?)))
            });
            if let Ok(s) = serde_json::to_value(stats) {
                v["statistics"] = s;
            }
            v
        })
        .collect();
    Ok(FitRun {
        report: FitSummary {
            fit,
            warnings,
            noise,
            headline,
            resumed_stages: resumed.0,
            resumed_reports,
            event_notes: inputs
                .events
                .iter()
                .chain(&inputs.held_out)
                .map(|e| (e.name.clone(), e.declaration_notes()))
                .filter(|(_, n)| !n.is_empty())
                .collect(),
        },
        unit,
        datasheet: inputs.unit.clone(),
        stages: result.stages,
        options: opts.clone(),
        calibrated_set,
    })
}

/// A free parameter without `start` whose value in the unit lies outside its bounds starts
/// from the nearest bound: said, not done in silence.
pub fn start_warnings(
    unit: &Unit,
    spec: &CalibSpec,
    stages: &[String],
    calib_path: &Path,
) -> Vec<Finding> {
    let mut out = vec![];
    for (k, st) in spec.stages.iter().enumerate() {
        if !stages.contains(&st.name) {
            continue;
        }
        for (j, f) in st.free.iter().enumerate() {
            if f.start.is_some() {
                continue;
            }
            let v = match st.set.get(&f.param) {
                Some(v) => *v,
                None => match unit.param(&f.param) {
                    Ok(r) => unit.get(r),
                    Err(_) => continue,
                },
            };
            if !(v >= f.min && v <= f.max) {
                out.push(Finding {
                    severity: Severity::Warning,
                    kind: "start_clamped",
                    file: calib_path.to_path_buf(),
                    line: None,
                    time_s: None,
                    column: format!("calibration.stage[{k}].free[{j}] ({})", f.param),
                    message: format!(
                        "the unit's value {v} lies outside [{}, {}]; stage {} starts from {}",
                        f.min,
                        f.max,
                        st.name,
                        v.clamp(f.min, f.max)
                    ),
                    fix: "widen the bounds, or give start = ... in the free entry".into(),
                });
            }
        }
    }
    out
}

/// Writes a finished stage's folder `dir/<stage>/`: per fitted event its traces before and
/// after the stage (`traces[_<event>].csv`, `traces_start[_<event>].csv`), then `extra` (a
/// front end's plots), then the stage's unit `unit.toml` last, so that a stage folder holding
/// `unit.toml` is complete.
pub fn write_stage_files(
    dir: &Path,
    st: &StageOutput,
    extra: impl FnOnce(&Path) -> Result<(), Error>,
) -> Result<PathBuf, Error> {
    let d = dir.join(&st.stage);
    std::fs::create_dir_all(&d)
        .map_err(|e| Error::Output(format!("cannot create {}: {e}", d.display())))?;
    for (ev, start, end) in &st.traces {
        let suffix = stage_trace_suffix(st, ev);
        for (name, tr) in [("traces", end), ("traces_start", start)] {
            let p = d.join(format!("{name}{suffix}.csv"));
            tr.write_csv(&p)
                .map_err(|e| Error::Output(format!("cannot write {}: {e}", p.display())))?;
        }
    }
    extra(&d)?;
    write_synced(
        &d.join("unit.toml"),
        unit_to_toml(&st.calibrated_unit).as_bytes(),
    )?;
    Ok(d)
}

/// The file-name suffix of event `ev`'s traces in a stage folder: none with one event,
/// `_<event>` with several.
pub fn stage_trace_suffix(st: &StageOutput, ev: &str) -> String {
    if st.traces.len() > 1 {
        format!("_{ev}")
    } else {
        String::new()
    }
}

/// The files of a fit's folder (not the stage folders: [`write_stage_files`]): `report.json`,
/// `calibrated.toml`, and what `diagnose --fit` needs to re-fit the same calibrated set with the
/// same prior, `datasheet.toml` (the unit as given) and `calibration.toml` (the spec's text).
/// Returns the names written.
pub fn write_fit_files(
    dir: &Path,
    run: &FitRun,
    spec_text: &str,
) -> Result<Vec<&'static str>, Error> {
    let json = serde_json::to_string_pretty(&run.report.to_json()?)
        .map_err(|e| Error::Output(format!("report.json: {e}")))?;
    let files: [(&'static str, String); 4] = [
        ("report.json", json),
        ("calibrated.toml", unit_to_toml(&run.unit)),
        ("datasheet.toml", unit_to_toml(&run.datasheet)),
        ("calibration.toml", spec_text.to_string()),
    ];
    for (name, text) in &files {
        write_synced(&dir.join(name), text.as_bytes())?;
    }
    Ok(files.iter().map(|(n, _)| *n).collect())
}

// -------------------------------------------------------------------------------------------
// Diagnose
// -------------------------------------------------------------------------------------------

/// A fit's folder as `diagnose --fit` reads it: the calibrated unit (`calibrated.toml`) and its
/// calibrated set re-freed with the calibration's prior around the datasheet values
/// (`calibration.toml`, `datasheet.toml`).
pub struct FitFolder {
    pub unit: Unit,
    pub unit_path: PathBuf,
    pub calibrated_set: Vec<FreeBound>,
    /// The folder's files read (calibration spec, datasheet unit), for provenance.
    pub files: Vec<(&'static str, PathBuf)>,
}

/// Reads a fit's output folder ([`FitFolder`]).
pub fn read_fit_folder(dir: &Path) -> Result<FitFolder, Error> {
    let unit_path = dir.join("calibrated.toml");
    let unit = load_unit(&unit_path)?.unit;
    let spec_path = dir.join("calibration.toml");
    let spec = CalibSpec::from_file(&spec_path)?;
    let datasheet_path = dir.join("datasheet.toml");
    let datasheet = load_unit(&datasheet_path)?.unit;
    // The stages the fit ran (its report's), not every stage the spec lists: a fit of gen and
    // avr re-frees what those stages freed, as the same fit's `FitRun::calibrated_set` does.
    let ran: Option<Vec<String>> = std::fs::read_to_string(dir.join("report.json"))
        .ok()
        .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok())
        .and_then(|r| {
            r["stages"].as_array().map(|a| {
                a.iter()
                    .filter_map(|s| s["stage"].as_str().map(String::from))
                    .collect()
            })
        });
    let stages: Vec<String> = spec
        .stages
        .iter()
        .map(|s| s.name.clone())
        .filter(|n| ran.as_ref().is_none_or(|r| r.contains(n)))
        .collect();
    let calibrated_set = diagnose::calibrated_set(&spec, &stages, &datasheet, &unit);
    Ok(FitFolder {
        unit,
        unit_path,
        calibrated_set,
        files: vec![
            ("calibration spec", spec_path),
            ("datasheet unit", datasheet_path),
        ],
    })
}

/// A finished diagnosis: the report (with the plausibility warnings on its inputs), the
/// extended, re-fitted unit of the named cause (described as such), the traces before and
/// after.
pub struct DiagnoseRun {
    pub report: Diagnosis,
    pub extended_unit: Option<Unit>,
    pub before: Vec<(String, itaipu_dynamics::simulate::Traces)>,
    pub after: Vec<(String, itaipu_dynamics::simulate::Traces)>,
}

/// The options of a diagnosis of `unit` from the request, with `calibrated_set` (a fit's, or
/// empty) re-freed in every re-fit after the parameters the request names, and the warnings
/// known before it runs (plausibility of the inputs). Each event is played back once first, so
/// that a unit that does not simulate on an event as given stops here with the sample or
/// operating point at fault ([`preflight`]).
pub fn prepare_diagnose(
    unit: &Unit,
    unit_path: Option<&Path>,
    events: &[Event],
    held_out: &[Event],
    request: &DiagnoseRequest,
    calibrated_set: &[FreeBound],
) -> Result<(DiagnoseOptions, Vec<Finding>), Error> {
    let mut opts = request.options(unit)?;
    merge_calibrated_set(&mut opts.refit, calibrated_set, unit);
    let all: Vec<&Event> = events.iter().chain(held_out).collect();
    let pb = diagnose::Playback::for_events(opts.mode, &all)?;
    let warnings = check_inputs(&all, unit, unit_path)?;
    for e in all {
        preflight_in(unit, e, &pb)?;
    }
    Ok((opts, warnings))
}

/// Adds a fit's calibrated set to the re-fit bounds (defined by the diagnosis, which re-frees
/// them).
pub use crate::diagnose::merge_calibrated_set;

/// Runs a diagnosis ([`diagnose::diagnose`]) with options and warnings from
/// [`prepare_diagnose`].
pub fn run_diagnose(
    unit: &Unit,
    events: &[Event],
    held_out: &[Event],
    opts: &DiagnoseOptions,
    warnings: Vec<Finding>,
    progress: &dyn Progress,
) -> Result<DiagnoseRun, Error> {
    let DiagnoseResult {
        mut report,
        extended_unit,
        before,
        after,
    } = diagnose::diagnose(unit, events, held_out, opts, progress)?;
    report.warnings = warnings;
    let extended_unit = extended_unit.map(|mut u| {
        let note = format!(
            "extended for {} and re-fitted by itaipu-calib diagnose, seed {}",
            report.verdict.cause, opts.seed
        );
        u.description = if unit.description.trim().is_empty() {
            note
        } else {
            format!("{} ({note})", unit.description)
        };
        u
    });
    Ok(DiagnoseRun {
        report,
        extended_unit,
        before,
        after,
    })
}

/// The files of a diagnosis' folder: `diagnosis.json`, `extended.toml` when a cause is named,
/// `warnings.json` when there are warnings. Returns the names written.
pub fn write_diagnosis_files(dir: &Path, run: &DiagnoseRun) -> Result<Vec<&'static str>, Error> {
    let json = serde_json::to_string_pretty(&run.report)
        .map_err(|e| Error::Output(format!("diagnosis.json: {e}")))?;
    write_synced(&dir.join("diagnosis.json"), json.as_bytes())?;
    let mut written = vec!["diagnosis.json"];
    if let Some(u) = &run.extended_unit {
        write_synced(&dir.join("extended.toml"), unit_to_toml(u).as_bytes())?;
        written.push("extended.toml");
    }
    if write_warnings(dir, &run.report.warnings)? {
        written.push("warnings.json");
    }
    Ok(written)
}

/// Writes `warnings.json` into `dir` when there are warnings (returns whether it did).
pub fn write_warnings(dir: &Path, warnings: &[Finding]) -> Result<bool, Error> {
    if warnings.is_empty() {
        return Ok(false);
    }
    let text = serde_json::to_string_pretty(warnings)
        .map_err(|e| Error::Output(format!("warnings.json: {e}")))?;
    write_synced(&dir.join("warnings.json"), text.as_bytes())?;
    Ok(true)
}
