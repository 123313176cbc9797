//! Plausibility of an event's data (and of a unit's parameters) beyond what the readers reject.
//!
//! The readers of [`crate::event`] reject what cannot be read (non-numbers, non-increasing
//! time, values that look like kV or MW, ...). What reads fine but is implausible would
//! otherwise be played back without a word: a 100 s gap in the record, a single sample with
//! |V| = 0 (played back as a fault), an angle column in radians, a time column in the wrong
//! unit, a generator absorbing P, P above the machine's rating on the system base, a sample of
//! 1e300, a record that ends (or starts) in a measurement drop-out. [`check_event`] finds these
//! and returns one [`Finding`] each, naming the file, the line (where the CSV can be re-read to
//! find it) or the time of the sample, the column and the fix; [`Severity::Error`] findings
//! should stop a run, warnings be reported with it.
//!
//! # Drop-outs at the record's edges (`edge_dropout`)
//!
//! A PMU that loses its voltage input (a fuse, a VT circuit, a channel that stops updating)
//! records a |V| that jumps about or falls while the current, and so P and Q, stay as they
//! were. A machine cannot do that: its stator answers a terminal-voltage change ΔV at once
//! (the flux linkages behind X''d cannot change in a sample) with a reactive-power change of
//! about V ΔV / X, X being X''d toward the machine or the grid's reactance, both below 1 pu on
//! the machine's rating. So a real |V| step moves Q by at least [`DROPOUT_KAPPA`] × ΔV × the
//! rating (by 3 to 5 times that, in practice). The rule:
//!
//! * a |V| step between consecutive samples is *testable* when it is beyond noise (above the
//!   union-bound threshold at 1 % over the record, in standard deviations of |V|'s one-sample
//!   changes) and the Q change it implies is above 4 standard deviations of Q's one-sample
//!   changes (the noise scales come from second differences, which the record's swings
//!   barely move, floored at the quantisation step);
//! * a testable step is *followed* when the largest one-sample Q change within 2 samples of it
//!   (so a skew of the power channels of a sample or two does not matter) reaches half the
//!   implied change, and *unfollowed* otherwise;
//! * the record *ends* in a drop-out when its last testable step is unfollowed and lies within
//!   its last [`DROPOUT_EDGE_SAMPLES`] samples (the record ends in it, nothing recovers after):
//!   the span runs from the earliest unfollowed step chained to it (each at most
//!   [`DROPOUT_GAP_S`] from the next, no followed step between) to the end. The start of the
//!   record, mirrored.
//!
//! The rating is the unit's when known, else the pre-event |P + jQ| (a lower bound of it, which
//! makes the implied change smaller and the rule more cautious). The bundled Itaipu record ends
//! in such a drop-out (its erratic |V| after 4.4 s, Q barely moving). A warning: the samples may
//! still be played back (the bundled event keeps them, as RaPId's objective does).
//! [`check_unit`] warns about parameters far outside the model library's ranges and about
//! machine saturation data that is no magnetisation curve (`S(1.2) <= S(1.0)`).

use std::fmt;
use std::path::{Path, PathBuf};

use serde::Serialize;

use crate::event::{read_csv_channels, Event, Record, TimeBase, NON_UNIFORM_SPREAD};
use crate::unit::Unit;

/// Sample intervals above this many times the median interval are a gap.
pub const GAP_FACTOR: f64 = 5.0;
/// A gap above this many times the median interval (and above [`GAP_ERROR_MIN_S`]) is an error.
pub const GAP_ERROR_FACTOR: f64 = 100.0;
/// Gaps shorter than this are never errors.
pub const GAP_ERROR_MIN_S: f64 = 1.0;
/// |V| below this [pu] is "near zero" (a dropout when it lasts a sample or two).
pub const DROPOUT_PU: f64 = 0.05;
/// Plausible grid frequencies [Hz].
pub const FREQ_RANGE_HZ: (f64, f64) = (45.0, 65.0);
/// Plausible PMU sample intervals [s] (10 kHz to 1 sample/s).
pub const DT_RANGE_S: (f64, f64) = (1e-4, 1.0);
/// |V| above this [pu] in any sample is an error.
pub const V_MAX_PU: f64 = 3.0;
/// |P| or |Q| above this many times the machine rating in any sample is an error.
pub const PQ_ABSURD_RATING: f64 = 20.0;
/// Pre-event P above this many times the machine rating is an error (base mismatch).
pub const P_RATING_FACTOR: f64 = 1.2;
/// Pre-event P below this [pu of the machine rating] is a warning (absorbing P).
pub const P_ABSORB_PU: f64 = -0.02;
/// A one-sample jump of P or Q above this [pu of the machine rating] that comes straight back
/// is a warning (no machine follows it).
pub const SPIKE_PU: f64 = 1.0;
/// The least |ΔQ| / |ΔV| of a physical terminal-voltage change, per unit of the machine's
/// rating (the reactance behind the terminal is below 1 pu; see "Drop-outs at the record's
/// edges").
pub const DROPOUT_KAPPA: f64 = 1.0;
/// An edge drop-out's last (first) unfollowed |V| step lies within this many samples of the
/// record's end (start).
pub const DROPOUT_EDGE_SAMPLES: usize = 3;
/// Unfollowed |V| steps at most this far apart belong to the same drop-out, s.
pub const DROPOUT_GAP_S: f64 = 0.25;

/// How bad a finding is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Severity {
    Warning,
    Error,
}

/// One implausibility.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Finding {
    pub severity: Severity,
    /// Stable identifier: `time_gap`, `dropout`, `edge_dropout`, `angle_radians`, `frequency`,
    /// `time_scale`, `absorbing_p`, `above_rating`, `absurd_value`, `spike`, `parameter_range`,
    /// `saturation`, `model_missing`, `import` (an event's [`Event::import_notes`]).
    pub kind: &'static str,
    /// The file the data are in (the CSV, or the unit file).
    pub file: PathBuf,
    /// 1-based CSV line (header = line 1) of the first sample concerned, where known.
    pub line: Option<usize>,
    /// Time of the first sample concerned [s].
    pub time_s: Option<f64>,
    /// Column or parameter.
    pub column: String,
    pub message: String,
    /// What to do about it.
    pub fix: String,
}

impl fmt::Display for Finding {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.file.display())?;
        if let Some(l) = self.line {
            write!(f, " line {l}")?;
        }
        if let Some(t) = self.time_s {
            write!(f, " (t = {t} s)")?;
        }
        write!(f, ", {}: {}; fix: {}", self.column, self.message, self.fix)
    }
}

/// Whether any finding is an error.
pub fn has_errors(findings: &[Finding]) -> bool {
    findings.iter().any(|f| f.severity == Severity::Error)
}

struct Ctx<'a> {
    file: PathBuf,
    /// CSV line of each playback sample, when the CSV could be re-read.
    lines: Option<Vec<usize>>,
    rec: &'a Record,
    out: Vec<Finding>,
}

impl Ctx<'_> {
    #[allow(clippy::too_many_arguments)]
    fn push(
        &mut self,
        severity: Severity,
        kind: &'static str,
        k: Option<usize>,
        column: &str,
        message: String,
        fix: &str,
    ) {
        self.out.push(Finding {
            severity,
            kind,
            file: self.file.clone(),
            line: k.and_then(|k| self.lines.as_ref().and_then(|l| l.get(k).copied())),
            time_s: k.map(|k| self.rec.time_s[k]),
            column: column.into(),
            message,
            fix: fix.into(),
        });
    }
}

fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(|a, b| a.total_cmp(b));
    v[v.len() / 2]
}

/// The CSV as read: its header's columns, the 1-based line of each of its samples (blank lines
/// are skipped by the reader, so a sample's line is not simply its index + 2), every sample,
/// and the index of the first playback sample; `None` for in-memory events or a CSV that no
/// longer reads.
struct Layout {
    header: Vec<String>,
    /// Line of every sample of the file (header = line 1).
    lines: Vec<usize>,
    full: Record,
    /// Index in `full` of playback sample 0.
    offset: usize,
}

impl Layout {
    /// Line of sample `i` of the file.
    fn line(&self, i: usize) -> usize {
        self.lines.get(i).copied().unwrap_or(i + 2)
    }

    /// Lines of the playback samples.
    fn playback_lines(&self, n: usize) -> Vec<usize> {
        (0..n).map(|k| self.line(self.offset + k)).collect()
    }
}

fn csv_layout(event: &Event) -> Option<Layout> {
    if event.csv_path.as_os_str().is_empty() {
        return None;
    }
    let text = std::fs::read_to_string(&event.csv_path).ok()?;
    let header: Vec<String> = text
        .lines()
        .next()?
        .trim_start_matches('\u{feff}')
        .split(',')
        .map(|c| c.trim().to_string())
        .collect();
    let full = read_csv_channels(&event.csv_path, event.nominal_hz, !event.has_angle())
        .ok()?
        .0;
    let t0 = *event.record.time_s.first()?;
    let offset = full.time_s.iter().position(|t| *t == t0)?;
    // The reader's records and the file's lines: the same CSV settings, positions kept.
    let mut rdr = csv::ReaderBuilder::new()
        .has_headers(true)
        .flexible(true)
        .trim(csv::Trim::All)
        .from_reader(text.as_bytes());
    let lines: Vec<usize> = rdr
        .records()
        .map_while(|r| r.ok())
        .filter_map(|r| r.position().map(|p| p.line() as usize))
        .collect();
    let lines = if lines.len() == full.time_s.len() {
        lines
    } else {
        (0..full.time_s.len()).map(|i| i + 2).collect()
    };
    Some(Layout {
        header,
        lines,
        full,
        offset,
    })
}

/// Checks an event's playback record. `machine_mva` (the unit's rating) enables the checks
/// against the rating (base mismatch, absurd values, spikes; without it the system base is
/// used for the last two).
pub fn check_event(event: &Event, machine_mva: Option<f64>) -> Vec<Finding> {
    let layout = csv_layout(event);
    let file = if event.csv_path.as_os_str().is_empty() {
        event
            .toml_path
            .clone()
            .unwrap_or_else(|| PathBuf::from(format!("<in-memory event '{}'>", event.name)))
    } else {
        event.csv_path.clone()
    };
    let rec = &event.record;
    let n = rec.time_s.len();
    let mut c = Ctx {
        file,
        lines: layout.as_ref().map(|l| l.playback_lines(n)),
        rec,
        out: vec![],
    };
    // What the import found wrong with the recording (a data file shorter than its header
    // declares), said again wherever the event is used: the record no longer shows it.
    for note in &event.import_notes {
        c.out.push(Finding {
            severity: Severity::Warning,
            kind: "import",
            file: event.toml_path.clone().unwrap_or_else(|| c.file.clone()),
            line: None,
            time_s: None,
            column: "import_notes".into(),
            message: note.clone(),
            fix: "import the whole recording again (the recorder's complete file); \
                  `import --refuse-truncated` refuses such a record"
                .into(),
        });
    }
    if n < 3 {
        return c.out;
    }
    // Time axis: scale, then gaps.
    let mut dts: Vec<f64> = rec.time_s.windows(2).map(|w| w[1] - w[0]).collect();
    let dt = median(&mut dts.clone());
    if !(dt >= DT_RANGE_S.0 && dt <= DT_RANGE_S.1) {
        let hint = if dt > DT_RANGE_S.1 && dt < 1000.0 {
            "the time column looks like milliseconds: divide it by 1000"
        } else if dt < DT_RANGE_S.0 {
            "the time column looks scaled (nanoseconds? a factor applied twice?): give time_s in seconds"
        } else {
            "give time_s in seconds"
        };
        c.push(
            Severity::Error,
            "time_scale",
            Some(0),
            "time_s",
            format!(
                "median sample interval {dt:e} s: PMU records have {} to {} s",
                DT_RANGE_S.0, DT_RANGE_S.1
            ),
            hint,
        );
        // Every later check assumes a sane time axis.
        return c.out;
    }
    for (k, d) in dts.iter_mut().enumerate() {
        if *d > GAP_FACTOR * dt {
            let error = *d > GAP_ERROR_FACTOR * dt && *d > GAP_ERROR_MIN_S;
            c.push(
                if error { Severity::Error } else { Severity::Warning },
                "time_gap",
                Some(k + 1),
                "time_s",
                format!(
                    "a gap of {:.6} s before this sample ({:.0} × the median interval {dt:.6} s); the playback interpolates |V| and the angle linearly across it",
                    *d,
                    *d / dt
                ),
                "trim [playback] to one side of the gap, or split the record into two events",
            );
        }
    }
    // An uneven time base not declared as such (a recorder's trend, not a PMU): kept as recorded
    // either way, but said, so that the event file states it.
    if event.time_base == TimeBase::Uniform {
        let even: Vec<f64> = rec
            .time_s
            .windows(2)
            .map(|w| w[1] - w[0])
            .filter(|d| *d <= GAP_FACTOR * dt)
            .collect();
        let uneven = even
            .iter()
            .filter(|d| (**d - dt).abs() > NON_UNIFORM_SPREAD * dt)
            .count();
        if uneven * 10 > even.len() {
            let lo = even.iter().copied().fold(f64::INFINITY, f64::min);
            let hi = even.iter().copied().fold(0.0, f64::max);
            c.push(
                Severity::Warning,
                "non_uniform_time",
                Some(0),
                "time_s",
                format!(
                    "{uneven} of {} sample intervals differ from the median {:.3} ms by more than \
                     {:.0} % ({:.3}-{:.3} ms): the time base is not uniform",
                    even.len(),
                    dt * 1e3,
                    NON_UNIFORM_SPREAD * 100.0,
                    lo * 1e3,
                    hi * 1e3
                ),
                "declare time_base = \"non_uniform\" in the event file (the stamps are kept as recorded either way; a stage's lowpass_hz needs uniform stamps)",
            );
        }
    }
    // Base: the pre-event P and Q against the machine's rating. Checked before the absurd
    // magnitudes so that a whole column on the wrong base is named as such (its fix is the base,
    // not a sample), unless an absurd sample in the init window would make the mean meaningless.
    let rating = machine_mva.filter(|m| *m > 0.0).unwrap_or(event.system_mva);
    let pq_max = PQ_ABSURD_RATING * rating / event.system_mva;
    let init_sane = (0..n)
        .filter(|&k| rec.time_s[k] >= event.init.start_s && rec.time_s[k] <= event.init.end_s)
        .all(|k| rec.p_pu[k].abs() <= pq_max && rec.q_pu[k].abs() <= pq_max);
    let op = event.operating_point();
    if let (Some(m), true) = (machine_mva.filter(|m| *m > 0.0), init_sane) {
        let s = op.p_pu.hypot(op.q_pu) * event.system_mva;
        if s > P_RATING_FACTOR * m {
            c.push(
                Severity::Error,
                "above_rating",
                Some(0),
                "p_pu",
                format!(
                    "the pre-event apparent power {s:.1} MVA (P {:.4} pu, Q {:.4} pu on {} MVA) exceeds the machine's rating {m} MVA by {:.0} %",
                    op.p_pu,
                    op.q_pu,
                    event.system_mva,
                    (s / m - 1.0) * 100.0
                ),
                "P and Q must be per unit on the event's system_mva base: if they are on another base (the machine's, say), set system_mva to that base or convert the columns",
            );
        }
    }
    // Absurd magnitudes (one sample of 1e300, |V| in the wrong unit...).
    for (col, v, lim) in [
        ("|V|", &rec.v_mag_pu, V_MAX_PU),
        ("p_pu", &rec.p_pu, pq_max),
        ("q_pu", &rec.q_pu, pq_max),
    ] {
        if let Some(k) = v.iter().position(|x| !(x.abs() <= lim)) {
            c.push(
                Severity::Error,
                "absurd_value",
                Some(k),
                col,
                format!(
                    "{} is far beyond anything a unit of {rating} MVA records (limit {lim:.3} pu on {} MVA)",
                    short(v[k]),
                    event.system_mva
                ),
                "correct or remove the sample in the CSV",
            );
        }
    }
    if has_errors(&c.out) {
        return c.out;
    }
    // Dropouts: |V| near zero for one or two samples between normal ones.
    let mut k = 0;
    while k < n {
        if rec.v_mag_pu[k] < DROPOUT_PU {
            let start = k;
            while k < n && rec.v_mag_pu[k] < DROPOUT_PU {
                k += 1;
            }
            let len = k - start;
            let before = start > 0 && rec.v_mag_pu[start - 1] > 0.5;
            let after = k < n && rec.v_mag_pu[k] > 0.5;
            if len <= 2 && (before || start == 0) && (after || k == n) {
                c.push(
                    Severity::Error,
                    "dropout",
                    Some(start),
                    "|V|",
                    format!(
                        "|V| = {:.4} pu for {len} sample(s) between normal samples: a PMU dropout, which the playback would play as a bolted fault",
                        rec.v_mag_pu[start]
                    ),
                    "remove the sample(s) or replace them by interpolated values in the CSV",
                );
            }
        } else {
            k += 1;
        }
    }
    // Angle units: an angle_deg column that holds radians wraps at ±π, not ±180.
    if let Some(layout) = &layout {
        if layout.header.iter().any(|h| h == "angle_deg") {
            let deg: Vec<f64> = layout
                .full
                .v_ang_rad
                .iter()
                .map(|a| a.to_degrees())
                .collect();
            let max = deg.iter().fold(0.0f64, |m, a| m.max(a.abs()));
            let wraps = deg
                .windows(2)
                .position(|w| ((w[1] - w[0]).abs() - std::f64::consts::TAU).abs() < 0.5);
            if max <= std::f64::consts::PI + 1e-6 {
                let (sev, msg) = match wraps {
                    Some(i) => (
                        Severity::Error,
                        format!(
                            "the angle stays within ±π and jumps by 2π at line {}: the column holds radians",
                            layout.line(i + 1)
                        ),
                    ),
                    None => (
                        Severity::Warning,
                        "every angle lies within ±π (±3.14°): the column may hold radians".into(),
                    ),
                };
                c.out.push(Finding {
                    severity: sev,
                    kind: "angle_radians",
                    file: c.file.clone(),
                    line: Some(1),
                    time_s: None,
                    column: "angle_deg".into(),
                    message: msg,
                    fix: "convert the column to degrees, or rename it if it is in degrees already"
                        .into(),
                });
            }
        }
    }
    // Frequency: the measured channel, and the operating point's (from the angle's slope).
    if let Some(f) = &rec.freq_hz {
        if let Some(k) = f
            .iter()
            .position(|x| !(*x >= FREQ_RANGE_HZ.0 && *x <= FREQ_RANGE_HZ.1))
        {
            c.push(
                Severity::Error,
                "frequency",
                Some(k),
                "freq_hz",
                format!(
                    "{} Hz lies outside {}-{} Hz",
                    f[k], FREQ_RANGE_HZ.0, FREQ_RANGE_HZ.1
                ),
                "check the column's unit (Hz) and the sample",
            );
        }
    }
    if !(op.freq_hz >= FREQ_RANGE_HZ.0 && op.freq_hz <= FREQ_RANGE_HZ.1) {
        c.push(
            Severity::Error,
            "frequency",
            Some(0),
            "angle",
            format!(
                "the initial frequency from the angle's slope over the init window [{}, {}] s is {:.6e} Hz, outside {}-{} Hz",
                event.init.start_s, event.init.end_s, op.freq_hz, FREQ_RANGE_HZ.0, FREQ_RANGE_HZ.1
            ),
            "check the time column's unit (seconds) and the angle's unit (degrees in angle_deg)",
        );
    }
    // Sign convention and base.
    let p_mach = op.p_pu * event.system_mva;
    if op.p_pu < P_ABSORB_PU * rating / event.system_mva {
        c.push(
            Severity::Warning,
            "absorbing_p",
            Some(0),
            "p_pu",
            format!(
                "the unit absorbs {:.1} MW before the event (mean P {:.4} pu): generator convention is P delivered > 0",
                -p_mach, op.p_pu
            ),
            "if P and Q have the load convention, negate both columns; a pump or motor is not a generating unit's model",
        );
    }
    // One-sample spikes of P or Q that come straight back.
    let spike = SPIKE_PU * rating / event.system_mva;
    for (col, v) in [("p_pu", &rec.p_pu), ("q_pu", &rec.q_pu)] {
        for k in 1..n - 1 {
            let (a, b, x) = (v[k - 1], v[k + 1], v[k]);
            let out = (x - 0.5 * (a + b)).abs();
            if out > spike && (a - b).abs() < 0.1 * out {
                c.push(
                    Severity::Warning,
                    "spike",
                    Some(k),
                    col,
                    format!(
                        "{x:.4} pu between {a:.4} and {b:.4}: a one-sample step of {:.2} × the rating that no machine could follow",
                        out / (rating / event.system_mva)
                    ),
                    "check the sample; remove or interpolate it if it is a recording error",
                );
                break;
            }
        }
    }
    // Drop-outs at the record's edges: |V| steps the unit's Q does not follow.
    let s_ref = match machine_mva.filter(|m| *m > 0.0) {
        Some(m) => m / event.system_mva,
        None => op.p_pu.hypot(op.q_pu),
    };
    for span in edge_dropouts(rec, s_ref) {
        let (a, b) = (span.first, span.last);
        let (v_lo, v_hi) = rec.v_mag_pu[a..=b]
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), v| {
                (l.min(*v), h.max(*v))
            });
        let edge = if span.at_end { "ends" } else { "starts" };
        let fix = if span.at_end {
            format!(
                "end [playback] (or [fit]) before {} s, or remove these samples: as they are, the playback drives the model with a voltage the unit never saw",
                rec.time_s[a]
            )
        } else {
            format!(
                "start [playback] (or [fit]) after {} s, or remove these samples: as they are, the playback drives the model with a voltage the unit never saw",
                rec.time_s[b]
            )
        };
        c.push(
            Severity::Warning,
            "edge_dropout",
            Some(a),
            "|V|",
            format!(
                "the record {edge} in a measurement drop-out: from {} to {} s ({} samples) |V| jumps by up to {:.4} pu from one sample to the next ({:.4}-{:.4} pu, {} steps beyond noise) while Q moves by at most {:.4} pu; a terminal-voltage step of ΔV moves a machine's Q by at least {DROPOUT_KAPPA} × ΔV × its rating ({:.3} pu on {} MVA) at once, here at least {:.4} pu",
                rec.time_s[a],
                rec.time_s[b],
                b - a + 1,
                span.max_dv,
                v_lo,
                v_hi,
                span.steps,
                span.max_dq,
                s_ref,
                event.system_mva,
                DROPOUT_KAPPA * s_ref * span.max_dv
            ),
            &fix,
        );
    }
    c.out
}

/// Median sample interval, s.
fn median_dt(rec: &Record) -> f64 {
    let mut d: Vec<f64> = rec.time_s.windows(2).map(|w| w[1] - w[0]).collect();
    median(&mut d)
}

/// A run of |V| samples at an edge of the record that the unit's Q does not follow.
struct EdgeSpan {
    /// First and last sample of the span.
    first: usize,
    last: usize,
    at_end: bool,
    /// Unfollowed |V| steps in it, the largest of them, and the largest Q step near them.
    steps: usize,
    max_dv: f64,
    max_dq: f64,
}

/// The record's edge drop-outs (see "Drop-outs at the record's edges"); `s_ref` is the
/// machine's rating on the system base (or a lower bound of it).
fn edge_dropouts(rec: &Record, s_ref: f64) -> Vec<EdgeSpan> {
    use crate::event::{normal_upper_quantile, quantum, robust_sd};
    let n = rec.len();
    if n < 8 || !(s_ref > 0.0) {
        return vec![];
    }
    let (v, q) = (&rec.v_mag_pu, &rec.q_pu);
    // Noise of one-sample changes, from second differences (σ_Δ = MAD(Δ²)·1.4826/√3).
    let sd_step = |x: &[f64]| {
        let d2: Vec<f64> = x.windows(3).map(|w| w[2] - 2.0 * w[1] + w[0]).collect();
        (robust_sd(&d2) / 3f64.sqrt())
            .max(quantum(x) / 6f64.sqrt())
            .max(1e-9)
    };
    let (sd_v, sd_q) = (sd_step(v), sd_step(q));
    let z = normal_upper_quantile(0.01 / (2.0 * (n - 1) as f64));
    // Testable steps k (between k-1 and k): Some(followed).
    let dq = |k: usize| (q[k] - q[k - 1]).abs();
    let mut steps: Vec<(usize, bool, f64, f64)> = vec![]; // (k, followed, |ΔV|, max |ΔQ| near)
    for k in 1..n {
        let dv = (v[k] - v[k - 1]).abs();
        let implied = DROPOUT_KAPPA * s_ref * dv;
        if dv > z * sd_v && implied > 4.0 * sd_q {
            let near = (k.saturating_sub(2).max(1)..(k + 3).min(n))
                .map(dq)
                .fold(0.0_f64, f64::max);
            steps.push((k, near >= 0.5 * implied, dv, near));
        }
    }
    let mut out = vec![];
    let span = |run: &[(usize, bool, f64, f64)]| {
        (
            run.len(),
            run.iter().fold(0.0_f64, |m, s| m.max(s.2)),
            run.iter().fold(0.0_f64, |m, s| m.max(s.3)),
        )
    };
    // The unfollowed steps chained to an edge: none followed, none more than DROPOUT_GAP_S
    // from the next.
    let gap = ((DROPOUT_GAP_S / median_dt(rec)).round() as usize).max(1);
    if let Some(&(k, false, _, _)) = steps.last() {
        if k + DROPOUT_EDGE_SAMPLES >= n {
            let mut from = steps.len() - 1;
            while from > 0 && !steps[from - 1].1 && steps[from].0 - steps[from - 1].0 <= gap {
                from -= 1;
            }
            let run = &steps[from..];
            let (count, max_dv, max_dq) = span(run);
            out.push(EdgeSpan {
                first: run[0].0,
                last: n - 1,
                at_end: true,
                steps: count,
                max_dv,
                max_dq,
            });
        }
    }
    if let Some(&(k, false, _, _)) = steps.first() {
        if k <= DROPOUT_EDGE_SAMPLES {
            let mut to = 0;
            while to + 1 < steps.len() && !steps[to + 1].1 && steps[to + 1].0 - steps[to].0 <= gap {
                to += 1;
            }
            let run = &steps[..=to];
            let (count, max_dv, max_dq) = span(run);
            out.push(EdgeSpan {
                first: 0,
                last: run[to].0,
                at_end: false,
                steps: count,
                max_dv,
                max_dq,
            });
        }
    }
    out
}

/// A number as written by hand: plain when moderate, in exponent form when huge or tiny (1e308,
/// not 309 digits).
fn short(v: f64) -> String {
    if v == 0.0 || !v.is_finite() || (1e-4..1e6).contains(&v.abs()) {
        format!("{v}")
    } else {
        format!("{v:e}")
    }
}

/// Whether `v` lies far outside the typical range `(lo, hi)`: more than the range's own width
/// beyond either end (or is not a number). A range that is not one (infinite or empty) holds
/// every value. The one rule behind the plausibility warnings and the diagnosis's note of
/// re-freed values absorbed far from their datasheet: a width beyond the range is outside the
/// spread of the library's sample data by as much as that spread itself, a unit-conversion or
/// model-form error rather than an unusual design.
pub fn far_outside_range(v: f64, (lo, hi): (f64, f64)) -> bool {
    if !(lo.is_finite() && hi.is_finite() && hi > lo) {
        return false;
    }
    let w = hi - lo;
    !(v >= lo - w && v <= hi + w)
}

/// Parameters of `unit` far outside the model library's typical ranges (more than a range's
/// width beyond it): warnings naming the file and the parameter.
/// Also saturation data that is no curve (`S(1.0) > 0`, `S(1.2) <= S(1.0)`).
pub fn check_unit(unit: &Unit, file: &Path) -> Vec<Finding> {
    let mut out = vec![];
    for l in &unit.lacks {
        out.push(Finding {
            severity: Severity::Warning,
            kind: "model_missing",
            file: file.to_path_buf(),
            line: None,
            time_s: None,
            column: "lacks".into(),
            message: format!("the unit lacks a model of its source: {l}"),
            fix: "the results are those of a unit without it: add the model to the library (docs/model-library.md) or model it with a diagram".into(),
        });
    }
    for (path, spec, v) in unit.params() {
        let (lo, hi) = spec.range;
        if far_outside_range(v, spec.range) {
            out.push(Finding {
                severity: Severity::Warning,
                kind: "parameter_range",
                file: file.to_path_buf(),
                line: None,
                time_s: None,
                column: path.clone(),
                message: format!(
                    "{} {} lies far outside the library's typical range {lo}-{hi} ({})",
                    short(v),
                    spec.unit,
                    spec.doc
                ),
                fix: "check the value and its unit (itaipu-calib models shows every range)".into(),
            });
        }
    }
    out.extend(check_saturation(unit, file));
    out.extend(check_relations(unit, file));
    out
}

/// How close to 1 the ratio of two parameters a machine model requires in order (`X'_d < X_d`,
/// …) may come before it is reported as pressed against the relation: within 1 %. The model
/// refuses equality, so a fit that wants to cross the relation stops just short of it, as one
/// that wants to cross a bound stops on it; the values are then held by the relation, not by the
/// data.
pub const RELATION_MARGIN: f64 = 0.01;

/// The order relations of a machine's parameters (`smaller`, `larger`, what the pair is) that
/// [`check_relations`] checks, where the unit's machine has both.
const RELATIONS: &[(&str, &str, &str)] = &[
    (
        "x_d_prime",
        "x_d",
        "the field winding no longer separates the transient from the synchronous reactance",
    ),
    (
        "x_d_pp",
        "x_d_prime",
        "the damper winding no longer separates the subtransient from the transient reactance",
    ),
    (
        "t_d0_pp",
        "t_d0_prime",
        "the subtransient and transient time constants are no longer separate dynamics",
    ),
    (
        "x_q_pp",
        "x_q",
        "the q-axis damper no longer separates the subtransient from the synchronous reactance",
    ),
];

/// Warns about a machine whose ordered parameters (`X_d > X'_d > X''_d`, `T'_d0 > T''_d0`,
/// `X_q > X''_q`) come within [`RELATION_MARGIN`] of equality: a degenerate machine (typically a
/// calibrated one whose data or bounds do not pin it).
pub fn check_relations(unit: &Unit, file: &Path) -> Vec<Finding> {
    let mut out = vec![];
    let params = unit.params();
    let get = |path: &str| params.iter().find(|(p, _, _)| p == path).map(|t| t.2);
    for inst in unit.instances() {
        let m = &inst.name;
        for (small, large, what) in RELATIONS {
            let (ps, pl) = (format!("{m}.{small}"), format!("{m}.{large}"));
            let (Some(a), Some(b)) = (get(&ps), get(&pl)) else {
                continue;
            };
            if b > 0.0 && a / b > 1.0 - RELATION_MARGIN {
                out.push(Finding {
                    severity: Severity::Warning,
                    kind: "degenerate_relation",
                    file: file.to_path_buf(),
                    line: None,
                    time_s: None,
                    column: ps.clone(),
                    message: format!(
                        "{ps} = {} is within {:.0} % of {pl} = {} (the model requires {ps} < \
                         {pl}): {what}; the value is held by the relation, not by the data",
                        short(a),
                        100.0 * RELATION_MARGIN,
                        short(b)
                    ),
                    fix: "narrow the bounds of the pair, fix one of them, or give the fit a \
                          datasheet prior (calibration.prior) so that the data's silence does not \
                          push the machine onto the relation"
                        .into(),
                });
            }
        }
    }
    out
}

/// Whether the saturation factors S(1.0), S(1.2) describe a magnetisation curve: iron saturates
/// more the higher the flux, so the factor grows, `S(1.2) > S(1.0)`; or `S(1.0) = 0`, the usual
/// way of writing "no saturation". (Open-circuit data put S(1.2) at 3-5 × S(1.0).) The one
/// criterion of the unit checks below and of the diagnosis's saturation cause.
pub fn is_magnetisation_curve(s10: f64, s12: f64) -> bool {
    s10 <= 0.0 || s12 > s10
}

/// Machine saturation data that is no magnetisation curve: `S(1.2) <= S(1.0)` with `S(1.0) > 0`
/// (saturation that does not grow with flux; with S(1.0) = S(1.2) GENSAE's exponential curve is
/// `Se = S(1.0)` at every flux, RaPId's Itaipu `S10 = S12 = 1` among them). `S(1.0) = 0` is
/// the usual way of writing "no saturation" and is not flagged.
fn check_saturation(unit: &Unit, file: &Path) -> Vec<Finding> {
    let mut out = vec![];
    for inst in unit.instances() {
        let ps = inst.block.params();
        let (Some(i10), Some(i12)) = (ps.index_of("s10"), ps.index_of("s12")) else {
            continue;
        };
        let (s10, s12) = (ps.get(i10), ps.get(i12));
        if !is_magnetisation_curve(s10, s12) {
            // GENSAE's curve is S(1.0)·ψⁿ, n = ln(S12/S10)/ln 1.2: flat or falling with flux.
            let shape = if inst.block.model() == "GENSAE" {
                format!(
                    "; GENSAE's exponential curve is then S(1.0)·ψ^n with n = {}{}",
                    short((s12 / s10).ln() / 1.2f64.ln()),
                    if s12 == s10 {
                        format!(": Se = {} at every flux level", short(s10))
                    } else {
                        String::new()
                    }
                )
            } else {
                String::new()
            };
            out.push(Finding {
                severity: Severity::Warning,
                kind: "saturation",
                file: file.to_path_buf(),
                line: None,
                time_s: None,
                column: format!("{}.s12", inst.name),
                message: format!(
                    "S(1.0) = {} and S(1.2) = {}: a saturation factor that does not grow from 1.0 to 1.2 pu flux is no magnetisation curve{shape}",
                    short(s10),
                    short(s12),
                ),
                fix: "take S(1.0) < S(1.2) from the open-circuit curve (typically 0.05-0.2 and 0.2-0.6), or S(1.0) = 0 for no saturation".into(),
            });
        }
    }
    out
}

/// Where a run-time failure at time `t_s` points in the data: the nearest sample's CSV line
/// (or time) and values, and the one before it, so that a failure caused by a sample (say one
/// of 1e300) names it.
pub fn locate_time(event: &Event, t_s: f64) -> String {
    let rec = &event.record;
    let n = rec.time_s.len();
    if n == 0 || !t_s.is_finite() {
        return String::new();
    }
    let k = rec.time_s.partition_point(|t| *t < t_s).min(n - 1);
    let k = if k > 0 && (rec.time_s[k] - t_s).abs() > (t_s - rec.time_s[k - 1]).abs() {
        k - 1
    } else {
        k
    };
    let lines = csv_layout(event).map(|l| l.playback_lines(n));
    let at = |i: usize| match &lines {
        Some(l) => format!("line {} (t = {} s)", l[i], rec.time_s[i]),
        None => format!("sample {i} (t = {} s)", rec.time_s[i]),
    };
    let vals = |i: usize| {
        format!(
            "|V| {} pu, angle {} rad, P {} pu, Q {} pu",
            rec.v_mag_pu[i], rec.v_ang_rad[i], rec.p_pu[i], rec.q_pu[i]
        )
    };
    let mut s = format!(
        "the record there: {} of {}: {}",
        at(k),
        event.csv_path.display(),
        vals(k)
    );
    if k > 0 {
        s.push_str(&format!("; before it, {}: {}", at(k - 1), vals(k - 1)));
    }
    s
}

/// The operating point the initialisation was given, from the event's init window, on the
/// system and the machine base: what to check when a unit cannot initialise (an E_fd0 beyond
/// the ceiling from P and Q on the wrong base, say).
pub fn describe_operating_point(event: &Event, machine_mva: f64) -> String {
    let op = event.operating_point();
    let k = if machine_mva > 0.0 {
        event.system_mva / machine_mva
    } else {
        f64::NAN
    };
    format!(
        "the operating point from the init window [{}, {}] s of {}: |V| {:.4} pu, P {:.4} pu, Q {:.4} pu on {} MVA (P {:.4} pu, Q {:.4} pu on the machine's {} MVA), f {:.4} Hz; check the columns' units and bases",
        event.init.start_s,
        event.init.end_s,
        event.csv_path.display(),
        op.v_mag_pu,
        op.p_pu,
        op.q_pu,
        event.system_mva,
        op.p_pu * k,
        op.q_pu * k,
        machine_mva,
        op.freq_hz
    )
}
