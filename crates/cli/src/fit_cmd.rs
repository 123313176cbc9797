//! `itaipu-calib fit`: staged calibration with report, calibrated unit, traces and plots.

use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use clap::ValueEnum;
use indicatif::{ProgressBar, ProgressStyle};
use itaipu_calib::fit::{fit, FitOptions, FitReport, Progress};
use itaipu_calib::spec::{CalibSpec, Strategy};
use itaipu_dynamics::unit_file::unit_to_toml;

use crate::{
    bundled, check_out, load_event, load_unit, plot, prepare_out, CliError, SearchArgs, EXIT_CODES,
};

#[derive(clap::Args, Debug)]
#[command(after_help = EXIT_CODES)]
pub struct FitArgs {
    /// Stage(s) to run: gen (machine, E_fd and P_m held), avr, pss, tg, or all (every stage the
    /// spec lists). Several stages (`--stage gen,avr,pss`) run in the fixed order gen, avr, pss,
    /// tg, each starting from the previous result.
    #[arg(long, value_enum, value_delimiter = ',', num_args = 1.., default_values_t = [StageArg::All])]
    stage: Vec<StageArg>,
    /// How stages are combined (default: the spec's, else sequential).
    #[arg(long, value_enum)]
    strategy: Option<StrategyArg>,
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
    /// Allow writing into an existing, non-empty --out folder.
    #[arg(long)]
    force: bool,
    #[command(flatten)]
    search: SearchArgs,
    /// Do not draw the plots.
    #[arg(long)]
    no_plot: bool,
    /// Skip the final joint refinement of all stages' parameters on the full unit.
    #[arg(long)]
    no_polish: bool,
}

#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
enum StageArg {
    Gen,
    Avr,
    Pss,
    Tg,
    All,
}

#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
enum StrategyArg {
    Sequential,
    Incremental,
    SimultaneousFirst,
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

fn strategy(s: StrategyArg) -> Strategy {
    match s {
        StrategyArg::Sequential => Strategy::Sequential,
        StrategyArg::Incremental => Strategy::Incremental,
        StrategyArg::SimultaneousFirst => Strategy::SimultaneousFirst,
    }
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
    let spec = CalibSpec::from_file(&calib_path).map_err(|e| CliError::new(4, e.to_string()))?;
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
    if let Some(s) = a.strategy {
        opts.strategy = strategy(s);
    }
    if !a.stage.contains(&StageArg::All) {
        let wanted: Vec<String> = a
            .stage
            .iter()
            .map(|s| format!("{s:?}").to_lowercase())
            .collect();
        opts.stages = itaipu_calib::spec::STAGES
            .iter()
            .filter(|s| wanted.iter().any(|w| w == *s))
            .map(|s| s.to_string())
            .collect();
    }
    if a.no_polish {
        opts.polish = false;
    }
    a.search.apply(
        &mut opts.seed,
        &mut opts.particles,
        &mut opts.pso_iterations,
        &mut opts.lbfgs_iterations,
    );
    let pool = a.search.pool()?;
    let name = events.first().map(|e| e.name.clone()).unwrap_or_default();
    // Check the output folder before the (long) fit, create it after.
    check_out(a.out.as_deref(), a.force)?;
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
    let result = pool.install(|| fit(&unit, &spec, &events, &held_out, &opts, &reporter));
    let result = result.map_err(|e| {
        let code = if matches!(e, itaipu_calib::fit::FitError::Spec(_)) {
            4
        } else {
            6
        };
        CliError::new(code, e.to_string())
    })?;
    reporter.finish();
    let out = prepare_out(a.out.as_deref(), &format!("fit-{name}"), a.force)?;
    let write = |p: &Path, text: &str| {
        std::fs::write(p, text)
            .map_err(|e| CliError::new(7, format!("cannot write {}: {e}", p.display())))
    };
    let json = serde_json::to_string_pretty(&result.report)
        .map_err(|e| CliError::new(7, e.to_string()))?;
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
    for st in &result.stages {
        let dir = out.join(&st.stage);
        std::fs::create_dir_all(&dir)
            .map_err(|e| CliError::new(7, format!("cannot create {}: {e}", dir.display())))?;
        write(&dir.join("unit.toml"), &unit_to_toml(&st.calibrated_unit))?;
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
            if !a.no_plot {
                let t = &end.time_s;
                let g =
                    |tr: &itaipu_dynamics::simulate::Traces, n: &str| tr.get(n).unwrap().to_vec();
                let (pm, qm, ps, qs, pe, qe) = (
                    g(end, "p_meas_pu"),
                    g(end, "q_meas_pu"),
                    g(start, "p_pu"),
                    g(start, "q_pu"),
                    g(end, "p_pu"),
                    g(end, "q_pu"),
                );
                let panels = vec![
                    plot::Panel {
                        y_label: "P [pu, system base]".into(),
                        series: vec![
                            plot::Series {
                                label: "measured".into(),
                                x: t,
                                y: &pm,
                                color: plot::MEASURED,
                                thin: true,
                            },
                            plot::Series {
                                label: "start".into(),
                                x: t,
                                y: &ps,
                                color: plot::START,
                                thin: true,
                            },
                            plot::Series {
                                label: "calibrated".into(),
                                x: t,
                                y: &pe,
                                color: plot::SIMULATED,
                                thin: false,
                            },
                        ],
                    },
                    plot::Panel {
                        y_label: "Q [pu, system base]".into(),
                        series: vec![
                            plot::Series {
                                label: "measured".into(),
                                x: t,
                                y: &qm,
                                color: plot::MEASURED,
                                thin: true,
                            },
                            plot::Series {
                                label: "start".into(),
                                x: t,
                                y: &qs,
                                color: plot::START,
                                thin: true,
                            },
                            plot::Series {
                                label: "calibrated".into(),
                                x: t,
                                y: &qe,
                                color: plot::SIMULATED,
                                thin: false,
                            },
                        ],
                    },
                ];
                let rep = result.report.stages.iter().find(|r| r.stage == st.stage);
                let title = match rep {
                    Some(r) => format!(
                        "{ev}, stage {}: objective {:.4} -> {:.4}",
                        st.stage, r.objective_before, r.objective_after
                    ),
                    None => format!("{ev}, stage {}", st.stage),
                };
                plot::draw(
                    &dir.join(format!("plot{suffix}.svg")),
                    &title,
                    "time [s]",
                    &panels,
                )
                .map_err(|e| CliError::new(7, e))?;
            }
        }
    }
    print_report(&result.report);
    println!("wrote  {}/report.json, calibrated.toml, datasheet.toml, calibration.toml, <stage>/{{unit.toml, traces.csv, traces_start.csv{}}}", out.display(), if a.no_plot { "" } else { ", plot.svg" });
    Ok(())
}

fn print_report(r: &FitReport) {
    for s in &r.stages {
        println!();
        println!(
            "stage {} ({}, objective {:?}): {:.5} -> {:.5}; {} simulations, {} failed candidates, {:.1} s",
            s.stage, s.strategy, s.objective, s.objective_before, s.objective_after, s.simulations, s.failed_candidates, s.wall_s
        );
        for ph in &s.phases {
            println!(
                "  {:<28} {:>4} iterations, best {:.5} ({})",
                ph.phase, ph.iterations, ph.best_objective, ph.stopped_by
            );
        }
        println!(
            "  {:<22} {:>10} {:>21} {:>10} {:>10}",
            "parameter", "start", "bounds", "result", "std err"
        );
        for p in &s.parameters {
            println!(
                "  {:<22} {:>10.4} {:>10}-{:<10} {:>10.4} {:>10.2e}{}",
                p.param,
                p.start,
                format!("{}", p.min),
                format!("{}", p.max),
                p.result,
                p.std_error,
                if p.at_bound { "  at bound" } else { "" }
            );
        }
        for (a, b, rho) in &s.correlated_pairs {
            println!("  not separately identifiable: {a} and {b} (correlation {rho:+.3})");
        }
        for u in &s.unidentified {
            println!("  not determined by the data: {u}");
        }
        if !s.weakly_determined.is_empty() {
            println!(
                "  weakly determined (std err > 1 %): {}",
                s.weakly_determined.join(", ")
            );
        }
        println!(
            "  identifiable: {}",
            if s.identifiable.is_empty() {
                "none".to_string()
            } else {
                s.identifiable.join(", ")
            }
        );
    }
    println!();
    println!("fitness J = sum(dP^2 + dQ^2) per event (system base; * = held out)");
    let mut header = vec!["stage".to_string()];
    header.extend(
        r.start_fitness
            .iter()
            .map(|f| format!("{}{}", f.event, if f.held_out { "*" } else { "" })),
    );
    println!(
        "  {}",
        header
            .iter()
            .map(|h| format!("{h:>22}"))
            .collect::<String>()
    );
    let row = |name: &str, f: &[itaipu_calib::fit::EventFitness]| {
        println!(
            "  {:>22}{}",
            name,
            f.iter()
                .map(|x| format!("{:>22.4}", x.j_pq))
                .collect::<String>()
        );
    };
    row("start", &r.start_fitness);
    for s in &r.stages {
        row(&s.stage, &s.fitness);
    }
    println!("total {:.1} s on {} threads", r.wall_s, r.threads);
}
