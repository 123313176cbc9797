//! The `fit` report (`report.html`): provenance, the events, the verdict, the parameter table
//! of every stage (start, bounds, result, standard error, flags), the stage table (objective
//! and J per event from the start through every stage), and per event the measured against
//! start and calibrated P, Q and every other measured channel, and the residuals with the
//! noise band.
//!
//! It is built from `report.json` as written (a `serde_json::Value`), so that the page and the
//! file cannot disagree: every number carries the JSON pointer it was read from.

use serde_json::Value;

use super::svg as plot;
use super::{escape, num, other_channels, residual, token, Cell, Page, Provenance, Tone};
use itaipu_dynamics::simulate::Traces;

/// The traces of one event for the plots: the unit as given and the calibrated unit.
pub struct EventTraces<'a> {
    pub event: &'a str,
    pub held_out: bool,
    pub nominal_hz: f64,
    pub start: &'a Traces,
    pub calibrated: &'a Traces,
}

fn f(v: &Value) -> f64 {
    v.as_f64().unwrap_or(f64::NAN)
}

fn s(v: &Value) -> &str {
    v.as_str().unwrap_or("")
}

/// A number of the report at `pointer` (`-` when absent, "not determined" when null).
fn cell(report: &Value, pointer: &str, fmt: fn(f64) -> String) -> Cell {
    match report.pointer(pointer) {
        Some(Value::Number(n)) => Cell::json(n.as_f64().unwrap_or(f64::NAN), pointer, fmt),
        Some(Value::Null) => Cell::text("not determined"),
        _ => Cell::text("-"),
    }
}

/// The noise standard deviations `(σP, σQ)` of an event in `report["noise"]`.
fn noise_of(report: &Value, event: &str) -> Option<(usize, f64, f64)> {
    report["noise"]
        .as_array()?
        .iter()
        .enumerate()
        .find(|(_, n)| s(&n["event"]) == event)
        .map(|(k, n)| (k, f(&n["sigma_p"]), f(&n["sigma_q"])))
}

/// The headline's worst RMS/σ (`report.json` `headline.worst`, the library's one number; NaN
/// when the noise could not be measured).
pub fn worst_ratio(report: &Value) -> f64 {
    f(&report["headline"]["worst"])
}

/// The headline sentence with its number marked up (JSON pointer `/headline/worst`).
pub fn headline_html(report: &Value, pointer: &str) -> String {
    let h: Option<itaipu_calib::noise::Headline> =
        serde_json::from_value(report.pointer(pointer).cloned().unwrap_or(Value::Null)).ok();
    match h {
        Some(h) => super::headline_html(&h, &format!("{pointer}/worst")),
        None => "<p>No headline in the report.</p>\n".into(),
    }
}

/// What a phasor stage compares, from its objective and weights (`P, Q`, `Q`).
fn objective_channels(st: &Value) -> String {
    let (wp, wq) = (f(&st["weights"]["p"]), f(&st["weights"]["q"]));
    match s(&st["objective"]) {
        "p" => "P".into(),
        "q" => "Q".into(),
        _ if wp.is_finite() && wq.is_finite() && (wp != 1.0 || wq != 1.0) => {
            format!("P (weight {wp}), Q (weight {wq})")
        }
        _ => "P, Q".into(),
    }
}

/// Every flag the stages raise: parameters at a bound, not determined, pairs not separately
/// identifiable.
pub fn flags(report: &Value) -> Vec<String> {
    let mut out = vec![];
    for st in report["stages"].as_array().into_iter().flatten() {
        let stage = s(&st["stage"]);
        for p in st["parameters"].as_array().into_iter().flatten() {
            if p["at_bound"].as_bool() == Some(true) {
                out.push(format!("{stage}: {} at a bound", s(&p["param"])));
            }
        }
        for u in st["not_determined"].as_array().into_iter().flatten() {
            out.push(format!("{stage}: {} not determined by the data", s(u)));
        }
        for pair in st["correlated_pairs"].as_array().into_iter().flatten() {
            out.push(format!(
                "{stage}: {} and {} not separately identifiable (ρ = {:+.3})",
                s(&pair[0]),
                s(&pair[1]),
                f(&pair[2])
            ));
        }
    }
    out
}

fn fmt4(v: f64) -> String {
    format!("{v:.4}")
}

/// The fit as a page. `plots` false: `--no-plot`, figures left out.
pub fn html(report: &Value, prov: &Provenance, traces: &[EventTraces], plots: bool) -> String {
    let e = escape;
    let events: Vec<&str> = report["events"]
        .as_array()
        .into_iter()
        .flatten()
        .map(s)
        .collect();
    let mut page = Page::new(&format!(
        "Model validation: calibration of {} on {}",
        s(&report["unit"]),
        events.join(", ")
    ));
    page.note(&format!(
        "itaipu-calib fit, strategy {}: staged calibration of the unit's parameters on the recorded events. {} threads, {:.1} s.",
        s(&report["strategy"]),
        report["threads"],
        f(&report["wall_s"])
    ));
    page.provenance(prov);

    // Events and noise: every compared channel's σ (the library's one definition).
    page.h2("events", "Events");
    let signals: Vec<String> = report["noise"]
        .as_array()
        .into_iter()
        .flatten()
        .flat_map(|n| n["channels"].as_array().into_iter().flatten())
        .map(|c| s(&c["signal"]).to_string())
        .fold(vec![], |mut v, x| {
            if !v.contains(&x) {
                v.push(x);
            }
            v
        });
    let rows: Vec<Vec<Cell>> = report["noise"]
        .as_array()
        .into_iter()
        .flatten()
        .enumerate()
        .map(|(k, n)| {
            let mut row = vec![
                Cell::text(s(&n["event"])),
                Cell::text(if n["held_out"].as_bool() == Some(true) {
                    "held out"
                } else {
                    "fitted"
                }),
                Cell::Num(n["samples"].as_u64().map_or("-".into(), |x| x.to_string())),
            ];
            for sig in &signals {
                let j = n["channels"]
                    .as_array()
                    .and_then(|a| a.iter().position(|c| s(&c["signal"]) == sig));
                row.push(match j {
                    Some(j) => cell(report, &format!("/noise/{k}/channels/{j}/floor/sigma"), num),
                    None => Cell::text(n["error"].as_str().map_or("-", |_| "not played back")),
                });
            }
            row
        })
        .collect();
    let mut head: Vec<String> = vec!["event".into(), "role".into(), "samples (fit window)".into()];
    head.extend(signals.iter().map(|sig| format!("noise σ {sig} [pu]")));
    let head: Vec<&str> = head.iter().map(String::as_str).collect();
    page.table("event-table", &head, &rows);
    page.note(&format!(
        "Noise: {} ({}).",
        itaipu_calib::noise::NOISE_DEFINITION,
        s(&report["headline"]["playback"])
    ));
    // What the events declare beyond their samples (report.json event_notes): channels without
    // an angle, a non-uniform time base kept as recorded, set-point steps.
    if let Some(notes) = report["event_notes"].as_object() {
        for (event, list) in notes {
            for n in list
                .as_array()
                .into_iter()
                .flatten()
                .filter_map(|n| n.as_str())
            {
                page.note(&format!("{event}: {n}"));
            }
        }
    }

    // Verdict.
    let worst = worst_ratio(report);
    let flagged = flags(report);
    let tone = if worst.is_nan() {
        Tone::Caution
    } else {
        Tone::judge(worst, !flagged.is_empty(), false)
    };
    let mut body = headline_html(report, "/headline");
    body.push_str(&format!(
        "<p class=\"muted\">Green needs at most {:.1} and no parameter flagged; above {:.1} it is red.</p>\n",
        super::AT_NOISE,
        super::FAR_ABOVE_NOISE
    ));
    if flagged.is_empty() {
        body.push_str("<p>No parameter at a bound, undetermined or confounded with another.</p>\n");
    } else {
        body.push_str(&format!(
            "<p>Flagged:</p>\n<ul class=\"tight\">{}</ul>\n",
            flagged
                .iter()
                .map(|x| format!("<li>{}</li>", e(x)))
                .collect::<String>()
        ));
    }
    let heading = match tone {
        Tone::Good => "Verdict: the calibrated unit reproduces the record to the noise floor",
        Tone::Caution => "Verdict: acceptable with reservations (see below)",
        Tone::Bad => "Verdict: the calibrated unit does not reproduce the record",
    };
    page.verdict(tone, heading, &body);

    // Stage table: objective and J per event.
    page.h2("stages", "Stages");
    let stages: Vec<&Value> = report["stages"].as_array().into_iter().flatten().collect();
    let fit_events: Vec<&Value> = report["start_fitness"]
        .as_array()
        .into_iter()
        .flatten()
        .collect();
    let mut head: Vec<String> = vec![
        "stage".into(),
        "compares".into(),
        "before".into(),
        "after".into(),
        "prior term after".into(),
        "simulations".into(),
        "failed".into(),
        "wall [s]".into(),
    ];
    // A fit with playback modes: one J column per event and mode (each mode's J in its own
    // channels), never numbers of different modes in one column. Otherwise the P+Q J.
    let modes: Vec<String> = fit_events
        .first()
        .and_then(|ev| ev["modes"].as_array())
        .into_iter()
        .flatten()
        .map(|m| s(&m["mode"]).to_string())
        .collect();
    // (column heading, pointer below a fitness row).
    let mut columns: Vec<(String, String, usize)> = vec![];
    for (k, ev) in fit_events.iter().enumerate() {
        let held = if ev["held_out"].as_bool() == Some(true) {
            " (held out)"
        } else {
            ""
        };
        if modes.is_empty() {
            columns.push((format!("J {}{held}", s(&ev["event"])), "j_pq".into(), k));
        } else {
            for (m, mode) in modes.iter().enumerate() {
                let channels: Vec<String> = ev["modes"][m]["channels"]
                    .as_array()
                    .into_iter()
                    .flatten()
                    .filter(|c| f(&c["weight"]) > 0.0)
                    .map(|c| s(&c["channel"]).to_string())
                    .collect();
                columns.push((
                    format!(
                        "J {}{held} {mode} ({})",
                        s(&ev["event"]),
                        channels.join(", ")
                    ),
                    format!("modes/{m}/j"),
                    k,
                ));
            }
        }
    }
    head.extend(columns.iter().map(|c| c.0.clone()));
    let mut rows = vec![];
    let mut start_row = vec![Cell::text("start (unit as given)")];
    start_row.extend((0..7).map(|_| Cell::text("")));
    for (_, field, k) in &columns {
        start_row.push(cell(report, &format!("/start_fitness/{k}/{field}"), fmt4));
    }
    rows.push(start_row);
    for (i, st) in stages.iter().enumerate() {
        let p = |x: &str| format!("/stages/{i}/{x}");
        let compares = match st["compare"].as_str() {
            Some(c) => c.to_string(),
            None => format!("phasor: {}", objective_channels(st)),
        };
        let mut row = vec![
            Cell::text(s(&st["stage"])),
            Cell::text(compares),
            cell(report, &p("objective_before"), num),
            cell(report, &p("objective_after"), num),
            cell(report, &p("prior_after"), num),
            Cell::Num(st["simulations"].to_string()),
            Cell::Num(st["failed_candidates"].to_string()),
            cell(report, &p("wall_s"), |v| format!("{v:.1}")),
        ];
        for (_, field, k) in &columns {
            let ev = fit_events[*k];
            // The stage's fitness row of the same event (same order as start_fitness).
            let j = st["fitness"]
                .as_array()
                .and_then(|a| a.iter().position(|x| x["event"] == ev["event"]))
                .unwrap_or(*k);
            row.push(cell(report, &p(&format!("fitness/{j}/{field}")), fmt4));
        }
        rows.push(row);
    }
    let head_ref: Vec<&str> = head.iter().map(String::as_str).collect();
    page.table("stage-table", &head_ref, &rows);
    page.note(if modes.is_empty() {
        "J = Σ(ΔP² + ΔQ²) over the event's fit window (system base), the same number in every row and in report.json; a stage's objective is its weighted sum of squares plus the datasheet prior's term."
    } else {
        "J per playback mode = Σ over the channels that mode compares (weighted as in the fit) of Σ Δ² over the event's fit window (pu), each column one mode; a stage's objective (before, after) is its own mode's weighted sum of squares plus the datasheet prior's term."
    });

    // Parameters per stage.
    page.h2("parameters", "Parameters");
    for (i, st) in stages.iter().enumerate() {
        page.h3(&format!("Stage {}", s(&st["stage"])));
        let sp = |x: &str| format!("/stages/{i}/statistics/{x}");
        page.table(
            &format!("stats-{}", token(s(&st["stage"]))),
            &[
                "data points",
                "free parameters",
                "χ²",
                "reduced χ²",
                "AIC",
                "BIC",
            ],
            &[vec![
                cell(report, &sp("n_data"), |v| format!("{v:.0}")),
                cell(report, &sp("n_free"), |v| format!("{v:.0}")),
                cell(report, &sp("chi2"), num),
                cell(report, &sp("reduced_chi2"), fmt4),
                cell(report, &sp("aic"), |v| format!("{v:.1}")),
                cell(report, &sp("bic"), |v| format!("{v:.1}")),
            ]],
        );
        let rows: Vec<Vec<Cell>> = st["parameters"]
            .as_array()
            .into_iter()
            .flatten()
            .enumerate()
            .map(|(j, p)| {
                let ptr = |x: &str| format!("/stages/{i}/parameters/{j}/{x}");
                let name = s(&p["param"]);
                // The library's flag (determined / weak / not determined), as the text report.
                let mut fl = vec![s(&p["determination"]).replace('_', " ")];
                if p["at_bound"].as_bool() == Some(true) {
                    fl.push("at bound".into());
                }
                vec![
                    Cell::Html(format!("<code>{}</code>", e(name))),
                    Cell::text(s(&p["unit"])),
                    cell(report, &ptr("result"), num),
                    cell(report, &ptr("std_error"), num),
                    match report.pointer(&ptr("relative_error")) {
                        Some(Value::Number(n)) => {
                            Cell::json_pct(n.as_f64().unwrap_or(f64::NAN), ptr("relative_error"))
                        }
                        _ => Cell::text("-"),
                    },
                    Cell::Html(format!("<span class=\"flag\">{}</span>", e(&fl.join(", ")))),
                    cell(report, &ptr("start"), num),
                    cell(report, &ptr("min"), num),
                    cell(report, &ptr("max"), num),
                ]
            })
            .collect();
        page.table(
            &format!("params-{}", token(s(&st["stage"]))),
            &[
                "parameter",
                "unit",
                "value",
                "std error",
                "rel. error [%]",
                "flag",
                "start",
                "min",
                "max",
            ],
            &rows,
        );
        let corr: Vec<String> = st["correlations"]
            .as_array()
            .into_iter()
            .flatten()
            .map(|pair| format!("C({}, {}) = {:+.3}", s(&pair[0]), s(&pair[1]), f(&pair[2])))
            .collect();
        if !corr.is_empty() {
            page.note(&format!(
                "Correlations above {} (at {} or more not separately identifiable): {}.",
                itaipu_calib::fit::CORRELATION_REPORT,
                itaipu_calib::fit::CORRELATION_LIMIT,
                corr.join("; ")
            ));
        }
    }
    page.note(&format!(
        "Standard errors from the Fisher approximation at the optimum. Determined: relative standard error at most {:.0} %; weak: up to {:.0} %; not determined: above, infinite (the data do not move the residuals along it) or at a bound. χ² in units of each event's measured noise (the noise table); AIC and BIC as lmfit reports them.",
        100.0 * itaipu_calib::fit::DETERMINED_LIMIT,
        100.0 * itaipu_calib::fit::NOT_DETERMINED_LIMIT
    ));

    // Plots.
    page.h2("plots", "Measured and simulated");
    if !plots {
        page.note("Plots not drawn (--no-plot).");
        return page.finish();
    }
    for tr in traces {
        match event_figure(report, tr) {
            Ok(svg) => page.figure(
                &svg,
                &format!(
                    "{}{}: measured, start and calibrated P and Q and every other measured channel; residuals of the calibrated unit with the ±σ noise band",
                    tr.event,
                    if tr.held_out { " (held out)" } else { "" }
                ),
            ),
            Err(err) => page.note(&format!("{}: plot failed: {err}", tr.event)),
        }
    }
    page.finish()
}

/// The figure of one event: P, Q and the other measured channels, then the P and Q residuals
/// with the noise band.
fn event_figure(report: &Value, tr: &EventTraces) -> Result<String, String> {
    let (st, ca) = (tr.start, tr.calibrated);
    let col = |t: &Traces, n: &str| {
        t.get(n)
            .map(|c| c.to_vec())
            .unwrap_or_else(|| vec![f64::NAN; t.time_s.len()])
    };
    let (pm, qm, ps, qs, pc, qc) = (
        col(ca, "p_meas_pu"),
        col(ca, "q_meas_pu"),
        col(st, "p_pu"),
        col(st, "q_pu"),
        col(ca, "p_pu"),
        col(ca, "q_pu"),
    );
    let (rp, rq) = (
        residual(ca, "p_pu", "p_meas_pu"),
        residual(ca, "q_pu", "q_meas_pu"),
    );
    let t = &ca.time_s;
    let series = |label: &str, y, color, thin| plot::Series {
        label: label.into(),
        x: t,
        y,
        color,
        thin,
    };
    let mut panels = vec![];
    for (sig, m, a, b) in [("P", &pm, &ps, &pc), ("Q", &qm, &qs, &qc)] {
        panels.push(plot::start_end_panel(
            t,
            format!("{sig} [pu, system base]"),
            "measured",
            m,
            a,
            b,
        ));
    }
    let start_channels = other_channels(st, tr.nominal_hz);
    let channels = other_channels(ca, tr.nominal_hz);
    for ((label, meas, sim), (_, _, sim0)) in channels.iter().zip(&start_channels) {
        let measured = if sim.is_empty() {
            "measured (played back)"
        } else {
            "measured"
        };
        panels.push(plot::start_end_panel(
            t,
            label.clone(),
            measured,
            meas,
            sim0,
            sim,
        ));
    }
    let mut decor: Vec<plot::Decor> = panels.iter().map(|_| plot::Decor::default()).collect();
    let (sp, sq) = noise_of(report, tr.event)
        .map(|(_, p, q)| (p, q))
        .unwrap_or((f64::NAN, f64::NAN));
    for (sig, res, sigma) in [("P", &rp, sp), ("Q", &rq, sq)] {
        panels.push(plot::Panel {
            y_label: format!("{sig} residual (sim − meas) [pu]"),
            series: vec![series("calibrated", res.as_slice(), plot::SIMULATED, false)],
        });
        decor.push(plot::Decor {
            y_bands: if sigma.is_finite() {
                vec![plot::YBand {
                    label: format!("±σ{sig} noise {}", num(sigma)),
                    y0: -sigma,
                    y1: sigma,
                    color: plot::NOISE,
                }]
            } else {
                vec![]
            },
            ..Default::default()
        });
    }
    plot::render(
        &format!("{}: measured and simulated", tr.event),
        "time [s]",
        &panels,
        &decor,
    )
}
