//! The verdicts' statements: a paragraph for a person saying what was named and why, or why
//! nothing was (`none`, `unexplained`, `inconclusive`), with where the residual lives.

use crate::evidence::SignalEvidence;

use super::gain::{bic_met, fit_floor_met, held_floor_met};
use super::look_alike;
use super::options::DiagnoseOptions;
use super::playback::{signal_channel, FIELD_CHANNELS};
use super::ranking::bic_gap;
use super::report::{
    fmt_num, CandidateReport, Confidence, EventEvidence, Gains, Grade, Verdict, VerdictCause,
};
use super::split::SEGMENT_S;

/// The event and P or Q signal with the largest residual RMS relative to its noise floor (the
/// evidence's `rms_over_noise`: the event's own floor, [`crate::noise::noise_floor`], as the
/// report shows it).
fn worst_residual<'a>(
    ev: &'a [EventEvidence],
    compared: &[&str],
) -> Option<(&'a str, &'a SignalEvidence)> {
    let mut worst: Option<(&str, &SignalEvidence)> = None;
    for e in ev {
        for s in e
            .signals
            .iter()
            .filter(|s| compared.contains(&s.signal.as_str()))
        {
            if worst.is_none_or(|(_, w)| s.rms_over_noise > w.rms_over_noise) {
                worst = Some((&e.event, s));
            }
        }
    }
    worst
}

/// The window holding the largest share of a signal's squared residual.
fn top_window(s: &SignalEvidence) -> Option<&crate::evidence::WindowStats> {
    s.windows
        .iter()
        .max_by(|a, b| a.share_of_sse.total_cmp(&b.share_of_sse))
}

/// A verdict that names no cause and carries no gains, grade or competitors: its id, title,
/// statement and where the residual lives.
fn unnamed(
    cause: VerdictCause,
    title: String,
    statement: String,
    where_: Option<(String, String, f64, f64)>,
) -> Verdict {
    Verdict {
        cause,
        title,
        statement,
        key_parameters: vec![],
        gains: None,
        where_,
        grade: None,
        probability: None,
        confidence: None,
        competing: vec![],
    }
}

/// The tests of a candidate's significance ([`DiagnoseOptions`]: `min_fit_drop`,
/// `min_held_drop`, `bic_threshold`) that its net gains `g` fall short of, as the verdict's
/// statement gives them, so that an engineer reading `none` sees which test an effect missed
/// and by how much. (A held-out blocks' shortfall is forgiven by the segments' second test,
/// reported apart in the candidate's note.)
pub(super) fn short_of(g: &Gains, opts: &DiagnoseOptions) -> Vec<String> {
    let mut out = vec![];
    if !fit_floor_met(g.fit_drop, opts) {
        out.push(shortfall("fitted", g.fit_drop, opts.min_fit_drop));
    }
    if !held_floor_met(g.held_drop, opts) {
        out.push(shortfall("held-out", g.held_drop, opts.min_held_drop));
    }
    if !bic_met(g.record_evidence, opts) {
        out.push(format!(
            "2 ln B {:.1}, not above {:.0}",
            g.record_evidence, opts.bic_threshold
        ));
    }
    if out.is_empty() {
        out.push("its held-out blocks and segments do not confirm it".into());
    }
    out
}

/// A relative χ² change short of its floor, as a statement gives it: "the fitted χ² down 1.6 %,
/// under 2.0 %", "the held-out χ² up 0.4 %" (a rise is short of any floor), "the fitted χ²
/// unchanged" (below the 0.05 % the statement prints).
fn shortfall(half: &str, drop: f64, floor: f64) -> String {
    let pct = 100.0 * drop;
    if pct.abs() < 0.05 {
        format!("the {half} χ² unchanged")
    } else if pct < 0.0 {
        format!("the {half} χ² up {:.1} %", -pct)
    } else {
        format!(
            "the {half} χ² down {pct:.1} %, under {:.1} %",
            100.0 * floor
        )
    }
}

/// The verdict when no cause is significant: `none` at the noise floor, else `unexplained`
/// with where the residual lives. A candidate whose gain passed the statistical test and was
/// refused by its physical checks ([`CandidateReport::passed_test`]) makes it `unexplained` at
/// the noise floor too: the test that would have named a cause says an effect is there (its
/// false-alarm rate is the naming's own, whatever refused the name), and the check says it is
/// not that cause, so "the model needs no extension" would be false.
pub(super) fn undecided(
    ev: &[EventEvidence],
    compared: &[&str],
    reports: &[CandidateReport],
    absorbed: &[String],
    opts: &DiagnoseOptions,
) -> Verdict {
    let best_try = best_try(reports, opts);
    let Some((event, s)) = worst_residual(ev, compared) else {
        return unnamed(
            VerdictCause::None,
            "no residual to explain".into(),
            format!(
                "No residual of the compared signals ({}).",
                compared.join(", ")
            ),
            None,
        );
    };
    let worst = Worst {
        event,
        s,
        top: top_window(s),
        over: s.rms_over_noise,
    };
    // The refused candidate with the largest evidence for the record.
    let refused = reports
        .iter()
        .filter(|r| r.passed_test && !r.significant)
        .filter_map(|r| r.gains.as_ref().map(|g| (r, g)))
        .max_by(|(_, a), (_, b)| a.record_evidence.total_cmp(&b.record_evidence));
    match refused.filter(|_| worst.over <= opts.noise_factor) {
        Some((r, g)) => refused_at_the_floor(&worst, r, g),
        None if worst.over <= opts.noise_factor && !absorbed.is_empty() => {
            absorbed_at_the_floor(&worst, absorbed, &best_try)
        }
        None if worst.over <= opts.noise_factor => at_the_floor(&worst, &best_try),
        None => unexplained(&worst, &best_try, field_hint(compared, s)),
    }
}

/// The largest residual of the compared signals relative to its noise floor: the event, the
/// signal's evidence, the window holding most of it and its RMS over the noise floor.
struct Worst<'e> {
    event: &'e str,
    s: &'e SignalEvidence,
    top: Option<&'e crate::evidence::WindowStats>,
    over: f64,
}

impl Worst<'_> {
    /// Where the residual lives: `(signal, window, start_s, end_s)`.
    fn where_(&self) -> Option<(String, String, f64, f64)> {
        let s = self.s;
        self.top
            .map(|w| (s.signal.clone(), w.label.clone(), w.start_s, w.end_s))
    }
}

/// What the best candidate (the first with gains) gained and which test it fell short of, as a
/// sentence of a verdict that names no cause (empty without one).
fn best_try(reports: &[CandidateReport], opts: &DiagnoseOptions) -> String {
    reports
        .iter()
        .filter_map(|r| r.gains.as_ref().map(|g| (r, g)))
        .next()
        .map(|(r, g)| {
            format!(
                " The best candidate, {}, gained ΔBIC {:.1} ({:.1} % of χ²; the record's evidence \
                 with its held-out prediction 2 ln B = {:.1}){}.",
                r.cause,
                g.delta_bic,
                100.0 * g.fit_drop,
                g.record_evidence,
                if r.note.starts_with("not named") {
                    format!(", {}", r.note)
                } else {
                    format!(", not significant ({})", short_of(g, opts).join("; "))
                }
            )
        })
        .unwrap_or_default()
}

/// The advice when the largest residual is in the recorded field of a phasor playback (P and Q
/// compared too): what a calibration on P and Q alone can leave, X_d and the exciter's gain
/// bent until the simulated field runs off the recorded one. The condition is structural
/// (which compared signal holds the largest residual), no threshold: the verdict is already
/// `unexplained`, the residual above the noise floor by `noise_factor`.
fn field_hint(compared: &[&str], s: &SignalEvidence) -> &'static str {
    if compared.contains(&"P")
        && compared.contains(&"Q")
        && signal_channel(&s.signal).is_some_and(|c| FIELD_CHANNELS.contains(&c))
    {
        " If the calibration compared P and Q alone, it may have bent X_d and the exciter's gain \
         until the simulated field ran off the recorded one: calibrate with channels = \"recorded\" \
         (P, Q and the recorded field, each weighted by its noise) and diagnose again."
    } else {
        ""
    }
}

/// `unexplained` at the noise floor: a candidate passed the statistical test and was refused
/// by its physical checks (`r`, its gains `g`).
fn refused_at_the_floor(w: &Worst, r: &CandidateReport, g: &Gains) -> Verdict {
    let (s, event, over) = (w.s, w.event, w.over);
    let why = r.note.strip_prefix("not named: ").unwrap_or(&r.note);
    let place = w.top.map_or(String::new(), |w| {
        format!(
            "; the largest residual is {} in the {} window ({:.2}-{:.2} s) on {event}",
            s.signal, w.label, w.start_s, w.end_s
        )
    });
    unnamed(
        VerdictCause::Unexplained,
        format!(
            "unexplained: a significant gain that {} cannot be",
            r.cause
        ),
        format!(
            "Unexplained by the catalog. The residuals are near the noise level (largest: {} on {event}, the reference's RMS \
             over the whole record {:.2} × the noise σ), yet the extension of {} ({}) lowers χ² on the fitted samples by {:.1} % and on the \
             held-out samples by {:.1} % (the record's evidence 2 ln B = {:.1}), a gain the test names a cause on; it is \
             not named: {why}. An effect the catalog does not hold is at work where {} acts{place}. If you know the \
             unit's setting that makes it, write a cause file for it and diagnose again with --user-cause.",
            s.signal,
            over,
            r.cause,
            r.extension,
            100.0 * g.fit_drop,
            100.0 * g.held_drop,
            g.record_evidence,
            r.cause
        ),
        w.where_(),
    )
}

/// `none` at the noise floor with re-freed values far outside their typical ranges
/// ([`super::absorbed`]): said, not an alarm. Such a value is either absorbing an effect the
/// model lacks or only weakly determined by the record (a flat direction the search wandered
/// along to its bound: on clean records of a unit other than the practice family's, X_d and X_q
/// reached twice their datasheet so), and the record cannot tell the two apart when no
/// extension gains; the engineer can, from the unit's test reports.
fn absorbed_at_the_floor(w: &Worst, absorbed: &[String], best_try: &str) -> Verdict {
    let mut v = at_the_floor(w, best_try);
    v.statement = format!(
        "{} But the calibrated values {} lie far outside the typical ranges of their models while \
         their datasheet values do not: either the record determines them weakly or they absorb \
         an effect the model lacks. Check them against the unit's test reports before relying on \
         the model.",
        v.statement,
        absorbed.join(", ")
    );
    v
}

/// `none`: the residuals at the noise floor and no extension gaining significantly.
fn at_the_floor(w: &Worst, best_try: &str) -> Verdict {
    let (s, event, over) = (w.s, w.event, w.over);
    unnamed(
        VerdictCause::None,
        "residual at the noise floor".into(),
        format!(
            "No cause named: the residuals are at the noise level (largest: {} on {event}, the reference's RMS over \
             the whole record {:.2} × the noise σ; Ljung-Box p = {:.2}) and no extension gains significantly.{best_try} The model needs no extension \
             for these data.",
            s.signal, over, s.whiteness.p_value
        ),
        w.where_(),
    )
}

/// `unexplained`: a residual above the noise floor that no candidate explains, with the window
/// and the mode where it lives (or, in a record too short to cut into windows, as a whole).
fn unexplained(w: &Worst, best_try: &str, field_hint: &str) -> Verdict {
    let (s, event, over) = (w.s, w.event, w.over);
    let Some(top) = w.top else {
        return unnamed(
            VerdictCause::Unexplained,
            format!("unexplained residual at {}", s.signal),
            format!(
                "Unexplained residual at {} on {event}: the reference's RMS over the whole record \
                 {:.2} × the noise σ, Ljung-Box p = {:.2}. No catalog extension explains it significantly.{best_try}{field_hint}",
                s.signal, over, s.whiteness.p_value
            ),
            None,
        );
    };
    let mode = s
        .modes
        .iter()
        .filter(|m| m.is_finding())
        .max_by(|a, b| a.energy_share.total_cmp(&b.energy_share))
        .map(|m| {
            format!(
                ", dominant residual mode {:.2} Hz (ζ = {:.2})",
                m.freq_hz, m.damping_ratio
            )
        })
        .unwrap_or_default();
    unnamed(
        VerdictCause::Unexplained,
        format!("unexplained residual at {} ({}, {:.2}-{:.2} s)", s.signal, top.label, top.start_s, top.end_s),
        format!(
            "Unexplained residual at {} in the {} window ({:.2}-{:.2} s, {:.0} % of its squared error) on {event}: the reference's RMS \
             over the whole record {:.2} × the noise σ, Ljung-Box p = {:.2}{mode}. No catalog extension explains it significantly.{best_try}{field_hint}",
            s.signal,
            top.label,
            top.start_s,
            top.end_s,
            100.0 * top.share_of_sse,
            over,
            s.whiteness.p_value
        ),
        w.where_(),
    )
}

/// A verdict that names no cause but lists the candidates behind it (`inconclusive`, or
/// `unexplained` by a look-alike): `best` first, then `others` with their BIC gaps above it,
/// and where the residual lives as `undecided` finds it.
fn listing(
    cause: VerdictCause,
    title: String,
    statement: String,
    (ev, compared): (&[EventEvidence], &[&str]),
    best: &CandidateReport,
    others: Vec<(String, f64)>,
) -> Verdict {
    let where_ = worst_residual(ev, compared).and_then(|(_, s)| {
        top_window(s).map(|w| (s.signal.clone(), w.label.clone(), w.start_s, w.end_s))
    });
    Verdict {
        competing: std::iter::once((best.cause.clone(), 0.0))
            .chain(others)
            .collect(),
        ..unnamed(cause, title, statement, where_)
    }
}

/// The verdict when a look-alike outside the catalog ([`super::look_alike`]) is the best
/// significant candidate: `unexplained`, saying what the residual looks like, which catalog
/// causes it beats and how to name it; `competing` holds the look-alike, then those causes
/// with their extended models' BIC above it.
pub(super) fn outside_catalog(
    best: &CandidateReport,
    reports: &[CandidateReport],
    ev: &[EventEvidence],
    compared: &[&str],
) -> Verdict {
    let beaten: Vec<(String, f64)> = reports
        .iter()
        .filter(|r| r.significant && !r.look_alike && r.gains.is_some())
        .map(|r| (r.cause.clone(), bic_gap(best, r)))
        .collect();
    let gains = best.gains.as_ref().map_or(String::new(), |g| {
        format!(
            ": its extension ({}) lowers χ² on the fitted samples by {:.0} % and on the held-out samples by {:.0} %, \
             the record's evidence 2 ln B = {:.1}",
            best.extension,
            100.0 * g.fit_drop,
            100.0 * g.held_drop,
            g.record_evidence
        )
    });
    let catalog = if beaten.is_empty() {
        String::new()
    } else {
        let list: Vec<String> = beaten
            .iter()
            .map(|(c, gap)| format!("{c} (its extended model's BIC {gap:.1} above)"))
            .collect();
        let verbs = if list.len() == 1 {
            "also passes its own test but explains the data less well; it is"
        } else {
            "also pass their own tests but explain the data less well; they are"
        };
        format!(
            " {} {verbs} not named, as the nearest catalog cause to an effect outside the catalog \
             would be a wrong name.",
            list.join(" and ")
        )
    };
    let file = look_alike::file_of(&best.cause);
    listing(
        VerdictCause::Unexplained,
        format!(
            "unexplained by the catalog: looks like {} ({})",
            best.title, best.cause
        ),
        format!(
            "Unexplained by the catalog. The residual is explained best by an effect outside the catalog that the \
             diagnosis tries as a look-alike, {} ({}){gains}.{catalog} If the unit has this setting, diagnose again \
             with --user-cause {file} to name it and re-fit with it; if not, write a cause file for the effect it has.",
            best.title, best.cause
        ),
        (ev, compared),
        best,
        beaten,
    )
}

/// A candidate as the verdicts that list it name it: its id, and for a look-alike the bundled
/// file that models it.
fn display_name(c: &CandidateReport) -> String {
    if c.look_alike {
        format!(
            "{} (outside the catalog: {})",
            c.cause,
            look_alike::file_of(&c.cause)
        )
    } else {
        c.cause.clone()
    }
}

/// The verdict when two or more significant candidates explain the residual within the BIC
/// threshold of each other: `inconclusive`, with the competitors and where the residual lives.
pub(super) fn inconclusive(
    best: &CandidateReport,
    competing: &[(String, f64)],
    reports: &[CandidateReport],
    ev: &[EventEvidence],
    compared: &[&str],
    opts: &DiagnoseOptions,
) -> Verdict {
    let describe = |c: &CandidateReport| {
        let name = display_name(c);
        c.gains.as_ref().map_or(name.clone(), |g| {
            format!(
                "{name} (ΔBIC {:.1} against its baseline, fitted χ² −{:.0} %, held out −{:.0} %)",
                g.delta_bic,
                100.0 * g.fit_drop,
                100.0 * g.held_drop
            )
        })
    };
    let rivals: Vec<String> = competing
        .iter()
        .filter_map(|(c, gap)| {
            reports.iter().find(|r| &r.cause == c).map(|r| {
                format!(
                    "{}, whose extended model's BIC is {gap:.1} above",
                    describe(r)
                )
            })
        })
        .collect();
    let names: Vec<&str> = std::iter::once(best.cause.as_str())
        .chain(competing.iter().map(|(c, _)| c.as_str()))
        .collect();
    listing(
        VerdictCause::Inconclusive,
        format!("inconclusive: {}", names.join(" or ")),
        format!(
            "Inconclusive: more than one cause explains the residual about equally. {} passes its test, and so does {}: a              BIC difference below {:.0} (Kass and Raftery's \"very strong\" level, the one each cause had to pass against its              baseline) does not decide between them, so none is named. Test them apart with another event (a step of the              other sign or size, a different operating point) or hold one of them out by knowledge of the unit.",
            describe(best),
            rivals.join("; and "),
            opts.bic_threshold
        ),
        (ev, compared),
        best,
        competing.to_vec(),
    )
}

/// The verdict when the fitted and the held-out samples disagree: `best` explains the fitted
/// samples best (lowest BIC of the significant candidates' extended models), but each of
/// `contradicting` (candidate, [`held_out_gap`]) predicts the held-out samples better by more than
/// the BIC threshold, the "very strong" level each cause had to pass against its baseline. A
/// cause is named for what it predicts, not only for what it fits: a model that fits the
/// samples it saw better and predicts the others worse has absorbed some of another effect's
/// misfit. `inconclusive`, listing both.
pub(super) fn contradicted(
    best: &CandidateReport,
    contradicting: &[(&CandidateReport, f64)],
    ev: &[EventEvidence],
    compared: &[&str],
    opts: &DiagnoseOptions,
) -> Verdict {
    let rivals: Vec<String> = contradicting
        .iter()
        .map(|(r, gap)| {
            format!(
                "{}, whose extended model predicts the held-out samples better by Δχ² = {gap:.1} (deflated by the \
                 residual's variance inflation) although its BIC on the fitted samples is {:.1} above",
                display_name(r),
                bic_gap(best, r)
            )
        })
        .collect();
    let names: Vec<&str> = std::iter::once(best.cause.as_str())
        .chain(contradicting.iter().map(|(r, _)| r.cause.as_str()))
        .collect();
    listing(
        VerdictCause::Inconclusive,
        format!("inconclusive: {}", names.join(" or ")),
        format!(
            "Inconclusive: the fitted and the held-out samples disagree. {} passes its test and explains the fitted \
             samples best, but so does {}: more than {:.0} (Kass and Raftery's \"very strong\" level) on samples neither \
             re-fit saw. A cause that fits better what it saw and predicts worse what it did not has absorbed part of \
             another effect's misfit, so none is named. Test them apart with another event, or hold one of them out by \
             knowledge of the unit.",
            display_name(best),
            rivals.join("; and "),
            opts.bic_threshold
        ),
        (ev, compared),
        best,
        contradicting
            .iter()
            .map(|(r, _)| (r.cause.clone(), bic_gap(best, r)))
            .collect(),
    )
}

/// The named cause's key parameters `(path, value, unit)`: the extension's own re-fitted
/// parameters, then its fixed structural results.
pub(super) fn key_parameters(rep: &CandidateReport) -> Vec<(String, f64, String)> {
    let mut key: Vec<(String, f64, String)> = rep
        .parameters
        .iter()
        .filter(|p| p.extension)
        .map(|p| (p.param.clone(), p.result, p.unit.clone()))
        .collect();
    key.extend(
        rep.fixed
            .iter()
            .map(|(p, v)| (p.clone(), *v, "-".to_string())),
    );
    key
}

/// The statement of a named cause `rep` (its gains `g`, its key parameters `key`): what it
/// gains on the fitted and held-out samples, its fitted values with their standard errors,
/// which calibrated values come back to their datasheet with it, and its confidence
/// (`probability` against its baseline and the `rivals` other significant candidates, and
/// `grade`).
pub(super) fn named(
    rep: &CandidateReport,
    g: &Gains,
    key: &[(String, f64, String)],
    (conf, grade, rivals): (&Confidence, Grade, usize),
) -> String {
    let params: Vec<String> = key
        .iter()
        .map(|(p, v, u)| {
            let se = rep
                .parameters
                .iter()
                .find(|c| &c.param == p)
                .and_then(|c| c.std_error)
                .filter(|e| e.is_finite())
                .map_or(String::new(), |e| format!(" ± {}", fmt_num(e)));
            format!("{p} = {}{se} {u}", fmt_num(*v))
        })
        .collect();
    let statement = format!(
        "{}: {}. The extension ({}) lowers χ² on the fitted samples by {:.0} % ({:.1} -> {:.1}) and on the held-out \
         samples by {:.0} %{}; ΔBIC = {:.1} with {} added parameter(s), and with the held-out samples' \
         predictive gain the record's evidence 2 ln B = {:.1}. Fitted values: {}.",
        rep.cause,
        rep.title,
        rep.extension,
        100.0 * g.fit_drop,
        g.chi2_fit_base,
        g.chi2_fit_ext,
        100.0 * g.held_drop,
        g.held_drop_segments.map_or(String::new(), |d| format!(
            " (on the held-out {SEGMENT_S} s segments of the second test by {:.0} %)",
            100.0 * d
        )),
        g.delta_bic,
        g.k,
        g.record_evidence,
        params.join(", ")
    );
    let back = un_bent(rep);
    let statement = if back.is_empty() {
        statement
    } else {
        format!(
            "{statement} Without it the re-fitted unit bends calibrated values away from their datasheet; with it they come back: {}.",
            back.join(", ")
        )
    };
    let why = if conf.not_strong.is_empty() {
        String::new()
    } else {
        format!("; not strong: {}", conf.not_strong.join("; "))
    };
    format!(
        "{statement} Confidence: {} (posterior probability {:.3} against its re-fitted baseline, the {} other significant \
         candidate(s) and an effect outside the catalog; the data's own evidence 2 ln B = {:.1}{why}).",
        grade.as_str(),
        conf.probability,
        rivals,
        conf.data_evidence
    )
}

/// The calibrated values that come back toward their datasheet with the extension.
fn un_bent(rep: &CandidateReport) -> Vec<String> {
    rep.distortion
        .iter()
        .filter(|d| d.z_base.abs() > 1.0 && d.z_extended.abs() < d.z_base.abs())
        .map(|d| {
            format!(
                "{} {} -> {} (datasheet {})",
                d.param,
                fmt_num(d.base),
                fmt_num(d.extended),
                fmt_num(d.datasheet)
            )
        })
        .collect()
}
