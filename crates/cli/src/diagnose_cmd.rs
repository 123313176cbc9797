//! `itaipu-calib diagnose`: what a (calibrated) unit still gets wrong on measured events, which
//! cause of the catalog explains it, the extended and re-fitted unit, evidence plots and an HTML
//! report.

use std::path::PathBuf;

use itaipu_calib::diagnose::{catalog, CandidateReport, Diagnosis, RefitRequest};
use itaipu_calib::evidence::SignalEvidence;
use itaipu_calib::job;
use itaipu_calib::options::{cli_help, Command::Diagnose};
use itaipu_calib::request::{parse_refit, DiagnoseRequest};

use crate::fit_cmd::{Detail, Reporter};
use crate::report::diagnose::{plausible, top_window};
use crate::report::diagnose_plots::draw_plots;
use crate::report::{self, num, pct, InputFile, Provenance};
use crate::{bundled, load_event, load_unit, prepare_out, CliError, SearchArgs, EXIT_CODES};

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
    #[arg(long, value_name = "ID", num_args = 1.., value_delimiter = ',', help = cli_help(Diagnose, "causes"))]
    cause: Vec<String>,
    #[arg(long, value_name = "FILE", help = cli_help(Diagnose, "user_causes"))]
    user_cause: Vec<PathBuf>,
    #[arg(long, value_name = "PARAM[=MIN:MAX]", num_args = 1.., value_delimiter = ',', help = cli_help(Diagnose, "refit"))]
    refit: Vec<String>,
    /// Output folder (diagnosis.json, extended.toml, plots, report.html). Default:
    /// out/diagnose-<first event>, or a new numbered folder beside it. An existing --out folder
    /// is never overwritten unless --force is given.
    #[arg(long, value_name = "DIR")]
    out: Option<PathBuf>,
    /// Allow writing into an existing, non-empty --out folder.
    #[arg(long)]
    force: bool,
    #[arg(long, value_parser = crate::simulate_cmd::mode_parser(), help = cli_help(Diagnose, "mode"))]
    mode: Option<itaipu_dynamics::mode::PlaybackMode>,
    #[arg(long, help = cli_help(Diagnose, "look_alikes"))]
    no_look_alikes: bool,
    #[command(flatten)]
    search: SearchArgs,
    /// Do not draw the plots (report.html is written without them).
    #[arg(long)]
    no_plot: bool,
}

/// Terminal width the tables are laid out for.
const WIDTH: usize = 100;

/// The `--refit` requests ([`parse_refit`]: `PARAM` or `PARAM=MIN:MAX`, a usage error naming the
/// request otherwise).
fn refit_requests(requested: &[String]) -> Result<Vec<RefitRequest>, CliError> {
    Ok(requested
        .iter()
        .map(|r| parse_refit(r))
        .collect::<Result<_, _>>()?)
}

/// The user causes' files, for the provenance.
fn user_cause_inputs(paths: &[PathBuf]) -> Vec<InputFile> {
    paths
        .iter()
        .map(|p| InputFile::new("user cause", p))
        .collect()
}

pub fn cmd_diagnose(a: &DiagnoseArgs) -> Result<(), CliError> {
    // Usage errors first, then the input files, then the output folder, then the (long) run.
    let request = DiagnoseRequest {
        mode: a.mode,
        causes: a.cause.clone(),
        user_causes: a.user_cause.clone(),
        refit: refit_requests(&a.refit)?,
        search: a.search.request(),
        look_alikes: a.no_look_alikes.then_some(false),
    };
    let pool = a.search.pool()?;
    let threads = pool.current_num_threads();
    let (unit_path, unit, calibrated_set, fit_files) = match (&a.unit, &a.fit) {
        (Some(p), _) => (p.clone(), load_unit(p)?, vec![], vec![]),
        (None, Some(dir)) => {
            let f = job::read_fit_folder(dir)?;
            (f.unit_path, f.unit, f.calibrated_set, f.files)
        }
        (None, None) => {
            let p = bundled("itaipu/unit.toml")?;
            let u = load_unit(&p)?;
            (p, u, vec![], vec![])
        }
    };
    let event_paths = if a.event.is_empty() {
        vec![bundled("itaipu/event.toml")?]
    } else {
        a.event.clone()
    };
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
    // The output folder: checked before the inputs are played back, started before the run.
    crate::check_out(a.out.as_deref(), a.force)?;
    let (opts, warnings) = job::prepare_diagnose(
        &unit,
        Some(&unit_path),
        &events,
        &held_out,
        &request,
        &calibrated_set,
    )?;
    for w in &warnings {
        eprintln!("warning: {w}");
    }
    let staging = prepare_out(a.out.as_deref(), &format!("diagnose-{name}"), a.force)?;
    let tried = if opts.causes.is_empty() {
        format!(
            "all {} causes (and the look-alikes outside the catalog if one is significant)",
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
    let reporter = Reporter::new(Detail::Summary, None);
    let result =
        pool.install(|| job::run_diagnose(&unit, &events, &held_out, &opts, warnings, &reporter));
    reporter.finish();
    let run = result?;
    let report = &run.report;

    let out = staging.path().to_path_buf();
    let mut written: Vec<String> = job::write_diagnosis_files(&out, &run)?
        .into_iter()
        .map(String::from)
        .collect();
    let extended_note = run.extended_unit.is_none().then(|| {
        format!(
            "no cause named ({}): extended.toml not written",
            report.verdict.cause
        )
    });
    let plots = if a.no_plot {
        vec![]
    } else {
        let hz: Vec<(String, f64)> = events
            .iter()
            .chain(&held_out)
            .map(|e| (e.name.clone(), e.nominal_hz))
            .collect();
        draw_plots(&out, &hz, report, &run.before, &run.after)?
    };
    written.extend(plots.iter().map(|p| p.file.clone()));
    let mut inputs = vec![InputFile::new("unit", &unit_path)];
    for (what, p) in &fit_files {
        inputs.push(InputFile::new(what, p));
    }
    inputs.extend(user_cause_inputs(&a.user_cause));
    for e in &events {
        inputs.extend(InputFile::event(e, false));
    }
    for e in &held_out {
        inputs.extend(InputFile::event(e, true));
    }
    let prov = Provenance::new(inputs, opts.seed);
    crate::output::write_synced(
        &out.join("report.html"),
        report::diagnose::html(report, &prov, &plots, !a.no_plot).as_bytes(),
    )?;
    written.push("report.html".into());

    print_report(report);
    if let Some(n) = extended_note {
        println!("{n}");
    }
    let target = crate::output::commit(staging, Some(opts.seed))?;
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

/// The oscillatory mode (above 0.1 Hz) with the largest energy share, as text.
fn dominant_mode(s: &SignalEvidence) -> String {
    s.modes
        .iter()
        .filter(|m| plausible(m))
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
    println!(
        "{}",
        wrap(&r.headline.sentence, WIDTH, "headline ", "         ")
    );
    let noise = format!(
        "playback {}; {} (pre-event residual of the unit as given); split: {} ({} fitted, {} held-out samples)",
        r.noise.playback,
        r.noise
            .sigmas
            .iter()
            .map(|(s, v)| format!("σ{s} {} pu", num(*v)))
            .collect::<Vec<_>>()
            .join(", "),
        r.noise.split,
        r.noise.n_fit,
        r.noise.n_held
    );
    println!("{}", wrap(&noise, WIDTH, "noise    ", "         "));
    if let Some(reference) = &r.reference {
        println!(
            "{}",
            wrap(&reference.sentence, WIDTH, "reference ", "         ")
        );
    }
    println!();
    println!(
        "candidates (* = significant, ranked by the extended model's BIC; the others by ΔBIC; ! = passed the test, refused by a rule in its note; ~ = a look-alike outside the catalog, never named)"
    );
    println!(
        "  {:<18} {:>9} {:>9} {:>9} {:>9} {:>2} {:1}  key parameters / note",
        "cause", "ΔBIC", "2 ln B", "fit χ²↓", "held χ²↓", "k", ""
    );
    let indent = " ".repeat(2 + 18 + 1 + 9 + 1 + 9 + 1 + 9 + 1 + 9 + 1 + 2 + 1 + 1 + 2);
    for c in &r.candidates {
        let cause = if c.look_alike {
            format!("~{}", c.cause)
        } else {
            c.cause.clone()
        };
        let head = match &c.gains {
            Some(g) => format!(
                "  {:<18} {:>9.1} {:>9.1} {:>9} {:>9} {:>2} {:1}  ",
                cause,
                g.delta_bic,
                g.record_evidence,
                pct(g.fit_drop),
                pct(g.held_drop),
                g.k,
                if c.significant {
                    "*"
                } else if c.passed_test {
                    "!"
                } else {
                    ""
                }
            ),
            None => format!(
                "  {:<18} {:>9} {:>9} {:>9} {:>9} {:>2} {:1}  ",
                cause, "-", "-", "-", "-", "-", ""
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
        "{}",
        wrap(
            &itaipu_calib::diagnose::profile_summary(&r.profile),
            WIDTH,
            "time     ",
            "         "
        )
    );
    println!(
        "total {:.1} s on {} threads, seed {}",
        r.wall_s, r.threads, r.seed
    );
}

#[cfg(test)]
mod tests {
    use super::*;

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
}
