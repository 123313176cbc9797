//! `itaipu-calib fit`: staged calibration with report, calibrated unit, traces and plots.

use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, MutexGuard, OnceLock, PoisonError};

use clap::builder::{PossibleValuesParser, TypedValueParser};
use indicatif::{ProgressBar, ProgressStyle};
use itaipu_calib::fit::{FitControl, FitError, Progress, Resume, StageOutput, StageReport};
use itaipu_calib::job;
use itaipu_calib::options::{cli_help, option, Command::Fit, DefaultValue};
use itaipu_calib::request::{FitRequest, Stage};
use itaipu_calib::spec::Strategy;
use itaipu_dynamics::event::Event;
use itaipu_dynamics::mode::simulate_mode_traces;
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
    #[arg(long, value_delimiter = ',', num_args = 1.., default_value = stages_default(), value_parser = stage_parser(), help = cli_help(Fit, "stages"))]
    stage: Vec<Stage>,
    #[arg(long, value_parser = strategy_parser(), help = cli_help(Fit, "strategy"))]
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
    /// Delete the work an interrupted fit killed outright left beside --out (its hidden
    /// `.NAME.partial-PID` folders and their finished stages) and run afresh. Without it a fit
    /// refuses to start beside such work (`--resume` goes on from it).
    #[arg(long, conflicts_with = "resume")]
    discard_interrupted: bool,
    #[command(flatten)]
    search: SearchArgs,
    /// Do not draw the plots.
    #[arg(long)]
    no_plot: bool,
    #[arg(long, help = cli_help(Fit, "polish"))]
    no_polish: bool,
}

/// `--stage`'s declared default.
fn stages_default() -> &'static str {
    match option(Fit, "stages").default {
        DefaultValue::Text(t) => t,
        _ => "all",
    }
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

/// How much a [`Reporter`] says.
#[derive(Clone, Copy, PartialEq, Eq)]
pub(crate) enum Detail {
    /// `fit`: each phase (a bar on a terminal; one line when it starts otherwise) and each
    /// message.
    Phases,
    /// `diagnose`, whose re-fits run side by side: on a terminal one bar counting the re-fits'
    /// phases, otherwise the messages alone (a line per cause), never a line per phase.
    Summary,
}

/// Progress, shared by `fit` and `diagnose`: on a terminal a progress bar per phase
/// ([`Detail`]), otherwise a few summary lines. Once the run's interrupt flag is set it says
/// nothing more (the stopping run's last candidates are not progress).
pub(crate) struct Reporter {
    bar: Mutex<Option<ProgressBar>>,
    terminal: bool,
    detail: Detail,
    /// Phases started (the `Summary` bar's position).
    started: AtomicUsize,
    cancel: Option<Arc<AtomicBool>>,
}

/// The data behind `m`, even when a thread panicked while holding it: the progress display
/// and the record of finished stages stay usable, so that one panic (which the run reports)
/// does not become a second one in the bookkeeping around it.
fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(PoisonError::into_inner)
}

/// A best objective as the progress shows it: the failure penalty is no objective.
fn best_text(best: f64) -> String {
    if best >= itaipu_calib::problem::FAILURE_PENALTY || !best.is_finite() {
        "none yet (every candidate failed)".into()
    } else {
        format!("{best:.5}")
    }
}

impl Reporter {
    pub(crate) fn new(detail: Detail, cancel: Option<Arc<AtomicBool>>) -> Self {
        Self {
            bar: Mutex::new(None),
            terminal: std::io::stderr().is_terminal(),
            detail,
            started: AtomicUsize::new(0),
            cancel,
        }
    }

    /// Whether the run was interrupted: nothing more is said.
    fn quiet(&self) -> bool {
        self.cancel
            .as_ref()
            .is_some_and(|c| c.load(Ordering::SeqCst))
    }

    /// Finishes the current bar, if any (abandoned where it stands after an interrupt).
    pub(crate) fn finish(&self) {
        if let Some(b) = lock(&self.bar).take() {
            if self.quiet() {
                b.abandon();
            } else {
                b.finish();
            }
        }
    }
}

impl Progress for Reporter {
    fn phase(&self, stage: &str, phase: &str, total: u64) {
        if self.quiet() {
            return;
        }
        let n = self.started.fetch_add(1, Ordering::SeqCst) + 1;
        let mut bar = lock(&self.bar);
        match (self.detail, self.terminal) {
            (Detail::Phases, true) => {
                if let Some(b) = bar.take() {
                    b.finish();
                }
                let b = ProgressBar::new(total);
                b.set_style(
                    ProgressStyle::with_template(
                        "{prefix:>12} {bar:30} {pos}/{len} best {msg} [{elapsed}]",
                    )
                    .expect("template"),
                );
                b.set_prefix(format!("{stage} {phase}"));
                *bar = Some(b);
            }
            (Detail::Phases, false) => eprintln!("[{stage}] {phase}: up to {total} iterations"),
            (Detail::Summary, true) => {
                let b = bar.get_or_insert_with(|| {
                    let b = ProgressBar::new_spinner();
                    b.set_style(
                        ProgressStyle::with_template(
                            "{spinner} re-fit phases {pos} [{elapsed}] {msg}",
                        )
                        .expect("template"),
                    );
                    b
                });
                b.set_position(n as u64);
                b.set_message(format!("{stage}: {phase}"));
            }
            (Detail::Summary, false) => {}
        }
    }
    fn iteration(&self, i: u64, best: f64) {
        if self.quiet() || self.detail == Detail::Summary {
            return;
        }
        if let Some(b) = lock(&self.bar).as_ref() {
            b.set_position(i);
            b.set_message(best_text(best));
        }
    }
    fn message(&self, text: &str) {
        if self.quiet() {
            return;
        }
        match lock(&self.bar).as_ref() {
            Some(b) => b.println(text),
            None => eprintln!("{text}"),
        }
    }
}

/// The interrupt flag of `fit` and the signal that set it, registered once per process
/// (SIGINT, SIGTERM). The first signal sets the flag: the fit stops at its next candidate and
/// keeps its finished stages. A second signal, while the first is being handled, ends the
/// process at once (exit 130 or 143), after renaming the output folder into place as it stands:
/// `partial.json` is kept up to date in it from the start (see `cmd_fit`), so it is marked
/// partial and resumable either way.
fn interrupt_flags() -> (Arc<AtomicBool>, Arc<AtomicUsize>) {
    static FLAGS: OnceLock<(Arc<AtomicBool>, Arc<AtomicUsize>)> = OnceLock::new();
    FLAGS
        .get_or_init(|| {
            let flag = Arc::new(AtomicBool::new(false));
            let which = Arc::new(AtomicUsize::new(0));
            #[cfg(unix)]
            {
                use signal_hook::consts::{SIGINT, SIGTERM};
                if let Ok(mut signals) = signal_hook::iterator::Signals::new([SIGINT, SIGTERM]) {
                    let (flag, which) = (flag.clone(), which.clone());
                    std::thread::spawn(move || {
                        for sig in signals.forever() {
                            if !flag.swap(true, Ordering::SeqCst) {
                                which.store(sig as usize, Ordering::SeqCst);
                                continue;
                            }
                            let (name, code) = signal_name(sig as usize);
                            // Held to the exit: no folder is renamed or removed after.
                            let (_held, kept) = itaipu_calib::output::finish_on_signal();
                            for k in &kept {
                                eprintln!(
                                    "error: interrupted again by {name}: the finished stages are kept in {} (marked incomplete by partial.json); run the same command with --resume to go on",
                                    k.display()
                                );
                            }
                            if kept.is_empty() {
                                eprintln!("error: interrupted again by {name}; nothing written");
                            }
                            std::process::exit(code as i32);
                        }
                    });
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

/// The unit the next stage starts from, kept in a partial folder for `--resume` by earlier
/// versions (now in `partial.json`, written whole or not at all, with the stages it follows).
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
    /// The unit the next stage starts from (unit-file TOML; absent before the first stage).
    #[serde(default)]
    resume_unit: Option<String>,
}

/// Finished stages so far: labels, reports and the unit the next stage starts from.
#[derive(Default)]
struct Finished {
    labels: Vec<String>,
    reports: Vec<serde_json::Value>,
    resume_unit: Option<String>,
}

/// What `--resume` goes on from ([`read_partial`]).
struct Resumed {
    /// The folder whose finished stages are taken: `--out` itself, or the hidden temporary
    /// folder of a fit killed outright beside it.
    dir: PathBuf,
    state: PartialState,
    master: Unit,
    /// Temporary folders of the same fit (same options and inputs) beside `--out`, killed
    /// outright: their stages are in the finished folder once it is written, then they go.
    superseded: Vec<PathBuf>,
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
    let calib_given = match (&a.calib, bundled_unit) {
        (Some(p), _) => Some(p.clone()),
        (None, true) => Some(bundled("itaipu/calibration.toml")?),
        (None, false) => None,
    };
    let unit = load_unit(&unit_path)?;
    let (spec, calib_path, spec_text) =
        job::FitInputs::read_spec(calib_given.as_deref(), Some(&unit_path))?;
    let inputs = job::FitInputs {
        unit,
        unit_path: Some(unit_path.clone()),
        spec,
        spec_path: Some(calib_path.clone()),
        spec_text: Some(spec_text.clone()),
        events: event_paths
            .iter()
            .map(|p| load_event(p))
            .collect::<Result<Vec<_>, _>>()?,
        held_out: a
            .held_out
            .iter()
            .map(|p| load_event(p))
            .collect::<Result<Vec<_>, _>>()?,
    };
    let request = FitRequest {
        stages: a.stage.clone(),
        strategy: a.strategy,
        search: a.search.request(),
        no_polish: a.no_polish,
    };
    let (opts, warnings) = job::prepare_fit(&inputs, &request)?;
    for w in &warnings {
        eprintln!("warning: {w}");
    }
    // Said once: the report's text after the run counts these instead of repeating them.
    let shown = warnings.clone();
    let pool = a.search.pool()?;
    let unit = &inputs.unit;
    let events = &inputs.events;
    let held_out = &inputs.held_out;
    let name = events.first().map(|e| e.name.clone()).unwrap_or_default();
    let mut input_paths: Vec<&Path> = vec![&unit_path, &calib_path];
    input_paths.extend(event_paths.iter().map(|p| p.as_path()));
    input_paths.extend(a.held_out.iter().map(|p| p.as_path()));
    let inputs_hashes = input_hashes(&input_paths)?;
    let options = format!("{opts:?}");

    // --resume: the partial folder of an interrupted run with the same inputs and options,
    // `--out` or the hidden folder a fit killed outright left beside it.
    let resumed: Option<Resumed> = if a.resume {
        match read_partial(a.out.as_deref(), &options, &inputs_hashes, unit)? {
            ResumeFrom::Stages(r) => Some(*r),
            ResumeFrom::Completed(msg) => {
                println!("{msg}");
                return Ok(());
            }
        }
    } else {
        check_out(a.out.as_deref(), a.force)?;
        None
    };
    if a.discard_interrupted {
        if let Some(out) = &a.out {
            for d in itaipu_calib::output::discard_stale(out) {
                eprintln!("note: discarded {}", d.describe());
            }
        }
    }
    // The output folder, started before the (long) fit: the writability check.
    let staging = prepare_out(
        a.out.as_deref(),
        &format!("fit-{name}"),
        a.force || a.resume,
    )?;
    // (Without --out the folder is chosen only now.)
    if a.discard_interrupted && a.out.is_none() {
        for d in itaipu_calib::output::discard_stale(staging.target()) {
            eprintln!("note: discarded {}", d.describe());
        }
    }
    // Work a fit killed outright left beside the folder is never overwritten in silence: go on
    // from it (--resume) or delete it (--discard-interrupted).
    let stranded: Vec<&crate::output::Stale> = staging
        .kept_stale
        .iter()
        .filter(|k| k.path.exists())
        .filter(|k| {
            resumed
                .as_ref()
                .is_none_or(|r| r.dir != k.path && !r.superseded.contains(&k.path))
        })
        .collect();
    if !a.resume && !stranded.is_empty() {
        return Err(CliError::new(
            7,
            format!(
                "{} has the work of an interrupted fit beside it: {}; run the same command with --resume to go on from it, or with --discard-interrupted to delete it",
                staging.target().display(),
                stranded
                    .iter()
                    .map(|k| k.describe())
                    .collect::<Vec<_>>()
                    .join("; ")
            ),
        ));
    }
    let out = staging.path().to_path_buf();
    let finished = Mutex::new(Finished::default());
    let mut resume = None;
    if let Some(Resumed {
        dir,
        state: st,
        master,
        ..
    }) = &resumed
    {
        for label in &st.finished_stages {
            crate::output::copy_dir(&dir.join(label), &out.join(label)).map_err(|e| {
                CliError::new(
                    7,
                    format!("--resume: cannot copy {}: {e}", dir.join(label).display()),
                )
            })?;
        }
        let mut f = lock(&finished);
        f.labels = st.finished_stages.clone();
        f.reports = st.stage_reports.clone();
        f.resume_unit = (!st.finished_stages.is_empty()).then(|| unit_to_toml(master));
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
    let (flag, which) = interrupt_flags();
    flag.store(false, Ordering::SeqCst);
    which.store(0, Ordering::SeqCst);
    // The folder is marked partial and resumable from now on, so that whatever ends the run
    // (a first signal, a second one) leaves it complete or resumable.
    let partial = |f: &Finished, sig: &str| {
        PartialState {
        complete: false,
        note: "interrupted: an incomplete result. Every stage folder listed in finished_stages is complete and usable (its unit.toml simulates); run the same command again with --resume to go on".into(),
        interrupted_by: sig.into(),
        finished_stages: f.labels.clone(),
        command: crate::output::command(),
        options: options.clone(),
        inputs: inputs_hashes.clone(),
        stage_reports: f.reports.clone(),
        resume_unit: f.resume_unit.clone(),
    }
    };
    write_partial(&out, &partial(&lock(&finished), "-"))?;
    staging.mark_resumable();
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
    let reporter = Reporter::new(Detail::Phases, Some(flag.clone()));
    let no_plot = a.no_plot;
    let on_stage = |rep: &StageReport, st: &StageOutput, master: &Unit| -> Result<(), FitError> {
        let to_fit = |e: itaipu_calib::Error| FitError::Output(e.to_string());
        job::write_stage_files(&out, st, |dir| {
            if no_plot {
                return Ok(());
            }
            stage_plots(dir, st, rep).map_err(|e| itaipu_calib::Error::Output(e.msg))
        })
        .map_err(to_fit)?;
        let mut f = lock(&finished);
        f.resume_unit = Some(unit_to_toml(master));
        f.labels.push(rep.stage.clone());
        f.reports
            .push(serde_json::to_value(rep).map_err(|e| FitError::Output(e.to_string()))?);
        write_partial(&out, &partial(&f, "-")).map_err(|e| FitError::Output(e.msg))?;
        Ok(())
    };
    let control = FitControl {
        cancel: Some(flag.clone()),
        on_stage: Some(&on_stage),
        resume,
    };
    let resumed_reports = resumed
        .as_ref()
        .map(|r| {
            (
                r.state.finished_stages.clone(),
                r.state.stage_reports.clone(),
            )
        })
        .unwrap_or_default();
    let result = pool.install(|| {
        job::run_fit(
            &inputs,
            &opts,
            warnings,
            &reporter,
            &control,
            resumed_reports,
        )
    });
    reporter.finish();
    let run = match result {
        Ok(r) => r,
        Err(itaipu_calib::Error::Fit(FitError::Interrupted { .. })) => {
            let (sig, code) = signal_name(which.load(Ordering::SeqCst));
            let f = lock(&finished);
            write_partial(&out, &partial(&f, sig))?;
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
    let report = run.report.to_json()?;
    job::write_fit_files(&out, &run, &spec_text)?;
    let mut files = vec![
        InputFile::new("unit", &unit_path),
        InputFile::new("calibration spec", &calib_path),
    ];
    files.extend(events.iter().flat_map(|e| InputFile::event(e, false)));
    files.extend(held_out.iter().flat_map(|e| InputFile::event(e, true)));
    crate::output::write_synced(
        &out.join("report.html"),
        fit_report_html(&report, &run, events, held_out, files, !a.no_plot).as_bytes(),
    )?;
    // partial.json stays until the manifest is written (`Staging::commit`): killed at any
    // moment, the folder is resumable or complete.
    let target = crate::output::commit(staging, Some(opts.seed))?;
    // The hidden folders of this fit killed outright: their stages are in the folder now.
    if let Some(r) = &resumed {
        for d in r.superseded.iter().chain(std::iter::once(&r.dir)) {
            if d != &target && d.exists() && std::fs::remove_dir_all(d).is_ok() {
                eprintln!(
                    "note: removed {}: its finished stages are in {}",
                    d.display(),
                    target.display()
                );
            }
        }
    }
    print!("{}", run.report.to_text_after(&shown));
    println!("wrote  {}/report.json, report.html, calibrated.toml, datasheet.toml, calibration.toml, <stage>/{{unit.toml, traces.csv, traces_start.csv{}}}, manifest.json", target.display(), if a.no_plot { "" } else { ", plot.svg" });
    Ok(())
}

/// Writes `partial.json` into the folder being written.
fn write_partial(out: &Path, state: &PartialState) -> Result<(), CliError> {
    let text = serde_json::to_string_pretty(state).map_err(|e| CliError::new(7, e.to_string()))?;
    Ok(itaipu_calib::output::write_atomic(
        &out.join(crate::output::PARTIAL),
        text.as_bytes(),
    )?)
}

/// What `--resume` finds ([`read_partial`]).
enum ResumeFrom {
    /// Go on from these finished stages.
    Stages(Box<Resumed>),
    /// The interrupted fit had finished (it was killed renaming its folder into place): the
    /// folder is now in place; the message says so.
    Completed(String),
}

/// `--resume`: the partial folder of an interrupted run with this run's options and input
/// hashes: `out` itself (renamed into place with `partial.json` at a signal) or, for a fit
/// killed outright, the hidden temporary folder it left beside `out`
/// ([`crate::output::stale`]); of several, the one with the most finished stages. Each
/// candidate that differs is named with how. The unit the next stage starts from.
fn read_partial(
    out: Option<&Path>,
    options: &str,
    inputs: &[(String, String)],
    unit: &Unit,
) -> Result<ResumeFrom, CliError> {
    let Some(dir) = out else {
        return Err(CliError::new(
            2,
            "--resume needs --out: the folder an interrupted fit left (or was writing)",
        ));
    };
    let stale = crate::output::stale(dir);
    let complete_here = dir.join(crate::output::MANIFEST).is_file();
    // A fit killed while renaming its finished folder into place: put it there.
    if !complete_here {
        if let Some(done) = stale.iter().find(|s| {
            s.complete
                && s.path.join("report.json").is_file()
                && s.path.join("calibrated.toml").is_file()
        }) {
            if dir.exists() {
                std::fs::remove_dir_all(dir).map_err(|e| {
                    CliError::new(
                        7,
                        format!("--resume: cannot replace {}: {e}", dir.display()),
                    )
                })?;
            }
            std::fs::rename(&done.path, dir).map_err(|e| {
                CliError::new(
                    7,
                    format!(
                        "--resume: cannot rename {} into place: {e}",
                        done.path.display()
                    ),
                )
            })?;
            return Ok(ResumeFrom::Completed(format!(
                "resume {}: the interrupted fit had finished (killed while renaming its folder into place); renamed into place, nothing to run",
                dir.display()
            )));
        }
    }
    let with_work: Vec<&crate::output::Stale> =
        stale.iter().filter(|s| !s.finished.is_empty()).collect();
    if complete_here {
        if with_work.is_empty() {
            return Err(CliError::new(
                2,
                format!(
                    "--resume: {} is complete (it has manifest.json); nothing to resume",
                    dir.display()
                ),
            ));
        }
        return Err(CliError::new(
            2,
            format!(
                "--resume: {} is a complete output folder (manifest.json), and beside it is the work of an interrupted fit: {}; move {} aside, then run the same command again to go on from that work",
                dir.display(),
                with_work.iter().map(|s| s.describe()).collect::<Vec<_>>().join("; "),
                dir.display()
            ),
        ));
    }
    let mut candidates: Vec<PathBuf> = vec![];
    if dir.join(crate::output::PARTIAL).is_file() {
        candidates.push(dir.to_path_buf());
    }
    candidates.extend(with_work.iter().map(|s| s.path.clone()));
    if candidates.is_empty() {
        return Err(CliError::new(
            2,
            format!(
                "--resume: nothing to resume at {}: it holds no partial.json, and no interrupted fit left work beside it (no .{}.partial-PID folder with a finished stage)",
                dir.display(),
                dir.file_name().unwrap_or_default().to_string_lossy()
            ),
        ));
    }
    let mut matching: Vec<(PathBuf, PartialState)> = vec![];
    let mut differing: Vec<String> = vec![];
    for c in &candidates {
        let pj = c.join(crate::output::PARTIAL);
        let st: PartialState = match std::fs::read_to_string(&pj)
            .map_err(|e| e.to_string())
            .and_then(|t| serde_json::from_str(&t).map_err(|e| e.to_string()))
        {
            Ok(st) => st,
            Err(e) => {
                differing.push(format!("{}: {e}", pj.display()));
                continue;
            }
        };
        if st.options != options {
            differing.push(format!(
                "{}: the options differ from the interrupted run's (give the same stages, strategy, seed and search settings)\n  then: {}\n  now:  {options}",
                c.display(),
                st.options
            ));
            continue;
        }
        if st.inputs != inputs {
            let diff = st
                .inputs
                .iter()
                .zip(inputs)
                .find(|(x, y)| x != y)
                .map(|(x, y)| format!("{} (then) / {} (now)", x.0, y.0))
                .unwrap_or_else(|| "a different number of input files".into());
            differing.push(format!(
                "{}: the input files differ from the interrupted run's: {diff}",
                c.display()
            ));
            continue;
        }
        matching.push((c.clone(), st));
    }
    // The most finished stages; of equals, `out` itself (listed first).
    let Some(best) = (0..matching.len()).max_by(|&i, &j| {
        matching[i]
            .1
            .finished_stages
            .len()
            .cmp(&matching[j].1.finished_stages.len())
            .then(j.cmp(&i))
    }) else {
        return Err(CliError::new(
            2,
            format!("--resume: {}", differing.join("\n")),
        ));
    };
    let (src, st) = matching.swap_remove(best);
    let superseded: Vec<PathBuf> = matching
        .into_iter()
        .map(|(d, _)| d)
        .filter(|d| d != dir)
        .collect();
    let master = if st.finished_stages.is_empty() {
        unit.clone()
    } else {
        match &st.resume_unit {
            Some(text) => {
                itaipu_dynamics::unit_file::parse_unit(text, &src.join(crate::output::PARTIAL))
                    .map_err(|e| CliError::new(4, format!("--resume: {e}")))?
            }
            None => load_unit(&src.join(RESUME_UNIT))?,
        }
    };
    Ok(ResumeFrom::Stages(Box::new(Resumed {
        dir: src,
        state: st,
        master,
        superseded,
    })))
}

/// The fit's `report.html` (the command line's, and Python's `FitResult.write(html=True)`):
/// the unit as given and the calibrated unit simulated once more on every event for the
/// figures, in the playback the headline compares in (the fit's last pass's); an event that
/// does not simulate is left out of them, said on stderr (the fit itself simulated it).
/// `inputs` are the files for the provenance.
pub fn fit_report_html(
    report: &serde_json::Value,
    run: &job::FitRun,
    events: &[Event],
    held_out: &[Event],
    inputs: Vec<InputFile>,
    plots: bool,
) -> String {
    let prov = Provenance::new(inputs, run.options.seed);
    let (start, calibrated) = (&run.datasheet, &run.unit);
    let mode = run.report.headline.mode;
    let mut runs = vec![];
    if plots {
        for (e, h) in events
            .iter()
            .map(|e| (e, false))
            .chain(held_out.iter().map(|e| (e, true)))
        {
            let sim = |u: &Unit| simulate_mode_traces(u, e, mode, &Default::default());
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

/// Draws a finished stage's plots into its folder `dir`: per fitted event, measured, start and
/// calibrated P and Q (`plot[_<event>].svg`).
fn stage_plots(dir: &Path, st: &StageOutput, rep: &StageReport) -> Result<(), CliError> {
    for (ev, start, end) in &st.traces {
        let suffix = job::stage_trace_suffix(st, ev);
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
        let mut panels = vec![
            plot::start_end_panel(t, "P [pu, system base]".into(), "measured", &pm, &ps, &pe),
            plot::start_end_panel(t, "Q [pu, system base]".into(), "measured", &qm, &qs, &qe),
        ];
        // A stage in a playback mode (its traces carry v_meas_pu): |V| (simulated in a closed
        // loop) and E_fd too. (The nominal frequency only converts the frequency channel,
        // which these plots leave out.)
        let moded = end.get("v_meas_pu").is_some();
        let (others, starts) = if moded {
            (
                crate::report::other_channels(end, 50.0),
                crate::report::other_channels(start, 50.0),
            )
        } else {
            (vec![], vec![])
        };
        for ((label, meas, sim), (_, _, sim0)) in others.iter().zip(&starts) {
            if !label.starts_with("frequency") {
                panels.push(plot::start_end_panel(
                    t,
                    label.clone(),
                    "measured",
                    meas,
                    sim0,
                    sim,
                ));
            }
        }
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
    Ok(())
}
