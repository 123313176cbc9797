//! The `diagnose` report (`report.html`) and its plots: provenance, the verdict with an honest
//! colour, the re-fitted parameters, the candidates against one reference, the evidence
//! (windows of more than a few samples, modes with plausible damping) and the plots inlined
//! (drawn by [`super::diagnose_plots`]).

use itaipu_calib::diagnose::{
    CandidateReport, Confidence, Diagnosis, EventEvidence, ReferenceRefit,
};
use itaipu_calib::evidence::{Mode, SignalEvidence, WindowStats};

use super::{chi2, escape, num, pct, Cell, Page, Provenance, Tone};

/// A residual window with fewer samples is not presented as evidence (its RMS is one or two
/// noisy samples, not a location).
pub const MIN_WINDOW_SAMPLES: usize = 5;

pub use itaipu_calib::evidence::PLAUSIBLE_ZETA;

/// Whether a fitted mode is shown as a finding: the library's rule ([`Mode::is_finding`]),
/// which the verdict cites modes by too.
pub fn plausible(m: &Mode) -> bool {
    m.is_finding()
}

/// The window (of at least [`MIN_WINDOW_SAMPLES`] samples) holding the largest share of the
/// squared error.
pub fn top_window(s: &SignalEvidence) -> Option<&WindowStats> {
    s.windows
        .iter()
        .filter(|w| w.samples >= MIN_WINDOW_SAMPLES)
        .max_by(|a, b| a.share_of_sse.total_cmp(&b.share_of_sse))
}

/// The headline's worst RMS/σ of the unit as given (the library's one number, as a fit's
/// report gives it for its calibrated unit; NaN when the noise could not be measured).
pub fn worst_ratio(r: &Diagnosis) -> f64 {
    r.headline.worst.unwrap_or(f64::NAN)
}

/// The reference every RMS of the report is compared with: the unit as given, pooled over
/// the events (`signal` P or Q), from the evidence.
pub fn reference_rms(r: &Diagnosis, signal: &str) -> f64 {
    let (mut sse, mut n) = (0.0, 0usize);
    for s in r
        .evidence
        .iter()
        .flat_map(|e| &e.signals)
        .filter(|s| s.signal == signal)
    {
        sse += s.rms * s.rms * s.samples as f64;
        n += s.samples;
    }
    if n == 0 {
        f64::NAN
    } else {
        (sse / n as f64).sqrt()
    }
}

/// A drawn plot: file name in the output folder, event, what it shows and its SVG text.
pub struct PlotFile {
    pub file: String,
    pub event: String,
    pub caption: String,
    pub svg: String,
}

fn opt_json(v: Option<f64>, pointer: String) -> Cell {
    match v {
        Some(x) if x.is_finite() => Cell::json(x, pointer, num),
        Some(_) => Cell::text("not determined"),
        None => Cell::text("-"),
    }
}

fn candidate_params(page: &mut Page, i: usize, c: &CandidateReport) {
    if c.parameters.is_empty() {
        return;
    }
    let rows: Vec<Vec<Cell>> = c
        .parameters
        .iter()
        .enumerate()
        .map(|(j, p)| {
            let ptr = |f: &str| format!("/candidates/{i}/parameters/{j}/{f}");
            let mut flags = vec![];
            if p.at_bound {
                flags.push("at bound");
            }
            if p.std_error.is_some_and(|s| !s.is_finite()) {
                flags.push("not identifiable");
            }
            vec![
                Cell::Html(format!("<code>{}</code>", escape(&p.param))),
                Cell::text(if p.extension { "extension" } else { "re-freed" }),
                Cell::text(&p.unit),
                Cell::json(p.start, ptr("start"), num),
                Cell::json(p.min, ptr("min"), num),
                Cell::json(p.max, ptr("max"), num),
                Cell::json(p.result, ptr("result"), num),
                opt_json(p.std_error, ptr("std_error")),
                Cell::Html(format!("<span class=\"flag\">{}</span>", flags.join(", "))),
            ]
        })
        .collect();
    page.table(
        &format!("params-{}", c.cause),
        &[
            "parameter",
            "role",
            "unit",
            "start",
            "min",
            "max",
            "result",
            "std error",
            "flags",
        ],
        &rows,
    );
}

/// The diagnosis as a page.
pub fn html(r: &Diagnosis, prov: &Provenance, plots: &[PlotFile], drawn: bool) -> String {
    let e = escape;
    let mut page = Page::new(&format!(
        "Model validation: diagnosis of {} on {}",
        r.unit,
        r.events.join(", ")
    ));
    page.note(&format!(
        "itaipu-calib diagnose: what the unit still gets wrong on the recorded events, which cause of the catalog explains it, and the extended unit re-fitted. {} threads, {:.1} s.",
        r.threads, r.wall_s
    ));
    page.provenance(prov);

    // The event(s).
    page.h2("events", "Events");
    let mut rows = vec![];
    for (k, ev) in r.evidence.iter().enumerate() {
        rows.push(vec![
            Cell::text(&ev.event),
            Cell::text(if r.held_out.contains(&ev.event) {
                "held out"
            } else {
                "fitted"
            }),
            Cell::json(ev.onset_s, format!("/evidence/{k}/onset_s"), |v| {
                format!("{v:.2}")
            }),
            Cell::Num(
                ev.signals
                    .first()
                    .map(|s| s.samples.to_string())
                    .unwrap_or_default(),
            ),
        ]);
    }
    page.table(
        "event-table",
        &["event", "role", "onset [s]", "samples"],
        &rows,
    );

    // Verdict.
    let v = &r.verdict;
    let named = v.names_a_cause();
    let worst = worst_ratio(r);
    let tone = Tone::judge(
        worst,
        named,
        v.cause == "unexplained" || v.cause == "inconclusive",
    );
    let mut body = format!("<p>{}</p>\n", e(&v.statement));
    body.push_str(&super::headline_html(&r.headline, "/headline/worst"));
    body.push_str(&format!(
        "<p class=\"muted\">Green needs at most {:.1} and no cause named; above {:.1} it is red.</p>\n",
        super::AT_NOISE,
        super::FAR_ABOVE_NOISE
    ));
    if let (Some(g), Some(pr)) = (v.grade, v.probability) {
        body.push_str(&format!(
            "<p>Confidence: <b>{}</b> (posterior probability <span data-json=\"/verdict/probability\" data-value=\"{}\">{pr:.3}</span> against its re-fitted baseline, the other significant candidates and an effect outside the catalog; strong needs at least {})</p>\n",
            g.as_str(),
            serde_json::to_string(&pr).unwrap_or_default(),
            itaipu_calib::diagnose::STRONG_PROBABILITY
        ));
    }
    if !v.competing.is_empty() {
        body.push_str(&format!(
            "<p>Competing causes: {}</p>\n",
            v.competing
                .iter()
                .map(|(c, gap)| format!("<code>{}</code> (BIC +{gap:.1})", e(c)))
                .collect::<Vec<_>>()
                .join(", ")
        ));
    }
    if !v.key_parameters.is_empty() {
        body.push_str(&format!(
            "<p>Key parameters: {}</p>\n",
            v.key_parameters
                .iter()
                .enumerate()
                .map(|(k, (p, x, u))| format!(
                    "<code>{}</code> = <span data-json=\"/verdict/key_parameters/{k}/1\" data-value=\"{}\">{}</span> {}",
                    e(p),
                    serde_json::to_string(x).unwrap_or_default(),
                    num(*x),
                    e(if u == "-" { "" } else { u })
                ))
                .collect::<Vec<_>>()
                .join(", ")
        ));
    }
    if let Some((sig, w, a, b)) = &v.where_ {
        let n = r
            .evidence
            .iter()
            .flat_map(|ev| &ev.signals)
            .filter(|s| &s.signal == sig)
            .flat_map(|s| &s.windows)
            .find(|x| &x.label == w)
            .map(|x| x.samples);
        match n {
            Some(n) if n < MIN_WINDOW_SAMPLES => body.push_str(&format!(
                "<p class=\"muted\">The residual's largest share lies in the {} window of {} ({n} samples): too short to locate it.</p>\n",
                e(w),
                e(sig)
            )),
            _ => body.push_str(&format!(
                "<p>Where the residual lives: {} in the {} window, {a:.2}–{b:.2} s.</p>\n",
                e(sig),
                e(w)
            )),
        }
    }
    body.push_str(if named {
        "<p class=\"muted\">The extended, re-fitted unit is in <code>extended.toml</code>.</p>\n"
    } else {
        "<p class=\"muted\">No cause named: no extended unit was written.</p>\n"
    });
    page.verdict(tone, &format!("Verdict: {} — {}", v.cause, v.title), &body);
    if let Some(c) = &v.confidence {
        confidence_section(&mut page, c);
    }

    // Parameters: the named cause's re-fit (with standard errors), the re-freed set.
    page.h2("parameters", "Parameters");
    match r.candidates.iter().position(|c| c.cause == v.cause) {
        Some(i) if named => {
            page.p(&format!(
                "The unit extended for {} and re-fitted: start, bounds, result and posterior standard error of every re-fitted parameter.",
                v.cause
            ));
            candidate_params(&mut page, i, &r.candidates[i]);
        }
        _ => page.note(
            "No cause named: the unit as given stands; its parameters are those of the unit file.",
        ),
    }
    if !r.refit.is_empty() {
        let rows: Vec<Vec<Cell>> = r
            .refit
            .iter()
            .enumerate()
            .map(|(k, b)| {
                vec![
                    Cell::Html(format!("<code>{}</code>", e(&b.param))),
                    Cell::json(b.min, format!("/refit/{k}/min"), num),
                    Cell::json(b.max, format!("/refit/{k}/max"), num),
                ]
            })
            .collect();
        page.p(
            "Calibrated parameters freed again in every re-fit (baselines and extensions alike):",
        );
        page.table("refit", &["parameter", "min", "max"], &rows);
    }

    // Noise: the one reference.
    let n = &r.noise;
    page.h2("noise", "Noise and the reference");
    let rows: Vec<Vec<Cell>> = n
        .sigmas
        .iter()
        .enumerate()
        .map(|(k, (s, sigma))| {
            vec![
                Cell::text(s),
                Cell::json(*sigma, format!("/noise/sigmas/{k}/1"), num),
                Cell::Num(num(reference_rms(r, s))),
            ]
        })
        .collect();
    page.p(&format!(
        "Playback: {}. Split: {} ({} fitted, {} held-out samples).",
        n.playback, n.split, n.n_fit, n.n_held
    ));
    page.table(
        "noise-table",
        &["compared signal", "σ [pu]", "reference RMS [pu]"],
        &rows,
    );
    let whole_set = r.reference.as_ref().is_some_and(|n| n.failed.is_none());
    page.note(&format!("Noise: {} (of the unit as given, pooled over the fitted events by their samples; the same σ in the evidence tables); χ² = Σ_c Σ (Δc/σ_c)² over the compared signals (P and Q for a phasor record). The reference throughout this report is the unit as given with its set-point offsets re-fitted{}: its residual RMS over the whole record (pooled over the events) is the one every RMS below is compared with, and the evidence tables are computed from it.", itaipu_calib::noise::NOISE_DEFINITION, if whole_set { ", and its calibrated set re-fitted on every compared channel (below)" } else { "" }));
    if let Some(note) = &r.reference {
        reference_section(&mut page, note);
    }

    // Candidates.
    page.h2("candidates", "Candidates");
    page.p("Ranked by ΔBIC = Δχ²/VIF − k ln(N/VIF); a cause is significant when the fitted and held-out χ² drops (net of what the same re-fit gains on noise alone) pass and the record's evidence 2 ln B = ΔBIC + Δχ²_held/VIF (the fitted blocks' Bayes factor times the held-out blocks' predictive likelihood ratio) is above 10. χ² base → ext compares each cause's extended re-fit with the baseline re-fitted over the same parameters; the RMS columns compare with the one reference above.");
    let mut rows = vec![];
    for (i, c) in r.candidates.iter().enumerate() {
        let ptr = |f: &str| format!("/candidates/{i}/gains/{f}");
        let mut row = vec![
            Cell::Num((i + 1).to_string()),
            Cell::Html(format!(
                "<b>{}</b><br/><span class=\"muted\">{}{}</span>",
                e(&c.cause),
                e(&c.title),
                if c.look_alike {
                    " (a look-alike outside the catalog: tried against the others, never named)"
                } else {
                    ""
                }
            )),
        ];
        match &c.gains {
            Some(g) => row.extend([
                Cell::json(g.delta_bic, ptr("delta_bic"), |v| format!("{v:.1}")),
                Cell::json(g.record_evidence, ptr("record_evidence"), |v| {
                    format!("{v:.1}")
                }),
                Cell::json(g.chi2_fit_base, ptr("chi2_fit_base"), chi2),
                Cell::json(g.chi2_fit_ext, ptr("chi2_fit_ext"), chi2),
                Cell::json_pct(g.fit_drop, ptr("fit_drop")),
                Cell::json(g.chi2_held_base, ptr("chi2_held_base"), chi2),
                Cell::json(g.chi2_held_ext, ptr("chi2_held_ext"), chi2),
                Cell::json_pct(g.held_drop, ptr("held_drop")),
                Cell::Num(g.k.to_string()),
                Cell::Html(if c.significant {
                    "<span class=\"sig\">yes</span>".into()
                } else {
                    "no".into()
                }),
                Cell::text(
                    g.rms
                        .iter()
                        .map(|(s, _, ext)| format!("{s} {}", num(*ext)))
                        .collect::<Vec<_>>()
                        .join(", "),
                ),
            ]),
            None => row.push(Cell::Html(format!(
                "<span class=\"muted\">{}</span>",
                e(&c.note)
            ))),
        }
        rows.push(row);
    }
    page.table(
        "candidates-table",
        &[
            "#",
            "cause",
            "ΔBIC",
            "2 ln B",
            "fit χ² base",
            "fit χ² ext",
            "fit drop [%]",
            "held-out χ² base",
            "held-out χ² ext",
            "held-out drop [%]",
            "k",
            "significant",
            "RMS ext [pu]",
        ],
        &rows,
    );
    page.note(&format!(
        "Reference (unit as given): RMS {}. {}",
        n.sigmas
            .iter()
            .map(|(s, _)| format!("{s} {} pu", num(reference_rms(r, s))))
            .collect::<Vec<_>>()
            .join(", "),
        itaipu_calib::diagnose::REFIT_RMS_NOTE
    ));
    for (i, c) in r
        .candidates
        .iter()
        .enumerate()
        .filter(|(_, c)| c.applicable)
    {
        page.h3(&c.cause);
        page.p(&format!(
            "Extension: {}.{}",
            c.extension,
            if c.note.is_empty() {
                String::new()
            } else {
                format!(" {}", c.note)
            }
        ));
        if !(named && c.cause == v.cause) {
            candidate_params(&mut page, i, c);
        }
        if !c.fixed.is_empty() {
            page.p(&format!(
                "Fixed: {}",
                c.fixed
                    .iter()
                    .map(|(p, x)| format!("{p} = {x}"))
                    .collect::<Vec<_>>()
                    .join(", ")
            ));
        }
        if !c.signature.is_empty() {
            page.raw(&format!(
                "<p>Evidence pointing to it:</p>\n<ul class=\"tight\">{}</ul>\n",
                c.signature
                    .iter()
                    .map(|s| format!("<li>{}</li>", e(s)))
                    .collect::<String>()
            ));
        }
        page.note(&format!(
            "{} simulations, {} failed candidates, {:.1} s.",
            c.simulations, c.failed_candidates, c.wall_s
        ));
    }

    // Evidence.
    page.h2("evidence", "Evidence");
    page.p("Residuals r = simulated − measured of the unit as given (the reference).");
    for (k, ev) in r.evidence.iter().enumerate() {
        evidence_tables(&mut page, k, ev, "/evidence");
    }
    if !r.evidence_after.is_empty() {
        page.h3(&format!("With the extension ({})", v.cause));
        let mut rows = vec![];
        for (k, ev) in r.evidence_after.iter().enumerate() {
            for (j, s) in ev.signals.iter().enumerate() {
                let ptr = |f: &str| format!("/evidence_after/{k}/signals/{j}/{f}");
                let w = top_window(s)
                    .map(|w| format!("{} ({})", w.label, pct(w.share_of_sse)))
                    .unwrap_or_else(|| "-".into());
                rows.push(vec![
                    Cell::text(&ev.event),
                    Cell::text(&s.signal),
                    Cell::json(s.rms, ptr("rms"), num),
                    Cell::json(s.rms_over_noise, ptr("rms_over_noise"), |v| {
                        format!("{v:.2}")
                    }),
                    Cell::json(s.whiteness.p_value, ptr("whiteness/p_value"), |v| {
                        format!("{v:.3}")
                    }),
                    Cell::text(w),
                ]);
            }
        }
        page.table(
            "evidence-after",
            &[
                "event",
                "signal",
                "RMS [pu]",
                "RMS/noise",
                "Ljung-Box p",
                "window with most SSE",
            ],
            &rows,
        );
    }

    // Plots.
    page.h2("plots", "Plots");
    if drawn {
        for p in plots {
            page.figure(&p.svg, &format!("{}: {} ({})", p.event, p.caption, p.file));
        }
    } else {
        page.note("Plots not drawn (--no-plot).");
    }
    page.finish()
}

/// The evidence tables of one event; `base` is the JSON array they come from.
/// The named cause's confidence: what its posterior probability weighs (the odds of each
/// alternative against it), the evidence behind it, and why the grade is not strong.
fn confidence_section(page: &mut Page, c: &Confidence) {
    let row = |what: &str, v: f64, field: &str, meaning: &str| {
        vec![
            Cell::text(what),
            if v.is_finite() {
                Cell::json(v, format!("/verdict/confidence/{field}"), num)
            } else {
                Cell::text("-")
            },
            Cell::text(meaning),
        ]
    };
    let rows = vec![
        row(
            "odds of the re-fitted baseline",
            c.odds_baseline,
            "odds_baseline",
            "no extension: e^(−2 ln B / 2) with the record's evidence",
        ),
        row(
            "odds of the other significant candidates",
            c.odds_rivals,
            "odds_rivals",
            "their fitted BIC less their held-out prediction, summed",
        ),
        row(
            "odds of an effect outside the catalog",
            c.odds_outside,
            "odds_outside",
            "a prior of its own, raised by the misfit the extension leaves, lowered by the data's own evidence",
        ),
        row(
            "data's own evidence 2 ln B",
            c.data_evidence,
            "data_evidence",
            "the extension's gain on the record, the priors' rows left out",
        ),
        row(
            "misfit left",
            c.misfit_left,
            "misfit_left",
            "fitted χ² the extension leaves beyond the noise and its block's model-form tolerance",
        ),
    ];
    page.h2("confidence", "Confidence");
    page.p("What the named cause's posterior probability weighs: 1 / (1 + the three odds below).");
    page.table("confidence", &["", "value", "meaning"], &rows);
    if !c.not_strong.is_empty() {
        page.p(&format!("Not strong: {}.", c.not_strong.join("; ")));
    }
}

/// The diagnosis's reference when it re-fitted the calibrated set on every compared channel
/// (the record holds the field): its sentence and, per channel, the RMS before and after.
fn reference_section(page: &mut Page, note: &ReferenceRefit) {
    page.p(&note.sentence);
    let rows: Vec<Vec<Cell>> = note
        .channels
        .iter()
        .enumerate()
        .map(|(k, c)| {
            vec![
                Cell::text(&c.signal),
                Cell::json(c.sigma, format!("/reference/channels/{k}/sigma"), num),
                Cell::json(
                    c.rms_offsets,
                    format!("/reference/channels/{k}/rms_offsets"),
                    num,
                ),
                Cell::json(
                    c.rms_reference,
                    format!("/reference/channels/{k}/rms_reference"),
                    num,
                ),
            ]
        })
        .collect();
    if !rows.is_empty() {
        page.table(
            "reference",
            &[
                "channel",
                "σ [pu]",
                "RMS, offsets re-fitted [pu]",
                "RMS, reference [pu]",
            ],
            &rows,
        );
    }
}

fn evidence_tables(page: &mut Page, k: usize, ev: &EventEvidence, base: &str) {
    page.h3(&format!("{} (event onset {:.2} s)", ev.event, ev.onset_s));
    let rows: Vec<Vec<Cell>> = ev
        .signals
        .iter()
        .enumerate()
        .map(|(j, s)| {
            let ptr = |f: &str| format!("{base}/{k}/signals/{j}/{f}");
            let w = &s.whiteness;
            vec![
                Cell::Html(format!("<b>{}</b>", escape(&s.signal))),
                Cell::Num(s.samples.to_string()),
                Cell::json(s.bias, ptr("bias"), num),
                Cell::json(s.rms, ptr("rms"), num),
                Cell::json(s.noise_floor_rms, ptr("noise_floor_rms"), num),
                Cell::json(s.rms_over_noise, ptr("rms_over_noise"), |v| {
                    format!("{v:.2}")
                }),
                Cell::json(w.ljung_box_q, ptr("whiteness/ljung_box_q"), |v| {
                    format!("{v:.1}")
                }),
                Cell::json(w.p_value, ptr("whiteness/p_value"), |v| format!("{v:.3}")),
                Cell::text(if w.white { "yes" } else { "no" }),
                Cell::Num(w.outside_band.to_string()),
                match s.spectrum.peak_hz {
                    Some(f) => {
                        Cell::Num(format!("{f:.2} Hz, {} pu", num(s.spectrum.peak_amplitude)))
                    }
                    None => Cell::text("-"),
                },
            ]
        })
        .collect();
    page.table(
        &format!("evidence-{k}"),
        &[
            "signal",
            "samples",
            "bias [pu]",
            "RMS [pu]",
            "noise floor [pu]",
            "RMS/noise",
            "Ljung-Box Q",
            "p",
            "white",
            "ACF lags outside band",
            "spectral peak",
        ],
        &rows,
    );
    for (j, s) in ev.signals.iter().enumerate() {
        let ptr = |f: String| format!("{base}/{k}/signals/{j}/{f}");
        page.p(&format!(
            "{} residual by window, cross-correlation with the inputs, modes:",
            s.signal
        ));
        let mut short = vec![];
        let mut rows = vec![];
        for (w_i, w) in s.windows.iter().enumerate() {
            if w.samples < MIN_WINDOW_SAMPLES {
                short.push(format!("{} ({} samples)", w.label, w.samples));
                continue;
            }
            let p = |f: &str| ptr(format!("windows/{w_i}/{f}"));
            rows.push(vec![
                Cell::text(&w.label),
                Cell::json(w.start_s, p("start_s"), |v| format!("{v:.2}")),
                Cell::json(w.end_s, p("end_s"), |v| format!("{v:.2}")),
                Cell::Num(w.samples.to_string()),
                Cell::json(w.bias, p("bias"), num),
                Cell::json(w.rms, p("rms"), num),
                Cell::json_pct(w.share_of_sse, p("share_of_sse")),
            ]);
        }
        page.table(
            &format!("windows-{k}-{}", s.signal),
            &[
                "window",
                "start [s]",
                "end [s]",
                "samples",
                "bias [pu]",
                "RMS [pu]",
                "share of SSE [%]",
            ],
            &rows,
        );
        if !short.is_empty() {
            page.note(&format!(
                "Not shown as evidence (fewer than {MIN_WINDOW_SAMPLES} samples): {}.",
                short.join(", ")
            ));
        }
        if !s.cross.is_empty() {
            let rows: Vec<Vec<Cell>> = s
                .cross
                .iter()
                .enumerate()
                .map(|(x_i, x)| {
                    vec![
                        Cell::text(&x.input),
                        Cell::Num(x.best_lag_samples.to_string()),
                        Cell::json(
                            x.correlation,
                            ptr(format!("cross/{x_i}/correlation")),
                            |v| format!("{v:+.3}"),
                        ),
                        Cell::json(x.band, ptr(format!("cross/{x_i}/band")), |v| {
                            format!("{v:.3}")
                        }),
                        Cell::text(if x.significant { "yes" } else { "no" }),
                    ]
                })
                .collect();
            page.table(
                &format!("cross-{k}-{}", s.signal),
                &[
                    "input",
                    "best lag [samples]",
                    "correlation",
                    "band",
                    "significant",
                ],
                &rows,
            );
        }
        let shown: Vec<(usize, &Mode)> = s
            .modes
            .iter()
            .enumerate()
            .filter(|(_, m)| plausible(m))
            .collect();
        let hidden = s.modes.len() - shown.len();
        if shown.is_empty() {
            page.note("No oscillatory mode with a plausible damping ratio.");
        } else {
            let rows: Vec<Vec<Cell>> = shown
                .iter()
                .map(|(m_i, m)| {
                    let p = |f: &str| ptr(format!("modes/{m_i}/{f}"));
                    vec![
                        Cell::json(m.freq_hz, p("freq_hz"), |v| format!("{v:.3}")),
                        Cell::json(m.damping_ratio, p("damping_ratio"), |v| format!("{v:.3}")),
                        Cell::json(m.amplitude, p("amplitude"), num),
                        Cell::json_pct(m.energy_share, p("energy_share")),
                    ]
                })
                .collect();
            page.table(
                &format!("modes-{k}-{}", s.signal),
                &[
                    "frequency [Hz]",
                    "damping ratio",
                    "amplitude [pu]",
                    "energy share [%]",
                ],
                &rows,
            );
        }
        if hidden > 0 {
            page.note(&format!(
                "{hidden} fitted term(s) not shown as modes: below 0.1 Hz, or a damping ratio outside ({}, {}) (a growing or non-oscillatory term of the fit, not a finding; all are in diagnosis.json).",
                PLAUSIBLE_ZETA.0, PLAUSIBLE_ZETA.1
            ));
        }
    }
}
