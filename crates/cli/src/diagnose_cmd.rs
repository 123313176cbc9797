//! `itaipu-calib diagnose`: what a (calibrated) unit still gets wrong on measured events, which
//! cause of the catalog explains it, the extended and re-fitted unit, evidence plots and an HTML
//! report.

use std::collections::BTreeSet;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use itaipu_calib::diagnose::{
    calibrated_set, catalog, diagnose, refit_bounds,
    user_cause::{self, read_all, UserCause},
    CandidateReport, DiagnoseError, DiagnoseOptions, Diagnosis, EventEvidence, RefitRequest,
};
use itaipu_calib::evidence::{SignalEvidence, WindowStats};
use itaipu_calib::spec::CalibSpec;
use itaipu_dynamics::simulate::Traces;
use itaipu_dynamics::unit_file::unit_to_toml;

use crate::fit_cmd::Reporter;
use crate::{bundled, load_event, load_unit, plot, prepare_out, CliError, SearchArgs, EXIT_CODES};

#[derive(clap::Args, Debug)]
#[command(after_help = EXIT_CODES)]
pub struct DiagnoseArgs {
    /// Event file(s) to diagnose on (the candidates are fitted on them). Default: the bundled
    /// Itaipu record.
    #[arg(long, value_name = "FILE", num_args = 1..)]
    event: Vec<PathBuf>,
    /// Event file(s) held out: the candidates are judged on them. Without, each event is split
    /// into alternating 0.5 s blocks, even blocks fitted and odd blocks held out.
    #[arg(long, value_name = "FILE", num_args = 1..)]
    held_out: Vec<PathBuf>,
    /// Unit model file, normally a calibrated one (e.g. fit's calibrated.toml). Default: the
    /// bundled Itaipu unit.
    #[arg(long, value_name = "FILE")]
    unit: Option<PathBuf>,
    /// A `fit` output folder: diagnose its calibrated.toml and re-fit the whole calibrated set
    /// (every parameter its calibration.toml frees, within the spec's bounds) in every
    /// baseline and extension, with the same prior around its datasheet.toml values, so that an
    /// effect the calibration absorbed by bending right values is still seen.
    #[arg(long, value_name = "DIR", conflicts_with = "unit")]
    fit: Option<PathBuf>,
    /// Cause(s) of the catalog to try (repeatable or comma-separated), e.g.
    /// `--cause measurement_skew,saturation`. Default: the whole catalog.
    #[arg(long, value_name = "ID", num_args = 1.., value_delimiter = ',')]
    cause: Vec<String>,
    /// A cause written by the user (repeatable): a TOML file declaring the blocks its model
    /// extension adds (user-defined diagrams or library models), the ports of the unit it
    /// rewires and the parameters the re-fit frees (see data/causes/reactive_droop.toml). It is
    /// tried after the catalog's causes, or alone with `--cause ITS_ID`.
    #[arg(long, value_name = "FILE")]
    user_cause: Vec<PathBuf>,
    /// Calibrated parameter(s) to free again in every re-fit, baselines and extensions alike
    /// (repeatable or comma-separated): `PARAM` within the model's declared range, or
    /// `PARAM=MIN:MAX`, e.g. `--refit machine.h,exciter.k=50:200`. For the stage parameters a
    /// calibration may have bent to make up for the missing cause; they are polished with
    /// L-BFGS after each candidate's global search.
    #[arg(long, value_name = "PARAM[=MIN:MAX]", num_args = 1.., value_delimiter = ',')]
    refit: Vec<String>,
    /// Output folder (diagnosis.json, extended.toml, plots, report.html). Default:
    /// out/diagnose-<first event>, or a new numbered folder beside it. An existing --out folder
    /// is never overwritten unless --force is given.
    #[arg(long, value_name = "DIR")]
    out: Option<PathBuf>,
    /// Allow writing into an existing, non-empty --out folder.
    #[arg(long)]
    force: bool,
    #[command(flatten)]
    search: SearchArgs,
    /// Do not draw the plots (report.html is written without them).
    #[arg(long)]
    no_plot: bool,
}

/// Terminal width the tables are laid out for.
const WIDTH: usize = 100;

/// Exit code of an engine error, as `fit` maps its errors: a unit that cannot initialise or
/// simulate on an event as given, and any other failure of the run, is 6. (Unknown causes, the
/// engine's only usage error, are refused with 2 before it runs.)
fn error_code(e: &DiagnoseError) -> u8 {
    match e {
        DiagnoseError::Simulation { .. } | DiagnoseError::Setup(_) => 6,
        // The command line sets no cancel flag (a signal ends the process, exit 130/143).
        DiagnoseError::Interrupted { .. } => 130,
    }
}

/// The `--refit` requests as `(path, bounds)`: `PARAM` or `PARAM=MIN:MAX`. Malformed numbers
/// are a usage error (exit 2) naming the request; whether the parameter exists is checked
/// against the unit by [`refit_bounds`].
fn refit_requests(requested: &[String]) -> Result<Vec<RefitRequest>, CliError> {
    requested
        .iter()
        .map(|r| {
            let r = r.trim();
            let bad = |why: &str| {
                CliError::new(2, format!("--refit {r}: {why} (PARAM or PARAM=MIN:MAX)"))
            };
            match r.split_once('=') {
                None if !r.is_empty() => Ok((r.to_string(), None)),
                None => Err(bad("empty")),
                Some((p, range)) => {
                    let (lo, hi) = range
                        .split_once(':')
                        .ok_or_else(|| bad("no ':' between MIN and MAX"))?;
                    let num = |v: &str| {
                        v.trim()
                            .parse::<f64>()
                            .ok()
                            .filter(|x| x.is_finite())
                            .ok_or_else(|| bad(&format!("'{}' is not a finite number", v.trim())))
                    };
                    Ok((p.trim().to_string(), Some((num(lo)?, num(hi)?))))
                }
            }
        })
        .collect()
}

/// The `--cause` ids, checked against the catalog, without duplicates, in the order given.
fn causes(requested: &[String], users: &[UserCause]) -> Result<Vec<String>, CliError> {
    let mut seen = BTreeSet::new();
    let mut out = vec![];
    for c in requested {
        let c = c.trim();
        if !user_cause::known(c, users) {
            return Err(CliError::new(
                2,
                format!(
                    "--cause: unknown cause '{c}' (known: {})",
                    user_cause::ids(users)
                ),
            ));
        }
        if seen.insert(c.to_string()) {
            out.push(c.to_string());
        }
    }
    Ok(out)
}

pub fn cmd_diagnose(a: &DiagnoseArgs) -> Result<(), CliError> {
    // Usage errors first, then the input files, then the output folder, then the (long) run.
    let user_causes = read_all(&a.user_cause).map_err(|e| CliError::new(4, e.to_string()))?;
    let mut opts = DiagnoseOptions {
        causes: causes(&a.cause, &user_causes)?,
        user_causes,
        ..Default::default()
    };
    a.search.apply(
        &mut opts.seed,
        &mut opts.particles,
        &mut opts.pso_iterations,
        &mut opts.lbfgs_iterations,
    )?;
    let pool = a.search.pool()?;
    let threads = pool.current_num_threads();
    let unit_path = match (&a.unit, &a.fit) {
        (Some(p), _) => p.clone(),
        (None, Some(dir)) => dir.join("calibrated.toml"),
        (None, None) => bundled("itaipu/unit.toml")?,
    };
    let event_paths = if a.event.is_empty() {
        vec![bundled("itaipu/event.toml")?]
    } else {
        a.event.clone()
    };
    let unit = load_unit(&unit_path)?;
    opts.refit = refit_bounds(&unit, &refit_requests(&a.refit)?)
        .map_err(|e| CliError::new(2, format!("--refit: {e} (unit {})", unit_path.display())))?;
    if let Some(dir) = &a.fit {
        let spec_path = dir.join("calibration.toml");
        let spec = CalibSpec::from_file(&spec_path).map_err(|e| CliError::new(4, e.to_string()))?;
        let datasheet = load_unit(&dir.join("datasheet.toml"))?;
        let stages: Vec<String> = spec.stages.iter().map(|s| s.name.clone()).collect();
        for b in calibrated_set(&spec, &stages, &datasheet, &unit) {
            if !opts.refit.iter().any(|r| r.param == b.param) {
                opts.refit.push(b);
            }
        }
    }
    let events = event_paths
        .iter()
        .map(|p| load_event(p))
        .collect::<Result<Vec<_>, _>>()?;
    let held_out = a
        .held_out
        .iter()
        .map(|p| load_event(p))
        .collect::<Result<Vec<_>, _>>()?;
    let name = events.first().map(|e| e.name.clone()).unwrap_or_default();
    let warnings = crate::plausibility(
        &events.iter().chain(&held_out).collect::<Vec<_>>(),
        &unit,
        &unit_path,
    )?;
    // The output folder: checked and started before the (long) diagnosis.
    let staging = prepare_out(a.out.as_deref(), &format!("diagnose-{name}"), a.force)?;
    // One playback of the unit on every event first (milliseconds): a unit that does not
    // initialise or integrate on an event stops here with the sample or the operating point
    // the failure comes from, not after the diagnosis with the event's name only.
    for e in events.iter().chain(&held_out) {
        itaipu_dynamics::simulate::simulate(&unit, e, &Default::default())
            .map_err(|err| crate::explain_sim_error(err, e, &unit))?;
    }
    let tried = if opts.causes.is_empty() {
        format!(
            "all {} causes",
            catalog::CAUSES.len() + opts.user_causes.len()
        )
    } else {
        opts.causes.join(", ")
    };
    let header = format!(
        "unit {} ({}), events {}{}, causes {tried}, seed {}, {threads} threads",
        unit.name,
        unit_path.display(),
        events
            .iter()
            .map(|e| e.name.as_str())
            .collect::<Vec<_>>()
            .join(", "),
        if held_out.is_empty() {
            String::new()
        } else {
            format!(
                " (held out: {})",
                held_out
                    .iter()
                    .map(|e| e.name.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            )
        },
        opts.seed,
    );
    let header = if opts.refit.is_empty() {
        header
    } else {
        let freed: Vec<String> = opts
            .refit
            .iter()
            .map(|b| format!("{} [{}, {}]", b.param, b.min, b.max))
            .collect();
        format!("{header}; re-freed in every re-fit: {}", freed.join(", "))
    };
    println!("{}", wrap(&header, WIDTH, "diagnose ", "         "));
    let reporter = Reporter::new();
    let result = pool.install(|| diagnose(&unit, &events, &held_out, &opts, &reporter));
    reporter.finish();
    let result = result.map_err(|e| CliError::new(error_code(&e), format!("diagnose: {e}")))?;
    let report = &result.report;

    let out = staging.path().to_path_buf();
    let write = |p: &Path, text: &str| {
        std::fs::write(p, text)
            .map_err(|e| CliError::new(7, format!("cannot write {}: {e}", p.display())))
    };
    let json = serde_json::to_string_pretty(report).map_err(|e| CliError::new(7, e.to_string()))?;
    write(&out.join("diagnosis.json"), &json)?;
    let mut written = vec!["diagnosis.json".to_string()];
    let extended_note = match &result.extended_unit {
        Some(u) => {
            let mut u = u.clone();
            let note = format!(
                "extended for {} and re-fitted by itaipu-calib diagnose, seed {}",
                report.verdict.cause, opts.seed
            );
            u.description = if unit.description.trim().is_empty() {
                note
            } else {
                format!("{} ({note})", unit.description)
            };
            write(&out.join("extended.toml"), &unit_to_toml(&u))?;
            written.push("extended.toml".into());
            None
        }
        None => Some(format!(
            "no cause named ({}): extended.toml not written",
            report.verdict.cause
        )),
    };
    let plots = if a.no_plot {
        vec![]
    } else {
        draw_plots(&out, &result.report, &result.before, &result.after)?
    };
    written.extend(plots.iter().map(|p| p.file.clone()));
    write(
        &out.join("report.html"),
        &html_report(report, &unit_path, &event_paths, &out, &plots),
    )?;
    written.push("report.html".into());

    print_report(report);
    if let Some(n) = extended_note {
        println!("{n}");
    }
    crate::write_warnings(&out, &warnings)?;
    if !warnings.is_empty() {
        written.push("warnings.json".into());
    }
    let target = staging.commit(Some(opts.seed))?;
    written.push(crate::output::MANIFEST.into());
    println!("wrote    {}/", target.display());
    let files: Vec<&str> = written.iter().map(String::as_str).collect();
    println!(
        "{}",
        wrap_items(&files, ", ", WIDTH, "         ", "         ")
    );
    Ok(())
}

// ---------------------------------------------------------------------------------------------
// Terminal
// ---------------------------------------------------------------------------------------------

/// Numbers for people: 4 decimals, scientific when very small or large.
fn num(v: f64) -> String {
    if !v.is_finite() {
        return format!("{v}");
    }
    if v != 0.0 && (v.abs() < 1e-2 || v.abs() >= 1e4) {
        format!("{v:.3e}")
    } else {
        format!("{v:.4}")
    }
}

/// A χ² value: one decimal, scientific when large.
fn chi2(v: f64) -> String {
    if v.is_finite() && v.abs() < 1e7 {
        format!("{v:.1}")
    } else {
        format!("{v:.4e}")
    }
}

/// A percentage with one decimal.
fn pct(v: f64) -> String {
    if v.is_finite() {
        format!("{:.1} %", 100.0 * v)
    } else {
        "-".into()
    }
}

/// Greedy word wrap to `width` columns; continuation lines start with `indent`.
fn wrap(text: &str, width: usize, first: &str, indent: &str) -> String {
    let words: Vec<&str> = text.split_whitespace().collect();
    wrap_items(&words, " ", width, first, indent)
}

/// Lays `items` out joined by `sep`, breaking lines between items to `width` columns (an item
/// longer than a line is broken between its words); continuation lines start with `indent`.
fn wrap_items(items: &[&str], sep: &str, width: usize, first: &str, indent: &str) -> String {
    let len = |s: &str| s.chars().count();
    let sep_trim = sep.trim_end();
    let mut out: Vec<String> = vec![];
    let mut line = first.to_string();
    let mut fresh = true;
    for (k, item) in items.iter().enumerate() {
        let piece = if k + 1 == items.len() {
            item.to_string()
        } else {
            format!("{item}{sep_trim}")
        };
        if !fresh && len(&line) + 1 + len(&piece) > width {
            out.push(std::mem::replace(&mut line, indent.to_string()));
            fresh = true;
        }
        let words: Vec<&str> = if len(&line) + usize::from(!fresh) + len(&piece) <= width {
            vec![piece.as_str()]
        } else {
            piece.split_whitespace().collect()
        };
        for w in words {
            if !fresh && len(&line) + 1 + len(w) > width {
                out.push(std::mem::replace(&mut line, indent.to_string()));
                fresh = true;
            }
            if !fresh {
                line.push(' ');
            }
            line.push_str(w);
            fresh = false;
        }
    }
    out.push(line);
    out.iter()
        .map(|l| l.trim_end())
        .collect::<Vec<_>>()
        .join("\n")
}

/// A value with its unit (none for dimensionless parameters).
fn with_unit(v: f64, unit: &str) -> String {
    text_with_unit(num(v), unit)
}

/// `text` followed by `unit` (nothing for a dimensionless `-`).
fn text_with_unit(text: String, unit: &str) -> String {
    match unit.trim() {
        "" | "-" => text,
        u => format!("{text} {u}"),
    }
}

/// The fitted extension parameters of a candidate, or why there are none.
fn key_params(c: &CandidateReport) -> Vec<String> {
    if !c.applicable || c.gains.is_none() {
        return vec![c.note.clone()];
    }
    let mut v: Vec<String> = c
        .parameters
        .iter()
        .filter(|p| p.extension)
        .map(|p| {
            let value = match p.std_error {
                Some(se) if se.is_finite() => {
                    text_with_unit(format!("{} ± {}", num(p.result), num(se)), &p.unit)
                }
                Some(_) => format!(
                    "{} (not determined by the data)",
                    with_unit(p.result, &p.unit)
                ),
                None => with_unit(p.result, &p.unit),
            };
            format!(
                "{} = {value}{}",
                p.param,
                if p.at_bound { " (at bound)" } else { "" }
            )
        })
        .collect();
    v.extend(c.fixed.iter().map(|(p, x)| format!("{p} = {x}")));
    if v.is_empty() {
        v.push("(no continuous parameter)".into());
    }
    v
}

/// The window holding the largest share of the squared error.
fn top_window(s: &SignalEvidence) -> Option<&WindowStats> {
    s.windows
        .iter()
        .max_by(|a, b| a.share_of_sse.total_cmp(&b.share_of_sse))
}

/// The oscillatory mode (above 0.1 Hz) with the largest energy share, as text.
fn dominant_mode(s: &SignalEvidence) -> String {
    s.modes
        .iter()
        .filter(|m| m.freq_hz > 0.1)
        .max_by(|a, b| a.energy_share.total_cmp(&b.energy_share))
        .map(|m| format!("{:.2} Hz, ζ {:.2}", m.freq_hz, m.damping_ratio))
        .unwrap_or_else(|| "none".into())
}

fn print_report(r: &Diagnosis) {
    println!();
    println!(
        "{}",
        wrap(
            &format!("{}: {}", r.verdict.cause, r.verdict.title),
            WIDTH,
            "verdict  ",
            "         "
        )
    );
    println!(
        "{}",
        wrap(&r.verdict.statement, WIDTH, "         ", "         ")
    );
    println!();
    let noise = format!(
        "σP {} pu, σQ {} pu (pre-event residual); split: {} ({} fitted, {} held-out samples)",
        num(r.noise.sigma_p),
        num(r.noise.sigma_q),
        r.noise.split,
        r.noise.n_fit,
        r.noise.n_held
    );
    println!("{}", wrap(&noise, WIDTH, "noise    ", "         "));
    println!();
    println!(
        "candidates (* = significant, ranked by the extended model's BIC; the others by ΔBIC)"
    );
    println!(
        "  {:<18} {:>9} {:>9} {:>9} {:>2} {:1}  key parameters / note",
        "cause", "ΔBIC", "fit χ²↓", "held χ²↓", "k", ""
    );
    let indent = " ".repeat(2 + 18 + 1 + 9 + 1 + 9 + 1 + 9 + 1 + 2 + 1 + 1 + 2);
    for c in &r.candidates {
        let head = match &c.gains {
            Some(g) => format!(
                "  {:<18} {:>9.1} {:>9} {:>9} {:>2} {:1}  ",
                c.cause,
                g.delta_bic,
                pct(g.fit_drop),
                pct(g.held_drop),
                g.k,
                if c.significant { "*" } else { "" }
            ),
            None => format!(
                "  {:<18} {:>9} {:>9} {:>9} {:>2} {:1}  ",
                c.cause, "-", "-", "-", "-", ""
            ),
        };
        let items = key_params(c);
        if !c.applicable || c.gains.is_none() {
            println!("{}", wrap(&items[0], WIDTH, &head, &indent));
        } else {
            let items: Vec<&str> = items.iter().map(String::as_str).collect();
            println!("{}", wrap_items(&items, ", ", WIDTH, &head, &indent));
        }
    }
    println!();
    let after_of = |event: &str, signal: &str| {
        r.evidence_after
            .iter()
            .find(|e| e.event == event)
            .and_then(|e| e.signals.iter().find(|s| s.signal == signal))
    };
    let with_after = !r.evidence_after.is_empty();
    for e in &r.evidence {
        println!("evidence {} (event onset {:.2} s)", e.event, e.onset_s);
        println!(
            "  {:<4} {:>9}{} {:>11}  {:<32} dominant mode",
            "sig",
            "RMS/noise",
            if with_after {
                format!(" {:>9}", "extended")
            } else {
                String::new()
            },
            "Ljung-Box p",
            "window with most SSE",
        );
        for s in &e.signals {
            let w = top_window(s)
                .map(|w| {
                    format!(
                        "{} {:.2}-{:.2} s ({:.0} %)",
                        w.label,
                        w.start_s,
                        w.end_s,
                        100.0 * w.share_of_sse
                    )
                })
                .unwrap_or_else(|| "-".into());
            let after = if with_after {
                format!(
                    " {:>9}",
                    after_of(&e.event, &s.signal)
                        .map(|a| format!("{:.2}", a.rms_over_noise))
                        .unwrap_or_else(|| "-".into())
                )
            } else {
                String::new()
            };
            println!(
                "  {:<4} {:>9.2}{after} {:>11.3}  {:<32} {}",
                s.signal,
                s.rms_over_noise,
                s.whiteness.p_value,
                w,
                dominant_mode(s)
            );
        }
    }
    println!(
        "total {:.1} s on {} threads, seed {}",
        r.wall_s, r.threads, r.seed
    );
}

// ---------------------------------------------------------------------------------------------
// Plots
// ---------------------------------------------------------------------------------------------

/// A drawn plot: file name in the output folder, event and what it shows.
pub struct PlotFile {
    pub file: String,
    pub event: String,
    pub caption: String,
}

/// `name` made safe as part of a file name.
fn file_stem(name: &str) -> String {
    let s: String = name
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || "-_.".contains(c) {
                c
            } else {
                '_'
            }
        })
        .collect();
    if s.is_empty() {
        "event".into()
    } else {
        s
    }
}

fn residual(tr: &Traces, sim: &str, meas: &str) -> Vec<f64> {
    match (tr.get(sim), tr.get(meas)) {
        (Some(s), Some(m)) => s.iter().zip(m).map(|(a, b)| a - b).collect(),
        _ => vec![f64::NAN; tr.time_s.len()],
    }
}

fn draw_plots(
    out: &Path,
    r: &Diagnosis,
    before: &[(String, Traces)],
    after: &[(String, Traces)],
) -> Result<Vec<PlotFile>, CliError> {
    let mut files = vec![];
    let mut stems = BTreeSet::new();
    let named = Some(r.verdict.cause.as_str()).filter(|c| *c != "none" && *c != "unexplained");
    for (k, (event, tr)) in before.iter().enumerate() {
        let mut stem = file_stem(event);
        if !stems.insert(stem.clone()) {
            stem = format!("{stem}-{}", k + 1);
            stems.insert(stem.clone());
        }
        let ev = r.evidence.iter().find(|e| &e.event == event);
        let tr_after = after.iter().find(|(e, _)| e == event).map(|(_, t)| t);
        let t = &tr.time_s;
        let draw = |file: &str,
                    title: &str,
                    x_label: &str,
                    panels: &[plot::Panel],
                    decor: &[plot::Decor]| {
            plot::draw_with(&out.join(file), title, x_label, panels, decor)
                .map_err(|e| CliError::new(7, e))
        };

        // Residuals with the implicated window and the noise band.
        let (rp, rq) = (
            residual(tr, "p_pu", "p_meas_pu"),
            residual(tr, "q_pu", "q_meas_pu"),
        );
        let after_res = tr_after.map(|ta| {
            (
                residual(ta, "p_pu", "p_meas_pu"),
                residual(ta, "q_pu", "q_meas_pu"),
            )
        });
        let mut panels = vec![];
        let mut decor = vec![];
        for (signal, res, sigma, k) in [
            ("P", &rp, r.noise.sigma_p, 0),
            ("Q", &rq, r.noise.sigma_q, 1),
        ] {
            let mut series = vec![plot::Series {
                label: "as given".into(),
                x: t,
                y: res,
                color: plot::START,
                thin: false,
            }];
            if let (Some(ta), Some((ap, aq)), Some(cause)) = (tr_after, &after_res, named) {
                let y = if k == 0 { ap } else { aq };
                series.push(plot::Series {
                    label: format!("with {cause}"),
                    x: &ta.time_s,
                    y,
                    color: plot::SIMULATED,
                    thin: false,
                });
            }
            panels.push(plot::Panel {
                y_label: format!("{signal} residual (sim − meas) [pu]"),
                series,
            });
            decor.push(plot::Decor {
                spans: implicated_window(r, ev, signal).into_iter().collect(),
                y_bands: vec![plot::YBand {
                    label: format!("±σ{signal} noise {}", num(sigma)),
                    y0: -sigma,
                    y1: sigma,
                    color: plot::NOISE,
                }],
                markers: vec![],
            });
        }
        let file = format!("residual-{stem}.svg");
        draw(
            &file,
            &format!("{event}: residuals; verdict {}", r.verdict.cause),
            "time [s]",
            &panels,
            &decor,
        )?;
        files.push(PlotFile { file, event: event.clone(), caption: "P and Q residuals (simulated − measured), the implicated window shaded, ±σ noise band".into() });

        // Residual spectra with the peak marked.
        if let Some(ev) = ev {
            let mut panels = vec![];
            let mut decor = vec![];
            for signal in ["P", "Q"] {
                let Some(s) = ev.signals.iter().find(|s| s.signal == signal) else {
                    continue;
                };
                let sp = &s.spectrum;
                let mut series = vec![plot::Series {
                    label: "as given".into(),
                    x: &sp.freq_hz,
                    y: &sp.amplitude,
                    color: plot::START,
                    thin: false,
                }];
                let sa = r
                    .evidence_after
                    .iter()
                    .find(|e| &e.event == event)
                    .and_then(|e| e.signals.iter().find(|x| x.signal == signal));
                if let (Some(sa), Some(cause)) = (sa, named) {
                    series.push(plot::Series {
                        label: format!("with {cause}"),
                        x: &sa.spectrum.freq_hz,
                        y: &sa.spectrum.amplitude,
                        color: plot::SIMULATED,
                        thin: true,
                    });
                }
                panels.push(plot::Panel {
                    y_label: format!("{signal} residual amplitude [pu]"),
                    series,
                });
                decor.push(plot::Decor {
                    markers: sp
                        .peak_hz
                        .map(|f| plot::Marker {
                            label: format!(
                                "peak {f:.2} Hz, {} pu ({:.1}× median)",
                                num(sp.peak_amplitude),
                                sp.peak_significance
                            ),
                            x: f,
                            y: sp.peak_amplitude,
                            color: plot::SIMULATED,
                        })
                        .into_iter()
                        .collect(),
                    ..Default::default()
                });
            }
            if !panels.is_empty() {
                let file = format!("spectrum-{stem}.svg");
                draw(
                    &file,
                    &format!("{event}: residual amplitude spectra"),
                    "frequency [Hz]",
                    &panels,
                    &decor,
                )?;
                files.push(PlotFile {
                    file,
                    event: event.clone(),
                    caption:
                        "amplitude spectra of the P and Q residuals (Hann window), the peak marked"
                            .into(),
                });
            }
        }

        // Measured against simulated, before and after the extension.
        let col = |tr: &Traces, n: &str| {
            tr.get(n)
                .map(|c| c.to_vec())
                .unwrap_or_else(|| vec![f64::NAN; tr.time_s.len()])
        };
        let (pm, qm, pb, qb) = (
            col(tr, "p_meas_pu"),
            col(tr, "q_meas_pu"),
            col(tr, "p_pu"),
            col(tr, "q_pu"),
        );
        let (pa, qa) = match tr_after {
            Some(ta) => (col(ta, "p_pu"), col(ta, "q_pu")),
            None => (vec![], vec![]),
        };
        let mut panels = vec![];
        for (signal, m, b, af) in [("P", &pm, &pb, &pa), ("Q", &qm, &qb, &qa)] {
            let mut series = vec![
                plot::Series {
                    label: "measured".into(),
                    x: t,
                    y: m,
                    color: plot::MEASURED,
                    thin: true,
                },
                plot::Series {
                    label: "unit as given".into(),
                    x: t,
                    y: b,
                    color: plot::START,
                    thin: false,
                },
            ];
            if let (Some(ta), Some(cause)) = (tr_after, named) {
                series.push(plot::Series {
                    label: format!("extended ({cause}), re-fitted"),
                    x: &ta.time_s,
                    y: af,
                    color: plot::SIMULATED,
                    thin: false,
                });
            }
            panels.push(plot::Panel {
                y_label: format!("{signal} [pu, system base]"),
                series,
            });
        }
        let file = format!("before-after-{stem}.svg");
        let title = match named {
            Some(c) => format!("{event}: measured, unit as given and extended for {c}"),
            None => format!("{event}: measured and simulated (no cause named, no extension)"),
        };
        draw(&file, &title, "time [s]", &panels, &[])?;
        files.push(PlotFile {
            file,
            event: event.clone(),
            caption: "measured and simulated P and Q, before and after the extension".into(),
        });
    }
    Ok(files)
}

/// The window to shade in the `signal` residual panel of an event: the verdict's (the same
/// labelled window of this event when it has one), otherwise the signal's window with the
/// largest share of the squared error.
fn implicated_window(
    r: &Diagnosis,
    ev: Option<&EventEvidence>,
    signal: &str,
) -> Option<plot::Span> {
    if let Some((sig, label, a, b)) = &r.verdict.where_ {
        let own = ev
            .and_then(|e| e.signals.iter().find(|s| &s.signal == sig))
            .and_then(|s| s.windows.iter().find(|w| &w.label == label))
            .map(|w| (w.start_s, w.end_s));
        let (a, b) = own.unwrap_or((*a, *b));
        return Some(plot::Span {
            label: format!("verdict's window: {sig} residual, {label}"),
            x0: a,
            x1: b,
            color: plot::HIGHLIGHT,
        });
    }
    let s = ev?.signals.iter().find(|s| s.signal == signal)?;
    let w = top_window(s)?;
    Some(plot::Span {
        label: format!("most SSE: {} ({:.0} %)", w.label, 100.0 * w.share_of_sse),
        x0: w.start_s,
        x1: w.end_s,
        color: plot::HIGHLIGHT,
    })
}

// ---------------------------------------------------------------------------------------------
// HTML report
// ---------------------------------------------------------------------------------------------

/// Escapes text for HTML element content and attribute values.
pub fn escape(s: &str) -> String {
    let mut o = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => o.push_str("&amp;"),
            '<' => o.push_str("&lt;"),
            '>' => o.push_str("&gt;"),
            '"' => o.push_str("&quot;"),
            '\'' => o.push_str("&#39;"),
            _ => o.push(c),
        }
    }
    o
}

/// An SVG file's text ready to be inlined: without an XML declaration or DOCTYPE, with a
/// viewBox so that it scales with the page.
fn inline_svg(text: &str) -> String {
    let start = text.find("<svg").unwrap_or(0);
    let mut svg = text[start..].to_string();
    let tag_end = svg.find('>').unwrap_or(0);
    if !svg[..tag_end].contains("viewBox") {
        let attr = |name: &str| -> Option<String> {
            let tag = &svg[..tag_end];
            let k = tag.find(&format!(" {name}=\""))? + name.len() + 3;
            let v = &tag[k..];
            Some(v[..v.find('"')?].to_string())
        };
        if let (Some(w), Some(h)) = (attr("width"), attr("height")) {
            svg.insert_str(
                4,
                &format!(" viewBox=\"0 0 {} {}\"", escape(&w), escape(&h)),
            );
        }
    }
    svg
}

const CSS: &str = "body{font-family:system-ui,-apple-system,'Segoe UI',Helvetica,Arial,sans-serif;max-width:1100px;margin:2em auto;\
padding:0 1em;color:#222;line-height:1.45}h1{font-size:1.6em;margin-bottom:.2em}h2{border-bottom:1px solid #ccc;padding-bottom:.2em;\
margin-top:1.8em}h3{margin-bottom:.3em}table{border-collapse:collapse;margin:.5em 0 1em;font-size:.92em}\
th,td{border:1px solid #d0d0d0;padding:.25em .55em;text-align:left;vertical-align:top}th{background:#f2f2f2}\
td.n{text-align:right;font-variant-numeric:tabular-nums;white-space:nowrap}.verdict{border:2px solid #888;border-radius:6px;\
padding:.8em 1.1em;margin:1em 0;background:#f7f7f7}.verdict.named{border-color:#2c7a2c;background:#eef8ee}\
.verdict.unexplained{border-color:#c77700;background:#fff5e6}.verdict h2{border:none;margin:.1em 0 .4em}.muted{color:#666}\
.sig{font-weight:bold;color:#2c7a2c}ul.tight{margin:.2em 0;padding-left:1.2em}figure{margin:1em 0}\
figure svg{max-width:100%;height:auto;border:1px solid #e3e3e3}figcaption{color:#555;font-size:.9em}code{font-size:.95em}";

fn html_report(
    r: &Diagnosis,
    unit_path: &Path,
    event_paths: &[PathBuf],
    out: &Path,
    plots: &[PlotFile],
) -> String {
    let e = escape;
    let mut h = String::new();
    let _ = write!(
        h,
        "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n<title>{}</title>\n<style>{CSS}</style>\n</head>\n<body>\n",
        e(&format!("Diagnosis of {} on {}", r.unit, r.events.join(", ")))
    );
    let _ = writeln!(
        h,
        "<h1>Diagnosis of {} on {}</h1>",
        e(&r.unit),
        e(&r.events.join(", "))
    );
    let _ = writeln!(
        h,
        "<p class=\"muted\">itaipu-calib {} diagnose. Unit file <code>{}</code>; event file(s) {}{}. Seed {}, {} threads, {:.1} s.</p>",
        env!("CARGO_PKG_VERSION"),
        e(&unit_path.display().to_string()),
        event_paths.iter().map(|p| format!("<code>{}</code>", e(&p.display().to_string()))).collect::<Vec<_>>().join(", "),
        if r.held_out.is_empty() { String::new() } else { format!("; held out: {}", e(&r.held_out.join(", "))) },
        r.seed,
        r.threads,
        r.wall_s
    );

    // Verdict.
    let v = &r.verdict;
    let class = match v.cause.as_str() {
        "none" => "verdict",
        "unexplained" => "verdict unexplained",
        _ => "verdict named",
    };
    let _ = writeln!(
        h,
        "<div class=\"{class}\">\n<h2>Verdict: {} — {}</h2>\n<p>{}</p>",
        e(&v.cause),
        e(&v.title),
        e(&v.statement)
    );
    if !v.key_parameters.is_empty() {
        let _ = writeln!(
            h,
            "<p>Key parameters: {}</p>",
            v.key_parameters
                .iter()
                .map(|(p, x, u)| format!("<code>{}</code> = {}", e(p), e(&with_unit(*x, u))))
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    if let Some((sig, w, a, b)) = &v.where_ {
        let _ = writeln!(
            h,
            "<p>Where the residual lives: {} in the {} window, {a:.2}–{b:.2} s.</p>",
            e(sig),
            e(w)
        );
    }
    if v.cause == "none" || v.cause == "unexplained" {
        h.push_str("<p class=\"muted\">No cause named: no extended unit was written.</p>\n");
    } else {
        h.push_str("<p class=\"muted\">The extended, re-fitted unit is in <code>extended.toml</code>.</p>\n");
    }
    h.push_str("</div>\n");

    // Candidates.
    h.push_str("<h2>Candidates</h2>\n<p>Ranked by ΔBIC = Δχ² − k ln N (fitted samples); a cause is significant when ΔBIC, the fitted and the held-out χ² drops all pass their thresholds.</p>\n");
    h.push_str("<table>\n<tr><th>#</th><th>cause</th><th>ΔBIC</th><th>fit χ² (base → ext)</th><th>fit drop</th><th>held-out χ² (base → ext)</th><th>held-out drop</th><th>k</th><th>significant</th><th>RMS P, Q (base → ext) [pu]</th></tr>\n");
    for (i, c) in r.candidates.iter().enumerate() {
        let _ = write!(
            h,
            "<tr><td class=\"n\">{}</td><td><b>{}</b><br><span class=\"muted\">{}</span></td>",
            i + 1,
            e(&c.cause),
            e(&c.title)
        );
        match &c.gains {
            Some(g) => {
                let _ = writeln!(
                    h,
                    "<td class=\"n\">{:.1}</td><td class=\"n\">{} → {}</td><td class=\"n\">{}</td><td class=\"n\">{} → {}</td><td class=\"n\">{}</td><td class=\"n\">{}</td><td>{}</td><td class=\"n\">{}, {} → {}, {}</td></tr>",
                    g.delta_bic,
                    chi2(g.chi2_fit_base),
                    chi2(g.chi2_fit_ext),
                    e(&pct(g.fit_drop)),
                    chi2(g.chi2_held_base),
                    chi2(g.chi2_held_ext),
                    e(&pct(g.held_drop)),
                    g.k,
                    if c.significant { "<span class=\"sig\">yes</span>" } else { "no" },
                    num(g.rms_p_base),
                    num(g.rms_q_base),
                    num(g.rms_p_ext),
                    num(g.rms_q_ext)
                );
            }
            None => {
                let _ = writeln!(
                    h,
                    "<td colspan=\"8\" class=\"muted\">{}</td></tr>",
                    e(&c.note)
                );
            }
        }
    }
    h.push_str("</table>\n");
    for c in r.candidates.iter().filter(|c| c.applicable) {
        let _ = writeln!(
            h,
            "<h3>{}</h3>\n<p>Extension: {}.{}</p>",
            e(&c.cause),
            e(&c.extension),
            if c.note.is_empty() {
                String::new()
            } else {
                format!(" {}", e(&c.note))
            }
        );
        if !c.parameters.is_empty() {
            h.push_str("<table>\n<tr><th>parameter</th><th>role</th><th>unit</th><th>start</th><th>bounds</th><th>result</th><th></th></tr>\n");
            for p in &c.parameters {
                let _ = writeln!(
                    h,
                    "<tr><td><code>{}</code></td><td>{}</td><td>{}</td><td class=\"n\">{}</td><td class=\"n\">{} – {}</td><td class=\"n\">{}</td><td>{}</td></tr>",
                    e(&p.param),
                    if p.extension { "extension" } else { "interacting" },
                    e(&p.unit),
                    num(p.start),
                    num(p.min),
                    num(p.max),
                    num(p.result),
                    if p.at_bound { "at bound" } else { "" }
                );
            }
            h.push_str("</table>\n");
        }
        if !c.fixed.is_empty() {
            let _ = writeln!(
                h,
                "<p>Fixed: {}</p>",
                c.fixed
                    .iter()
                    .map(|(p, x)| format!("<code>{}</code> = {x}", e(p)))
                    .collect::<Vec<_>>()
                    .join(", ")
            );
        }
        if !c.signature.is_empty() {
            let _ = writeln!(
                h,
                "<p>Evidence pointing to it:</p>\n<ul class=\"tight\">{}</ul>",
                c.signature
                    .iter()
                    .map(|s| format!("<li>{}</li>", e(s)))
                    .collect::<String>()
            );
        }
        let _ = writeln!(
            h,
            "<p class=\"muted\">{} simulations, {} failed candidates, {:.1} s.</p>",
            c.simulations, c.failed_candidates, c.wall_s
        );
    }

    // Noise and split.
    let n = &r.noise;
    let _ = writeln!(
        h,
        "<h2>Noise model and split</h2>\n<table>\n<tr><th>σ<sub>P</sub> [pu]</th><th>σ<sub>Q</sub> [pu]</th><th>split</th><th>fitted samples</th><th>held-out samples</th></tr>\n<tr><td class=\"n\">{}</td><td class=\"n\">{}</td><td>{}</td><td class=\"n\">{}</td><td class=\"n\">{}</td></tr>\n</table>\n<p class=\"muted\">σ from the pre-event segment of the residuals; χ² = Σ(ΔP/σ<sub>P</sub>)² + Σ(ΔQ/σ<sub>Q</sub>)².</p>",
        num(n.sigma_p),
        num(n.sigma_q),
        e(&n.split),
        n.n_fit,
        n.n_held
    );

    // Evidence.
    h.push_str(
        "<h2>Evidence</h2>\n<p>Residuals r = simulated − measured of the unit as given.</p>\n",
    );
    for ev in &r.evidence {
        let _ = writeln!(
            h,
            "<h3>{} (event onset {:.2} s)</h3>",
            e(&ev.event),
            ev.onset_s
        );
        h.push_str("<table>\n<tr><th>signal</th><th>samples</th><th>bias</th><th>RMS</th><th>noise floor</th><th>RMS/noise</th><th>Ljung-Box Q (lags)</th><th>p</th><th>white</th><th>ACF lags outside band</th><th>spectral peak</th></tr>\n");
        for s in &ev.signals {
            let w = &s.whiteness;
            let _ = writeln!(
                h,
                "<tr><td><b>{}</b></td><td class=\"n\">{}</td><td class=\"n\">{}</td><td class=\"n\">{}</td><td class=\"n\">{}</td><td class=\"n\">{:.2}</td><td class=\"n\">{:.1} ({})</td><td class=\"n\">{:.3}</td><td>{}</td><td class=\"n\">{}</td><td class=\"n\">{}</td></tr>",
                e(&s.signal),
                s.samples,
                num(s.bias),
                num(s.rms),
                num(s.noise_floor_rms),
                s.rms_over_noise,
                w.ljung_box_q,
                w.lags,
                w.p_value,
                if w.white { "yes" } else { "no" },
                w.outside_band,
                s.spectrum.peak_hz.map(|f| format!("{f:.2} Hz, {} pu", num(s.spectrum.peak_amplitude))).unwrap_or_else(|| "-".into())
            );
        }
        h.push_str("</table>\n");
        for s in &ev.signals {
            let _ = writeln!(
                h,
                "<p><b>{}</b> residual by window, cross-correlation with the inputs, modes:</p>",
                e(&s.signal)
            );
            h.push_str("<table>\n<tr><th>window</th><th>start [s]</th><th>end [s]</th><th>samples</th><th>bias</th><th>RMS</th><th>share of SSE</th></tr>\n");
            for w in &s.windows {
                let _ = writeln!(
                    h,
                    "<tr><td>{}</td><td class=\"n\">{:.2}</td><td class=\"n\">{:.2}</td><td class=\"n\">{}</td><td class=\"n\">{}</td><td class=\"n\">{}</td><td class=\"n\">{}</td></tr>",
                    e(&w.label),
                    w.start_s,
                    w.end_s,
                    w.samples,
                    num(w.bias),
                    num(w.rms),
                    e(&pct(w.share_of_sse))
                );
            }
            h.push_str("</table>\n");
            if !s.cross.is_empty() {
                h.push_str("<table>\n<tr><th>input</th><th>best lag [samples]</th><th>correlation</th><th>band</th><th>significant</th></tr>\n");
                for x in &s.cross {
                    let _ = writeln!(
                        h,
                        "<tr><td>{}</td><td class=\"n\">{}</td><td class=\"n\">{:+.3}</td><td class=\"n\">{:.3}</td><td>{}</td></tr>",
                        e(&x.input),
                        x.best_lag_samples,
                        x.correlation,
                        x.band,
                        if x.significant { "yes" } else { "no" }
                    );
                }
                h.push_str("</table>\n");
            }
            if s.modes.is_empty() {
                h.push_str("<p class=\"muted\">No modes fitted.</p>\n");
            } else {
                h.push_str("<table>\n<tr><th>frequency [Hz]</th><th>damping ratio</th><th>amplitude</th><th>energy share</th></tr>\n");
                for m in &s.modes {
                    let _ = writeln!(
                        h,
                        "<tr><td class=\"n\">{:.3}</td><td class=\"n\">{:.3}</td><td class=\"n\">{}</td><td class=\"n\">{}</td></tr>",
                        m.freq_hz,
                        m.damping_ratio,
                        num(m.amplitude),
                        e(&pct(m.energy_share))
                    );
                }
                h.push_str("</table>\n");
            }
        }
    }
    if !r.evidence_after.is_empty() {
        let _ = writeln!(h, "<h3>With the extension ({})</h3>", e(&v.cause));
        h.push_str("<table>\n<tr><th>event</th><th>signal</th><th>RMS</th><th>RMS/noise</th><th>Ljung-Box p</th><th>window with most SSE</th></tr>\n");
        for ev in &r.evidence_after {
            for s in &ev.signals {
                let w = top_window(s)
                    .map(|w| format!("{} ({})", w.label, pct(w.share_of_sse)))
                    .unwrap_or_default();
                let _ = writeln!(
                    h,
                    "<tr><td>{}</td><td>{}</td><td class=\"n\">{}</td><td class=\"n\">{:.2}</td><td class=\"n\">{:.3}</td><td>{}</td></tr>",
                    e(&ev.event),
                    e(&s.signal),
                    num(s.rms),
                    s.rms_over_noise,
                    s.whiteness.p_value,
                    e(&w)
                );
            }
        }
        h.push_str("</table>\n");
    }

    // Plots, inlined.
    if !plots.is_empty() {
        h.push_str("<h2>Plots</h2>\n");
        for p in plots {
            match std::fs::read_to_string(out.join(&p.file)) {
                Ok(svg) => {
                    let _ = writeln!(h, "<figure>\n{}\n<figcaption>{}: {} (<code>{}</code>)</figcaption>\n</figure>", inline_svg(&svg), e(&p.event), e(&p.caption), e(&p.file));
                }
                Err(err) => {
                    let _ = writeln!(
                        h,
                        "<p class=\"muted\">{} could not be read: {}</p>",
                        e(&p.file),
                        e(&err.to_string())
                    );
                }
            }
        }
    } else {
        h.push_str("<p class=\"muted\">Plots not drawn (--no-plot).</p>\n");
    }
    h.push_str("</body>\n</html>\n");
    h
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn escape_covers_markup_and_quotes() {
        assert_eq!(
            escape("a<b & \"c\" 'd'>"),
            "a&lt;b &amp; &quot;c&quot; &#39;d&#39;&gt;"
        );
        assert_eq!(escape("Δχ² ζ"), "Δχ² ζ");
    }

    #[test]
    fn inline_svg_drops_the_declaration_and_adds_a_viewbox() {
        let s = inline_svg("<?xml version=\"1.0\"?>\n<svg width=\"1000\" height=\"580\" xmlns=\"http://www.w3.org/2000/svg\"><g/></svg>");
        assert!(
            s.starts_with("<svg viewBox=\"0 0 1000 580\" width=\"1000\""),
            "{s}"
        );
        let kept = inline_svg("<svg viewBox=\"0 0 1 1\" width=\"5\" height=\"5\"></svg>");
        assert_eq!(kept.matches("viewBox").count(), 1);
    }

    #[test]
    fn wrap_keeps_lines_within_the_width() {
        let text = "word ".repeat(60);
        let w = wrap(&text, 40, "head     ", "         ");
        assert!(w.lines().count() > 5);
        for l in w.lines() {
            assert!(l.chars().count() <= 40, "{l}");
            assert!(l.starts_with("head") || l.starts_with("         "));
        }
    }

    #[test]
    fn causes_are_checked_and_deduplicated() {
        let ok = causes(
            &[
                "saturation".into(),
                "measurement_skew".into(),
                "saturation".into(),
            ],
            &[],
        )
        .unwrap();
        assert_eq!(ok, ["saturation", "measurement_skew"]);
        let e = causes(&["saturation".into(), "gremlins".into()], &[]).unwrap_err();
        assert_eq!(e.code, 2);
        assert!(
            e.msg.contains("gremlins") && e.msg.contains("measurement_skew"),
            "{}",
            e.msg
        );
    }

    #[test]
    fn refit_requests_parse_names_and_ranges_and_name_bad_ones() {
        let ok = refit_requests(&["machine.h".into(), " exciter.k = 50 : 200 ".into()]).unwrap();
        assert_eq!(
            ok,
            [
                ("machine.h".to_string(), None),
                ("exciter.k".to_string(), Some((50.0, 200.0)))
            ]
        );
        for bad in ["exciter.k=50", "exciter.k=a:2", "exciter.k=1:NaN", ""] {
            let e = refit_requests(&[bad.into()]).unwrap_err();
            assert_eq!(e.code, 2, "{bad}");
            assert!(e.msg.contains("--refit"), "{}", e.msg);
        }
    }

    #[test]
    fn wrap_items_breaks_between_items_only() {
        let items = [
            "machine.s10 = 0.1184",
            "machine.s12 = 0.4004",
            "x.y = 1.0000 s",
        ];
        let w = wrap_items(&items, ", ", 30, "  head  ", "        ");
        assert_eq!(
            w,
            "  head  machine.s10 = 0.1184,\n        machine.s12 = 0.4004,\n        x.y = 1.0000 s"
        );
        assert_eq!(with_unit(0.012, "s"), "0.0120 s");
        assert_eq!(with_unit(0.005, "s"), "5.000e-3 s");
        assert_eq!(with_unit(0.5, "-"), "0.5000");
    }

    #[test]
    fn a_long_item_is_broken_between_words() {
        let w = wrap_items(
            &["short", "a much longer item that does not fit"],
            ", ",
            20,
            "hd ",
            "   ",
        );
        assert_eq!(
            w,
            "hd short,\n   a much longer\n   item that does\n   not fit"
        );
        for l in w.lines() {
            assert!(l.chars().count() <= 20, "{l}");
        }
    }

    #[test]
    fn file_stems_are_safe() {
        assert_eq!(file_stem("itaipu-60hz-fault"), "itaipu-60hz-fault");
        assert_eq!(file_stem("a/b c"), "a_b_c");
        assert_eq!(file_stem(""), "event");
    }
}
