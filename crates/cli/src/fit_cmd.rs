//! `itaipu-calib fit`: staged calibration with report, calibrated unit, traces and plots.

use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, OnceLock};

use clap::builder::{PossibleValuesParser, TypedValueParser};
use indicatif::{ProgressBar, ProgressStyle};
use itaipu_calib::fit::{
    fit_with, FitControl, FitError, FitOptions, Progress, Resume, StageOutput, StageReport,
};
use itaipu_calib::problem::EventData;
use itaipu_calib::request::{FitRequest, Stage};
use itaipu_calib::spec::{CalibSpec, Strategy};
use itaipu_dynamics::event::Event;
use itaipu_dynamics::plausibility::{Finding, Severity};
use itaipu_dynamics::simulate::simulate;
use itaipu_dynamics::unit::Unit;
use itaipu_dynamics::unit_file::unit_to_toml;

use crate::report::fit::EventTraces;
use crate::report::{InputFile, Provenance};
use crate::{
    bundled, check_out, load_event, load_unit, prepare_out, report::svg as plot, CliError,
    SearchArgs, EXIT_CODES,
};

#[derive(clap::Args, Debug)]
#[command(after_help = EXIT_CODES)]
pub struct FitArgs {
    /// Stage(s) to run: gen (machine, E_fd and P_m held), avr, pss, tg, or all (every stage the
    /// spec lists). Several stages (`--stage gen,avr,pss`) run in the fixed order gen, avr, pss,
    /// tg, each starting from the previous result.
    #[arg(long, value_delimiter = ',', num_args = 1.., default_value = "all", value_parser = stage_parser())]
    stage: Vec<Stage>,
    /// How stages are combined (default: the spec's, else sequential).
    #[arg(long, value_parser = strategy_parser())]
    strategy: Option<Strategy>,
    /// Event file(s) to fit together (summed objective). Default: the bundled Itaipu record.
    #[arg(long, value_name = "FILE", num_args = 1..)]
    event: Vec<PathBuf>,
    /// Event file(s) held out: not fitted, their objective is reported per stage.
    #[arg(long, value_name = "FILE", num_args = 1..)]
    held_out: Vec<PathBuf>,
    /// Unit model file. Default: the bundled Itaipu unit.
    #[arg(long, value_name = "FILE")]
    unit: Option<PathBuf>,
    /// Calibration spec (a file with a [calibration] table). Default: the unit file's
    /// [calibration] table, or with the bundled unit the bundled RaPId problem.
    #[arg(long, value_name = "FILE")]
    calib: Option<PathBuf>,
    /// Output folder (report.json, calibrated.toml, per-stage traces and plots). Default:
    /// out/fit-<event>, or a new numbered folder beside it. An existing --out folder is never
    /// overwritten unless --force is given.
    #[arg(long, value_name = "DIR")]
    out: Option<PathBuf>,
    /// Replace an existing, non-empty --out folder (whole: nothing of the earlier run stays).
    #[arg(long)]
    force: bool,
    /// Go on from an interrupted fit: --out must be the partial folder it left (partial.json);
    /// its finished stages are kept and the others run, with the same numbers as an
    /// uninterrupted run. Give the same inputs and options as the interrupted run.
    #[arg(long, conflicts_with = "force")]
    resume: bool,
    #[command(flatten)]
    search: SearchArgs,
    /// Do not draw the plots.
    #[arg(long)]
    no_plot: bool,
    /// Skip the final joint refinement of all stages' parameters on the full unit.
    #[arg(long)]
    no_polish: bool,
}

/// `--stage`: the library's stage names ([`Stage::NAMES`]), parsed by [`Stage`]'s `FromStr`.
fn stage_parser() -> impl TypedValueParser<Value = Stage> {
    PossibleValuesParser::new(Stage::NAMES).map(|s| s.parse::<Stage>().expect("a stage name"))
}

/// `--strategy`: parsed by [`Strategy`]'s `FromStr`.
fn strategy_parser() -> impl TypedValueParser<Value = Strategy> {
    PossibleValuesParser::new(Strategy::NAMES)
        .map(|s| s.parse::<Strategy>().expect("a strategy name"))
}

/// Progress on a terminal: one bar per phase. Otherwise: plain lines every 10 iterations.
/// Shared with `diagnose`.
pub(crate) struct Reporter {
    bar: Mutex<Option<ProgressBar>>,
    terminal: bool,
}

impl Reporter {
    pub(crate) fn new() -> Self {
        Self {
            bar: Mutex::new(None),
            terminal: std::io::stderr().is_terminal(),
        }
    }

    /// Finishes the current bar, if any.
    pub(crate) fn finish(&self) {
        if let Some(b) = self.bar.lock().expect("progress").take() {
            b.finish();
        }
    }
}

impl Progress for Reporter {
    fn phase(&self, stage: &str, phase: &str, total: u64) {
        let mut bar = self.bar.lock().expect("progress");
        if let Some(b) = bar.take() {
            b.finish();
        }
        if self.terminal {
            let b = ProgressBar::new(total);
            b.set_style(
                ProgressStyle::with_template(
                    "{prefix:>12} {bar:30} {pos}/{len} best {msg} [{elapsed}]",
                )
                .expect("template"),
            );
            b.set_prefix(format!("{stage} {phase}"));
            *bar = Some(b);
        } else {
            eprintln!("[{stage}] {phase}: up to {total} iterations");
        }
    }
    fn iteration(&self, i: u64, best: f64) {
        if let Some(b) = self.bar.lock().expect("progress").as_ref() {
            b.set_position(i);
            b.set_message(format!("{best:.5}"));
        } else if i.is_multiple_of(10) {
            eprintln!("    iteration {i}: best objective {best:.5}");
        }
    }
    fn message(&self, text: &str) {
        match self.bar.lock().expect("progress").as_ref() {
            Some(b) => b.println(text),
            None => eprintln!("{text}"),
        }
    }
}

/// The interrupt flag of `fit` and the signal that set it, registered once per process
/// (SIGINT, SIGTERM). A second signal while the first is being handled ends the process at
/// once (exit 130 or 143).
fn interrupt_flags() -> (Arc<AtomicBool>, Arc<AtomicUsize>) {
    static FLAGS: OnceLock<(Arc<AtomicBool>, Arc<AtomicUsize>)> = OnceLock::new();
    FLAGS
        .get_or_init(|| {
            let flag = Arc::new(AtomicBool::new(false));
            let which = Arc::new(AtomicUsize::new(0));
            #[cfg(unix)]
            {
                use signal_hook::consts::{SIGINT, SIGTERM};
                for (sig, code) in [(SIGINT, 130), (SIGTERM, 143)] {
                    // Registration fails only for forbidden signals; then a signal ends the
                    // process as usual, which loses nothing written (the folder is temporary).
                    let _ =
                        signal_hook::flag::register_conditional_shutdown(sig, code, flag.clone());
                    let _ = signal_hook::flag::register_usize(sig, which.clone(), sig as usize);
                    let _ = signal_hook::flag::register(sig, flag.clone());
                }
            }
            (flag, which)
        })
        .clone()
}

/// Name and exit code of the signal that interrupted the run.
fn signal_name(which: usize) -> (&'static str, u8) {
    #[cfg(unix)]
    {
        if which == signal_hook::consts::SIGTERM as usize {
            return ("SIGTERM", 143);
        }
    }
    let _ = which;
    ("SIGINT", 130)
}

/// The unit the next stage starts from, kept in a partial folder for `--resume`.
const RESUME_UNIT: &str = "resume-unit.toml";

/// What a partial folder records (`partial.json`).
#[derive(serde::Serialize, serde::Deserialize)]
struct PartialState {
    complete: bool,
    note: String,
    interrupted_by: String,
    finished_stages: Vec<String>,
    command: Vec<String>,
    /// The fit options (stages, strategy, seed, swarm and local settings) in full.
    options: String,
    /// SHA-256 of every input file (unit, spec, events).
    inputs: Vec<(String, String)>,
    /// The finished stages' reports, as in report.json.
    stage_reports: Vec<serde_json::Value>,
}

/// Finished stages so far: labels and reports.
#[derive(Default)]
struct Finished {
    labels: Vec<String>,
    reports: Vec<serde_json::Value>,
}

fn input_hashes(paths: &[&Path]) -> Result<Vec<(String, String)>, CliError> {
    paths
        .iter()
        .map(|p| {
            let h = crate::output::sha256_file(p)
                .map_err(|e| CliError::new(3, format!("cannot read {}: {e}", p.display())))?;
            Ok((p.display().to_string(), h))
        })
        .collect()
}

pub fn cmd_fit(a: &FitArgs) -> Result<(), CliError> {
    let bundled_unit = a.unit.is_none();
    let unit_path = match &a.unit {
        Some(p) => p.clone(),
        None => bundled("itaipu/unit.toml")?,
    };
    let event_paths = if a.event.is_empty() {
        vec![bundled("itaipu/event.toml")?]
    } else {
        a.event.clone()
    };
    let calib_path = match (&a.calib, bundled_unit) {
        (Some(p), _) => p.clone(),
        (None, true) => bundled("itaipu/calibration.toml")?,
        (None, false) => unit_path.clone(),
    };
    let unit = load_unit(&unit_path)?;
    let spec = CalibSpec::from_file(&calib_path)?;
    let events = event_paths
        .iter()
        .map(|p| load_event(p))
        .collect::<Result<Vec<_>, _>>()?;
    let held_out = a
        .held_out
        .iter()
        .map(|p| load_event(p))
        .collect::<Result<Vec<_>, _>>()?;

    let mut opts = FitOptions::from_spec(&spec);
    FitRequest {
        stages: a.stage.clone(),
        strategy: a.strategy,
        search: a.search.request(),
        no_polish: a.no_polish,
    }
    .apply(&mut opts)?;
    let pool = a.search.pool()?;
    let mut warnings = crate::plausibility(
        &events.iter().chain(&held_out).collect::<Vec<_>>(),
        &unit,
        &unit_path,
    )?;
    warnings.extend(start_warnings(&unit, &spec, &opts.stages, &calib_path));
    for w in warnings.iter().filter(|w| w.kind == "start_clamped") {
        eprintln!("warning: {w}");
    }
    let name = events.first().map(|e| e.name.clone()).unwrap_or_default();
    let mut input_paths: Vec<&Path> = vec![&unit_path, &calib_path];
    input_paths.extend(event_paths.iter().map(|p| p.as_path()));
    input_paths.extend(a.held_out.iter().map(|p| p.as_path()));
    let inputs = input_hashes(&input_paths)?;
    let options = format!("{opts:?}");

    // --resume: the partial folder of an interrupted run with the same inputs and options.
    let resumed: Option<(PathBuf, PartialState, Unit)> = if a.resume {
        let Some(dir) = a.out.as_deref() else {
            return Err(CliError::new(
                2,
                "--resume needs --out: the folder an interrupted fit left",
            ));
        };
        if dir.join(crate::output::MANIFEST).is_file() {
            return Err(CliError::new(
                2,
                format!(
                    "--resume: {} is complete (it has manifest.json); nothing to resume",
                    dir.display()
                ),
            ));
        }
        let pj = dir.join(crate::output::PARTIAL);
        let text = std::fs::read_to_string(&pj).map_err(|e| {
            CliError::new(
                2,
                format!(
                    "--resume: {}: {e} (not the folder of an interrupted fit)",
                    pj.display()
                ),
            )
        })?;
        let st: PartialState = serde_json::from_str(&text)
            .map_err(|e| CliError::new(2, format!("--resume: {}: {e}", pj.display())))?;
        if st.options != options {
            return Err(CliError::new(
                2,
                format!(
                    "--resume: the options differ from the interrupted run's (give the same stages, strategy, seed and search settings)\n  then: {}\n  now:  {options}",
                    st.options
                ),
            ));
        }
        if st.inputs != inputs {
            let diff = st
                .inputs
                .iter()
                .zip(&inputs)
                .find(|(x, y)| x != y)
                .map(|(x, y)| format!("{} (then) / {} (now)", x.0, y.0))
                .unwrap_or_else(|| "a different number of input files".into());
            return Err(CliError::new(
                2,
                format!("--resume: the input files differ from the interrupted run's: {diff}"),
            ));
        }
        let master = if st.finished_stages.is_empty() {
            unit.clone()
        } else {
            load_unit(&dir.join(RESUME_UNIT))?
        };
        Some((dir.to_path_buf(), st, master))
    } else {
        check_out(a.out.as_deref(), a.force)?;
        None
    };
    // The output folder, started before the (long) fit: the writability check.
    let staging = prepare_out(
        a.out.as_deref(),
        &format!("fit-{name}"),
        a.force || a.resume,
    )?;
    let out = staging.path().to_path_buf();
    let finished = Mutex::new(Finished::default());
    let mut resume = None;
    if let Some((dir, st, master)) = &resumed {
        for label in &st.finished_stages {
            crate::output::copy_dir(&dir.join(label), &out.join(label)).map_err(|e| {
                CliError::new(
                    7,
                    format!("--resume: cannot copy {}: {e}", dir.join(label).display()),
                )
            })?;
        }
        if !st.finished_stages.is_empty() {
            std::fs::copy(dir.join(RESUME_UNIT), out.join(RESUME_UNIT)).map_err(|e| {
                CliError::new(
                    7,
                    format!(
                        "--resume: cannot copy {}: {e}",
                        dir.join(RESUME_UNIT).display()
                    ),
                )
            })?;
        }
        let mut f = finished.lock().expect("finished");
        f.labels = st.finished_stages.clone();
        f.reports = st.stage_reports.clone();
        resume = Some(Resume {
            finished: st.finished_stages.clone(),
            master: master.clone(),
        });
        println!(
            "resume {} finished stage(s) from {}: {}",
            st.finished_stages.len(),
            dir.display(),
            st.finished_stages.join(", ")
        );
    }
    println!(
        "fit    unit {} ({}), events {}, spec {}, stages {}, strategy {}, seed {}, {} threads",
        unit.name,
        unit_path.display(),
        events
            .iter()
            .map(|e| e.name.as_str())
            .collect::<Vec<_>>()
            .join(", "),
        calib_path.display(),
        opts.stages.join(" -> "),
        opts.strategy,
        opts.seed,
        pool.current_num_threads()
    );
    let reporter = Reporter::new();
    let (flag, which) = interrupt_flags();
    flag.store(false, Ordering::SeqCst);
    which.store(0, Ordering::SeqCst);
    let no_plot = a.no_plot;
    let on_stage = |rep: &StageReport, st: &StageOutput, master: &Unit| -> Result<(), FitError> {
        write_stage(&out, st, rep, no_plot).map_err(|e| FitError::Output(e.msg))?;
        crate::output::write_synced(&out.join(RESUME_UNIT), unit_to_toml(master).as_bytes())
            .map_err(|e| FitError::Output(e.msg))?;
        let mut f = finished.lock().expect("finished");
        f.labels.push(rep.stage.clone());
        f.reports
            .push(serde_json::to_value(rep).map_err(|e| FitError::Output(e.to_string()))?);
        Ok(())
    };
    let control = FitControl {
        cancel: Some(flag.clone()),
        on_stage: Some(&on_stage),
        resume,
    };
    let result =
        pool.install(|| fit_with(&unit, &spec, &events, &held_out, &opts, &reporter, &control));
    reporter.finish();
    let result = match result {
        Ok(r) => r,
        Err(FitError::Interrupted { .. }) => {
            let (sig, code) = signal_name(which.load(Ordering::SeqCst));
            let f = finished.lock().expect("finished");
            let state = PartialState {
                complete: false,
                note: "interrupted: an incomplete result. Every stage folder listed in finished_stages is complete and usable (its unit.toml simulates); run the same command again with --resume to go on".into(),
                interrupted_by: sig.into(),
                finished_stages: f.labels.clone(),
                command: crate::output::command(),
                options: options.clone(),
                inputs: inputs.clone(),
                stage_reports: f.reports.clone(),
            };
            let text = serde_json::to_string_pretty(&state)
                .map_err(|e| CliError::new(7, e.to_string()))?;
            crate::output::write_synced(&out.join(crate::output::PARTIAL), text.as_bytes())?;
            let target = staging.keep_partial()?;
            return Err(CliError::new(
                code,
                format!(
                    "interrupted by {sig}: finished stage(s) {} kept in {} (marked incomplete by partial.json); run the same command with --resume to go on",
                    if f.labels.is_empty() { "none".to_string() } else { f.labels.join(", ") },
                    target.display()
                ),
            ));
        }
        Err(e) => {
            // The starting unit cannot initialise at the measured operating point: exit 5, as
            // for simulate, with the operating point it was given.
            let e = itaipu_calib::Error::from(e);
            let init_failed = e.class() == itaipu_calib::error::ErrorClass::Init;
            let mut err = CliError::from(e);
            if let (true, Some(ev)) = (init_failed, events.first()) {
                err.msg = format!(
                    "{}; {}",
                    err.msg,
                    itaipu_dynamics::plausibility::describe_operating_point(ev, unit.machine_mva)
                );
            }
            return Err(err);
        }
    };
    let write = |p: &Path, text: &str| crate::output::write_synced(p, text.as_bytes());
    let mut report =
        serde_json::to_value(&result.report).map_err(|e| CliError::new(7, e.to_string()))?;
    {
        let f = finished.lock().expect("finished");
        report["stages"] = serde_json::Value::Array(f.reports.clone());
        report["warnings"] =
            serde_json::to_value(&warnings).map_err(|e| CliError::new(7, e.to_string()))?;
        if let Some((_, st, _)) = &resumed {
            report["resumed_stages"] = serde_json::json!(st.finished_stages);
        }
        report["noise"] = noise_levels(&events, &held_out);
    }
    let json =
        serde_json::to_string_pretty(&report).map_err(|e| CliError::new(7, e.to_string()))?;
    write(&out.join("report.json"), &json)?;
    let mut calibrated = result.unit.clone();
    calibrated.description = format!(
        "{} (calibrated by itaipu-calib fit, stages {}, seed {})",
        unit.description,
        opts.stages.join("+"),
        opts.seed
    );
    write(&out.join("calibrated.toml"), &unit_to_toml(&calibrated))?;
    // What `diagnose --fit` needs to re-fit the same calibrated set with the same prior: the unit
    // as given (the datasheet values the prior is centred on) and the spec.
    write(&out.join("datasheet.toml"), &unit_to_toml(&unit))?;
    let spec_text = std::fs::read_to_string(&calib_path)
        .map_err(|e| CliError::new(7, format!("cannot read {}: {e}", calib_path.display())))?;
    write(&out.join("calibration.toml"), &spec_text)?;
    write(
        &out.join("report.html"),
        &fit_report_html(
            &report,
            &unit,
            &result.unit,
            &events,
            &held_out,
            [&unit_path, &calib_path],
            opts.seed,
            !a.no_plot,
        ),
    )?;
    let _ = std::fs::remove_file(out.join(RESUME_UNIT));
    let target = staging.commit(Some(opts.seed))?;
    print!("{}", result.report.to_text());
    println!("wrote  {}/report.json, report.html, calibrated.toml, datasheet.toml, calibration.toml, <stage>/{{unit.toml, traces.csv, traces_start.csv{}}}, manifest.json", target.display(), if a.no_plot { "" } else { ", plot.svg" });
    Ok(())
}

/// `report.json`'s `noise`: per event (fitted, then held out) the robust noise standard
/// deviations of the measured P and Q (second differences, as the prior's weight) over the
/// event's fit window.
fn noise_levels(events: &[Event], held_out: &[Event]) -> serde_json::Value {
    let rows: Vec<serde_json::Value> = events
        .iter()
        .map(|e| (e, false))
        .chain(held_out.iter().map(|e| (e, true)))
        .map(|(e, h)| {
            // The fit's own window and estimate (an event the fit could not window has none).
            let (samples, vp, vq) = EventData::new(e, None, None)
                .map(|d| {
                    let (vp, vq) = d.noise_variances();
                    (d.n_window(), vp, vq)
                })
                .unwrap_or((0, f64::NAN, f64::NAN));
            serde_json::json!({
                "event": e.name,
                "held_out": h,
                "samples": samples,
                "sigma_p": vp.sqrt(),
                "sigma_q": vq.sqrt(),
            })
        })
        .collect();
    serde_json::Value::Array(rows)
}

/// The fit's `report.html`: the unit as given and the calibrated unit simulated once more on
/// every event for the figures (an event that does not simulate is left out of them, said on
/// stderr; the fit itself simulated it).
#[allow(clippy::too_many_arguments)]
fn fit_report_html(
    report: &serde_json::Value,
    start: &Unit,
    calibrated: &Unit,
    events: &[Event],
    held_out: &[Event],
    files: [&Path; 2],
    seed: u64,
    plots: bool,
) -> String {
    let mut inputs = vec![
        InputFile::new("unit", files[0]),
        InputFile::new("calibration spec", files[1]),
    ];
    for e in events {
        inputs.extend(InputFile::event(e, false));
    }
    for e in held_out {
        inputs.extend(InputFile::event(e, true));
    }
    let prov = Provenance::new(inputs, seed);
    let mut runs = vec![];
    if plots {
        for (e, h) in events
            .iter()
            .map(|e| (e, false))
            .chain(held_out.iter().map(|e| (e, true)))
        {
            let sim = |u: &Unit| simulate(u, e, &Default::default());
            match (sim(start), sim(calibrated)) {
                (Ok(a), Ok(b)) => runs.push((e, h, a, b)),
                (Err(err), _) | (_, Err(err)) => {
                    eprintln!("report.html: {} left out of the figures: {err}", e.name)
                }
            }
        }
    }
    let traces: Vec<EventTraces> = runs
        .iter()
        .map(|(e, h, a, b)| EventTraces {
            event: &e.name,
            held_out: *h,
            nominal_hz: e.nominal_hz,
            start: a,
            calibrated: b,
        })
        .collect();
    crate::report::fit::html(report, &prov, &traces, plots)
}

/// A free parameter without `start` whose value in the unit lies outside its bounds starts
/// from the nearest bound: said, not done in silence.
fn start_warnings(
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

/// Writes a finished stage's folder: unit, traces and plots.
fn write_stage(
    out: &Path,
    st: &StageOutput,
    rep: &StageReport,
    no_plot: bool,
) -> Result<(), CliError> {
    let write = |p: &Path, text: &str| crate::output::write_synced(p, text.as_bytes());
    let dir = out.join(&st.stage);
    std::fs::create_dir_all(&dir)
        .map_err(|e| CliError::new(7, format!("cannot create {}: {e}", dir.display())))?;
    for (ev, start, end) in &st.traces {
        let suffix = if st.traces.len() > 1 {
            format!("_{ev}")
        } else {
            String::new()
        };
        let p = dir.join(format!("traces{suffix}.csv"));
        end.write_csv(&p)
            .map_err(|e| CliError::new(7, format!("cannot write {}: {e}", p.display())))?;
        let p = dir.join(format!("traces_start{suffix}.csv"));
        start
            .write_csv(&p)
            .map_err(|e| CliError::new(7, format!("cannot write {}: {e}", p.display())))?;
        if !no_plot {
            let t = &end.time_s;
            let g = |tr: &itaipu_dynamics::simulate::Traces, n: &str| {
                tr.get(n).map(|c| c.to_vec()).unwrap_or_default()
            };
            let (pm, qm, ps, qs, pe, qe) = (
                g(end, "p_meas_pu"),
                g(end, "q_meas_pu"),
                g(start, "p_pu"),
                g(start, "q_pu"),
                g(end, "p_pu"),
                g(end, "q_pu"),
            );
            let series = |label: &str, y, color, thin| plot::Series {
                label: label.into(),
                x: t,
                y,
                color,
                thin,
            };
            let panels = vec![
                plot::Panel {
                    y_label: "P [pu, system base]".into(),
                    series: vec![
                        series("measured", pm.as_slice(), plot::MEASURED, true),
                        series("start", ps.as_slice(), plot::START, true),
                        series("calibrated", pe.as_slice(), plot::SIMULATED, false),
                    ],
                },
                plot::Panel {
                    y_label: "Q [pu, system base]".into(),
                    series: vec![
                        series("measured", qm.as_slice(), plot::MEASURED, true),
                        series("start", qs.as_slice(), plot::START, true),
                        series("calibrated", qe.as_slice(), plot::SIMULATED, false),
                    ],
                },
            ];
            let title = format!(
                "{ev}, stage {}: objective {:.4} -> {:.4}",
                st.stage, rep.objective_before, rep.objective_after
            );
            plot::draw(
                &dir.join(format!("plot{suffix}.svg")),
                &title,
                "time [s]",
                &panels,
            )
            .map_err(|e| CliError::new(7, e))?;
        }
    }
    // Last: the stage's unit, so that a stage folder with unit.toml is complete.
    write(&dir.join("unit.toml"), &unit_to_toml(&st.calibrated_unit))?;
    Ok(())
}
