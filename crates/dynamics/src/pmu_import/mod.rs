//! Import of PMU and recorder files into an [`Event`]: C37.118-style CSV exports ([`c37`]) and
//! COMTRADE 1991/1999/2013 `.cfg` + `.dat`, ASCII, BINARY, BINARY32 and FLOAT32 ([`comtrade`]).
//!
//! Both readers find, by column or channel name, a voltage phasor, a current phasor (magnitude
//! and angle, or real and imaginary parts) and optionally a frequency:
//!
//! | role      | names (case-insensitive; `.`, `-`, blanks read as `_`)                       |
//! |-----------|-------------------------------------------------------------------------------|
//! | voltage   | `v`, `v1`, `vpos`, `u`, `u1` (positive sequence), else `va`, `ua` (phase A)   |
//! | current   | `i`, `i1`, `ipos` (positive sequence), else `ia` (phase A)                    |
//! | part      | a last word `mag`/`magnitude`/`abs`, `ang`/`angle`/`phase`, `re`/`real`, `im`/`imag` |
//! | frequency | `freq`, `frequency`, `f`                                                      |
//!
//! e.g. `v1_mag_kv`, `VA.ang [deg]`, `i_re_a`. The unit is a last word or a bracket (`kv`, `v`,
//! `pu` for voltages; `a`, `ka`, `pu` for currents; `deg`, `rad` for angles; `hz`); COMTRADE
//! takes it from the channel's unit field. `map` renames a column or channel to one of these
//! names (`v_mag_kv=STN.VPM`) for exports that name them otherwise. Phase-A phasors are taken
//! for a balanced unit (S = 3 V_a I_a*), with a warning.
//!
//! **Bases** ([`ImportOptions`]): `system_mva` (the event's P, Q base), `v_base_kv` (rated
//! line-to-line voltage, for voltages in V or kV), `pu_base_mva` (the MVA base of currents and
//! voltages given in pu; default `system_mva`). Voltages are phase-to-neutral phasors (C37.118)
//! unless `line_voltage` (then `V_an = V_ab/√3 ∠−30°`). P + jQ = 3 V I* (physical) or V I* (pu)
//! in generator convention: the current flows out of the machine into the grid unless
//! `current_into_machine`.
//!
//! **Gaps and dropouts.** A sample interval above 1.5 times the PMU's (median) interval is a
//! gap, reported with the number of missing samples; a sample flagged bad (C37.118 `STAT` data
//! error bits, COMTRADE missing-data codes, empty or NaN fields, |V| = 0) is a dropout,
//! reported and removed. The event keeps the PMU's own time stamps (the playback interpolates
//! across a gap), or with `rate_hz` is resampled to a uniform grid: linear interpolation of |V|,
//! the unwrapped angle, P, Q and f, and when the new rate is lower, the mean of the samples
//! within half an output interval (a boxcar against aliasing).
//!
//! **Onset and init window.** The event's onset is detected on the imported record (the one
//! detector of [`crate::event::detect_onset`]) and, with the pre-event init window it implies
//! (from the start to a few samples before it), reported and written into `event.toml` as
//! explicit keys with a comment saying they were detected and how to override them.
//!
//! Layout: this file holds the options, the report, the conversion of assigned samples into the
//! event ([`import`], [`write_event_folder`]) and the resampling; `names.rs` recognises and
//! assigns the columns and channels by name; `time.rs` parses and formats time stamps.

use std::fmt;
use std::path::{Path, PathBuf};

use crate::event::{format_g17, unwrap_angles, Event, EventError, Record, ONSET_GUARD_SAMPLES};

pub mod c37;
pub mod comtrade;
mod names;
mod time;

pub(crate) use names::assign;
use names::{Assignment, ChanUnit};
use time::shift_iso;
pub(crate) use time::{days_from_civil, parse_hms};
pub use time::{format_iso, parse_iso};

/// How to turn phasors into the event's per-unit quantities.
#[derive(Debug, Clone, PartialEq)]
pub struct ImportOptions {
    /// Event name (default: the file stem).
    pub name: Option<String>,
    /// MVA base of the event's P and Q.
    pub system_mva: f64,
    /// Nominal frequency, Hz.
    pub nominal_hz: f64,
    /// Rated line-to-line voltage, kV (needed for voltages in V or kV).
    pub v_base_kv: Option<f64>,
    /// MVA base of channels given in pu (default `system_mva`).
    pub pu_base_mva: Option<f64>,
    /// Voltage phasors are line-to-line (V_ab) rather than phase-to-neutral.
    pub line_voltage: bool,
    /// The current is measured flowing into the machine (P, Q are negated).
    pub current_into_machine: bool,
    /// Resample to this rate [samples/s]; `None` keeps the PMU's time stamps.
    pub rate_hz: Option<f64>,
    /// `(name, column)`: the column or channel `column` is read as `name`.
    pub map: Vec<(String, String)>,
    /// Refuse a recording whose data file holds fewer samples than its header declares (a
    /// COMTRADE `.dat` cut short): an error instead of a warning.
    pub refuse_truncated: bool,
}

impl ImportOptions {
    /// Options with the given bases, everything else by default.
    pub fn new(system_mva: f64, nominal_hz: f64) -> Self {
        ImportOptions {
            name: None,
            system_mva,
            nominal_hz,
            v_base_kv: None,
            pu_base_mva: None,
            line_voltage: false,
            current_into_machine: false,
            rate_hz: None,
            map: vec![],
            refuse_truncated: false,
        }
    }
}

/// A failed import. Messages name the file and the line (CSV, `.cfg`, ASCII `.dat`), the
/// record (binary `.dat`) or the option.
#[derive(Debug, thiserror::Error)]
pub enum ImportError {
    #[error("{}: cannot read: {source}", path.display())]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    /// Bad data in a file; `at` is e.g. `line 12, column v_mag_kv` or `record 7`.
    #[error("{}{}: {msg}", path.display(), at.as_ref().map(|a| format!(" {a}")).unwrap_or_default())]
    Data {
        path: PathBuf,
        at: Option<String>,
        msg: String,
    },
    /// A missing or wrong option (a base, a resampling rate, a map entry).
    #[error("{}: {option}: {msg}", path.display())]
    Options {
        path: PathBuf,
        option: String,
        msg: String,
    },
    /// The imported record fails the event checks (units, time, windows).
    #[error("{}: the imported record is not a usable event: {source}", path.display())]
    Event {
        path: PathBuf,
        source: Box<EventError>,
    },
}

impl ImportError {
    /// Short identifier of the error kind.
    pub fn kind(&self) -> &'static str {
        match self {
            ImportError::Io { .. } => "io",
            ImportError::Data { .. } => "data",
            ImportError::Options { .. } => "options",
            ImportError::Event { .. } => "event",
        }
    }
    pub(crate) fn data(path: &Path, at: Option<String>, msg: impl Into<String>) -> Self {
        ImportError::Data {
            path: path.into(),
            at,
            msg: msg.into(),
        }
    }
}

/// A run of missing samples.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Gap {
    /// Time of the last sample before the gap and of the first after, s (event time axis).
    pub from_s: f64,
    pub to_s: f64,
    /// Samples missing at the PMU's rate.
    pub missing: usize,
    /// Where the gap ends in the source (`line 120`, `record 119`).
    pub at: String,
}

/// A sample flagged bad and removed.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Dropout {
    pub time_s: f64,
    pub at: String,
    pub reason: String,
}

/// What an import did.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct ImportReport {
    pub source: PathBuf,
    /// e.g. `C37.118 CSV`, `COMTRADE 1999 BINARY`.
    pub format: String,
    /// Absolute time of the event's t = 0 (ISO 8601), when the source has one.
    pub start: Option<String>,
    /// Samples read, and kept (after dropouts).
    pub samples_read: usize,
    pub samples_kept: usize,
    /// Samples the source's header declares (a COMTRADE `.cfg`'s rate table), when it does: more
    /// than `samples_read` is a truncated data file ([`truncation_note`]).
    pub samples_declared: Option<usize>,
    /// The PMU's rate (from the median interval), samples/s.
    pub source_rate_hz: f64,
    /// The event's rate when resampled.
    pub resampled_hz: Option<f64>,
    /// Columns or channels used, as `role <- name [unit]`.
    pub channels: Vec<String>,
    pub gaps: Vec<Gap>,
    pub dropouts: Vec<Dropout>,
    pub warnings: Vec<String>,
    /// The event's onset, s, as detected on the imported record (`None`: no disturbance found).
    pub onset_s: Option<f64>,
    /// Why: the detector's evidence, one line.
    pub onset: String,
    /// The init window it implies, `[start_s, end_s]`.
    pub init_s: [f64; 2],
}

impl fmt::Display for ImportReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "import {} ({}): {} samples read, {} kept, {:.3} samples/s{}{}",
            self.source.display(),
            self.format,
            self.samples_read,
            self.samples_kept,
            self.source_rate_hz,
            self.resampled_hz
                .map(|r| format!(", resampled to {r} samples/s"))
                .unwrap_or_default(),
            self.start
                .as_ref()
                .map(|s| format!(", t = 0 at {s}"))
                .unwrap_or_default()
        )?;
        writeln!(f, "  channels: {}", self.channels.join("; "))?;
        for g in &self.gaps {
            writeln!(
                f,
                "  gap: {:.6}-{:.6} s, {} sample(s) missing (before {})",
                g.from_s, g.to_s, g.missing, g.at
            )?;
        }
        for d in &self.dropouts {
            writeln!(f, "  dropout: {:.6} s ({}): {}", d.time_s, d.at, d.reason)?;
        }
        for w in &self.warnings {
            writeln!(f, "  warning: {w}")?;
        }
        match self.onset_s {
            Some(t) => writeln!(
                f,
                "  onset: {t:.4} s, init window [{}, {:.4}] s (pre-event, ends {ONSET_GUARD_SAMPLES} samples before the onset); {}",
                self.init_s[0], self.init_s[1], self.onset
            )?,
            None => writeln!(
                f,
                "  onset: none, init window [{}, {:.4}] s (the default); {}",
                self.init_s[0], self.init_s[1], self.onset
            )?,
        }
        Ok(())
    }
}

/// A usable sample: (t, |V| pu, angle rad, P pu, Q pu, f Hz, location).
type Kept = (f64, f64, f64, f64, f64, Option<f64>, String);

/// One sample in source units (as assigned), or why it is bad.
pub(crate) struct RawSample {
    /// Absolute time: whole seconds and fraction (keeps µs over epoch times).
    pub sec: i64,
    pub frac: f64,
    /// Values by slot (NaN = absent in this sample).
    pub vals: [f64; 9],
    /// Where it is (`line 12`, `record 11`).
    pub at: String,
    /// Set when the source flags the sample bad.
    pub bad: Option<String>,
}

/// Turns raw samples into the event and the report (shared by both readers).
pub(crate) fn finish(
    path: &Path,
    format: String,
    start: Option<String>,
    a: &Assignment,
    samples: Vec<RawSample>,
    opts: &ImportOptions,
    mut warnings: Vec<String>,
) -> Result<(Event, ImportReport), ImportError> {
    let opt = |o: &str, m: String| ImportError::Options {
        path: path.into(),
        option: o.into(),
        msg: m,
    };
    if !(opts.system_mva.is_finite() && opts.system_mva > 0.0) {
        return Err(opt(
            "system_mva",
            format!("must be > 0 MVA (got {})", opts.system_mva),
        ));
    }
    if !(opts.nominal_hz.is_finite() && opts.nominal_hz > 0.0) {
        return Err(opt(
            "nominal_hz",
            format!("must be > 0 Hz (got {})", opts.nominal_hz),
        ));
    }
    let pu_base = opts.pu_base_mva.unwrap_or(opts.system_mva);
    if !(pu_base.is_finite() && pu_base > 0.0) {
        return Err(opt(
            "pu_base_mva",
            format!("must be > 0 MVA (got {pu_base})"),
        ));
    }
    let unit_of = |s: usize| a.slots[s].as_ref().map(|x| x.1);
    let v_pu = matches!(unit_of(0).or(unit_of(2)), Some(ChanUnit::Pu));
    let i_pu = matches!(unit_of(4).or(unit_of(6)), Some(ChanUnit::Pu));
    if v_pu != i_pu {
        return Err(opt(
            "units",
            "voltage and current must both be physical (kV/V and kA/A) or both pu".into(),
        ));
    }
    let v_base = if v_pu {
        None
    } else {
        let v = opts.v_base_kv.ok_or_else(|| {
            opt(
                "v_base_kv",
                "missing: the rated line-to-line voltage [kV] is needed for voltages in V or kV"
                    .into(),
            )
        })?;
        if !(v.is_finite() && v > 0.0) {
            return Err(opt("v_base_kv", format!("must be > 0 kV (got {v})")));
        }
        Some(v)
    };
    if let Some(r) = opts.rate_hz {
        if !(r.is_finite() && r > 0.0) {
            return Err(opt("rate_hz", format!("must be > 0 samples/s (got {r})")));
        }
    }
    if a.phase_a {
        warnings.push(
            "phase-A phasors taken as the positive sequence (balanced unit): S = 3 V_a I_a*".into(),
        );
    }
    let samples_read = samples.len();
    if samples_read == 0 {
        return Err(ImportError::data(path, None, "no samples"));
    }
    let (sec0, frac0) = (samples[0].sec, samples[0].frac);
    let rel = |s: &RawSample| (s.sec - sec0) as f64 + (s.frac - frac0);
    let get = |s: &RawSample, k: usize| -> f64 {
        match &a.slots[k] {
            Some((_, ChanUnit::Physical(f), _)) => s.vals[k] * f,
            Some((_, ChanUnit::Pu, _)) => s.vals[k],
            None => f64::NAN,
        }
    };
    let phasor = |s: &RawSample, k: usize| -> (f64, f64) {
        if a.slots[k].is_some() {
            let (m, th) = (get(s, k), get(s, k + 1));
            (m * th.cos(), m * th.sin())
        } else {
            (get(s, k + 2), get(s, k + 3))
        }
    };
    let sign = if opts.current_into_machine { -1.0 } else { 1.0 };
    let (c30, s30) = ((-30f64).to_radians().cos(), (-30f64).to_radians().sin());
    let mut dropouts = vec![];
    let mut kept: Vec<Kept> = vec![];
    for s in &samples {
        let t = rel(s);
        let (mut vr, mut vi) = phasor(s, 0);
        let (ir, ii) = phasor(s, 4);
        let f = a.slots[8].as_ref().map(|_| get(s, 8));
        let reason = if let Some(b) = &s.bad {
            Some(b.clone())
        } else if ![vr, vi, ir, ii].iter().all(|x| x.is_finite())
            || f.is_some_and(|x| !x.is_finite())
        {
            Some("a value is missing or not a number".to_string())
        } else if vr == 0.0 && vi == 0.0 {
            Some("|V| = 0".to_string())
        } else {
            None
        };
        if let Some(reason) = reason {
            dropouts.push(Dropout {
                time_s: t,
                at: s.at.clone(),
                reason,
            });
            continue;
        }
        if opts.line_voltage {
            let (r, i) = (vr / 3f64.sqrt(), vi / 3f64.sqrt());
            (vr, vi) = (r * c30 - i * s30, r * s30 + i * c30);
        }
        // S = k V I* (k = 3 for phase-to-neutral kV and kA → MVA; 1 in pu on pu_base).
        let (sr, si) = (vr * ir + vi * ii, vi * ir - vr * ii);
        let (p, q, vmag) = match v_base {
            Some(vb) => (
                3.0 * sr / opts.system_mva,
                3.0 * si / opts.system_mva,
                vr.hypot(vi) * 3f64.sqrt() / vb,
            ),
            None => (
                sr * pu_base / opts.system_mva,
                si * pu_base / opts.system_mva,
                vr.hypot(vi),
            ),
        };
        kept.push((t, vmag, vi.atan2(vr), sign * p, sign * q, f, s.at.clone()));
    }
    if kept.len() < 2 {
        return Err(ImportError::data(
            path,
            None,
            format!("{} usable sample(s) of {samples_read}", kept.len()),
        ));
    }
    // Time axis: strictly increasing, relative to the first kept sample.
    let t0 = kept[0].0;
    for w in kept.windows(2) {
        if !(w[1].0 > w[0].0) {
            return Err(ImportError::data(
                path,
                Some(w[1].6.clone()),
                format!(
                    "time {:.6} s is not after the previous sample's {:.6} s ({})",
                    w[1].0 - t0,
                    w[0].0 - t0,
                    w[0].6
                ),
            ));
        }
    }
    // Gaps are time stamps that never came (on every sample read, so that a dropout removed
    // here is not also a gap); the rate is over the intervals without a gap.
    let all: Vec<(f64, &str)> = samples.iter().map(|s| (rel(s), s.at.as_str())).collect();
    let mut dts: Vec<f64> = all
        .windows(2)
        .map(|w| w[1].0 - w[0].0)
        .filter(|d| *d > 0.0)
        .collect();
    if dts.is_empty() {
        dts = kept.windows(2).map(|w| w[1].0 - w[0].0).collect();
    }
    dts.sort_by(|x, y| x.partial_cmp(y).expect("finite"));
    let dt_median = dts[dts.len() / 2];
    let regular: Vec<f64> = dts
        .iter()
        .copied()
        .filter(|d| *d <= 1.5 * dt_median)
        .collect();
    let dt = regular.iter().sum::<f64>() / regular.len() as f64;
    let mut gaps = vec![];
    for w in all.windows(2) {
        let d = w[1].0 - w[0].0;
        if d > 1.5 * dt_median {
            gaps.push(Gap {
                from_s: w[0].0 - t0,
                to_s: w[1].0 - t0,
                missing: ((d / dt).round() as usize).saturating_sub(1).max(1),
                at: w[1].1.to_string(),
            });
        }
    }
    for d in &mut dropouts {
        d.time_s -= t0;
    }
    let mut time: Vec<f64> = kept.iter().map(|k| k.0 - t0).collect();
    if opts.rate_hz.is_none() {
        if let Some(rate) = crate::event::snap_to_rate(&mut time) {
            warnings.push(format!(
                "time stamps lie on the {rate} samples/s reporting grid to within {} µs \
                 (their written resolution): taken as exact multiples of 1/{rate} s",
                crate::event::SNAP_TOL_S * 1e6
            ));
        }
    }
    let vmag: Vec<f64> = kept.iter().map(|k| k.1).collect();
    let ang = unwrap_angles(&kept.iter().map(|k| k.2).collect::<Vec<_>>());
    let p: Vec<f64> = kept.iter().map(|k| k.3).collect();
    let q: Vec<f64> = kept.iter().map(|k| k.4).collect();
    let freq: Option<Vec<f64>> = if a.slots[8].is_some() {
        Some(kept.iter().map(|k| k.5.expect("checked")).collect())
    } else {
        None
    };
    let mut rec = Record {
        time_s: time,
        v_mag_pu: vmag,
        v_ang_rad: ang,
        p_pu: p,
        q_pu: q,
        freq_hz: freq,
        efd_pu: None,
        ifd_pu: None,
    };
    if let Some(rate) = opts.rate_hz {
        rec = resample(&rec, rate, dt);
        if !gaps.is_empty() {
            warnings.push(format!(
                "{} gap(s) filled by interpolation in the resampled record",
                gaps.len()
            ));
        }
    }
    let name = opts.name.clone().unwrap_or_else(|| {
        path.file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "imported".into())
    });
    let samples_kept = kept.len();
    let event = Event::from_record(&name, rec, opts.system_mva, opts.nominal_hz, None, None)
        .map_err(|source| ImportError::Event {
            path: path.into(),
            source: Box::new(source),
        })?;
    // The plausibility layer on the imported record (a record that ends in a measurement
    // drop-out, say), as every command that reads the event will say it; the machine's rating
    // is not known here, the operating point's |S| stands for it.
    for f in crate::plausibility::check_event(&event, None) {
        let at = f
            .time_s
            .map(|t| format!(" (t = {t} s)"))
            .unwrap_or_default();
        warnings.push(format!("{}{at}: {}; fix: {}", f.column, f.message, f.fix));
    }
    let report = ImportReport {
        source: path.into(),
        format,
        start: start.map(|s| shift_iso(&s, t0)),
        samples_read,
        samples_kept,
        samples_declared: None,
        source_rate_hz: 1.0 / dt,
        resampled_hz: opts.rate_hz,
        channels: a.describe(),
        gaps,
        dropouts,
        warnings,
        onset_s: event.onset_s(),
        onset: event.onset.detection.describe(),
        init_s: [event.init.start_s, event.init.end_s],
    };
    Ok((event, report))
}

/// The note of a data file that holds `read` samples where its header declares `declared`
/// (`None` when it holds them all): what the import warns of, writes into the event file
/// ([`Event::import_notes`]) and, with [`ImportOptions::refuse_truncated`], refuses.
pub fn truncation_note(
    data: &Path,
    header: &Path,
    read: usize,
    declared: usize,
    last_s: f64,
) -> Option<String> {
    (read < declared).then(|| {
        format!(
            "{} holds {read} samples where {} declares {declared}: the data file is truncated \
             (the record ends at {last_s:.4} s, {} samples short)",
            data.display(),
            header.display(),
            declared - read
        )
    })
}

/// Resamples to a uniform grid from the first sample (see the module documentation).
fn resample(r: &Record, rate: f64, dt_src: f64) -> Record {
    let h = 1.0 / rate;
    let n = ((r.end_s() - r.start_s()) / h + 1e-9).floor() as usize + 1;
    let t: Vec<f64> = (0..n).map(|k| r.start_s() + k as f64 * h).collect();
    let boxcar = h > 1.5 * dt_src;
    let col = |y: &[f64]| -> Vec<f64> {
        t.iter()
            .map(|&tk| {
                if boxcar {
                    let (lo, hi) = (tk - 0.5 * h, tk + 0.5 * h);
                    let (mut s, mut c) = (0.0, 0);
                    for (ti, yi) in r.time_s.iter().zip(y) {
                        if *ti >= lo && *ti < hi {
                            s += yi;
                            c += 1;
                        }
                    }
                    if c > 0 {
                        return s / c as f64;
                    }
                }
                interp(&r.time_s, y, tk)
            })
            .collect()
    };
    Record {
        v_mag_pu: col(&r.v_mag_pu),
        v_ang_rad: col(&r.v_ang_rad),
        p_pu: col(&r.p_pu),
        q_pu: col(&r.q_pu),
        freq_hz: r.freq_hz.as_ref().map(|f| col(f)),
        efd_pu: None,
        ifd_pu: None,
        time_s: t,
    }
}

fn interp(x: &[f64], y: &[f64], t: f64) -> f64 {
    let k = x.partition_point(|v| *v <= t);
    if k == 0 {
        return y[0];
    }
    if k >= x.len() {
        return y[x.len() - 1];
    }
    let (x0, x1) = (x[k - 1], x[k]);
    y[k - 1] + (y[k] - y[k - 1]) * (t - x0) / (x1 - x0)
}

/// Imports a file by its extension: `.cfg` (or a `.dat` with a `.cfg` beside it) as COMTRADE,
/// anything else as C37.118-style CSV.
pub fn import(path: &Path, opts: &ImportOptions) -> Result<(Event, ImportReport), ImportError> {
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    match ext.as_str() {
        "cfg" => comtrade::import(path, opts),
        "dat" => {
            let upper = path.with_extension("CFG");
            let cfg = if upper.is_file() {
                upper
            } else {
                path.with_extension("cfg")
            };
            comtrade::import(&cfg, opts)
        }
        _ => c37::import(path, opts),
    }
}

/// Words of `text` in lines of at most `width` characters (a longer word on a line of its own).
fn wrap(text: &str, width: usize) -> Vec<String> {
    let mut lines = vec![];
    let mut line = String::new();
    for word in text.split_whitespace() {
        if !line.is_empty() && line.len() + 1 + word.len() > width {
            lines.push(std::mem::take(&mut line));
        }
        if !line.is_empty() {
            line.push(' ');
        }
        line.push_str(word);
    }
    if !line.is_empty() {
        lines.push(line);
    }
    lines
}

/// Writes an event folder: `event.toml` (with the detected onset and the init window it
/// implies, see the module documentation), `<name>.csv` (the canonical columns) and
/// `import.json` (the report). Returns the paths written.
pub fn write_event_folder(
    event: &Event,
    report: &ImportReport,
    dir: &Path,
) -> Result<Vec<PathBuf>, EventError> {
    let io = |p: &Path, source| EventError::Io {
        path: p.into(),
        action: "cannot write".into(),
        source,
    };
    std::fs::create_dir_all(dir).map_err(|e| io(dir, e))?;
    let csv_name = format!("{}.csv", event.name);
    let csv = dir.join(&csv_name);
    event.write_csv(&csv)?;
    let toml_path = dir.join("event.toml");
    let mut desc = format!(
        "imported by itaipu-calib from {} ({})",
        report.source.display(),
        report.format
    );
    if let Some(s) = &report.start {
        desc.push_str(&format!(", t = 0 at {s}"));
    }
    if !report.gaps.is_empty() || !report.dropouts.is_empty() {
        desc.push_str(&format!(
            "; {} gap(s), {} dropout(s): see import.json",
            report.gaps.len(),
            report.dropouts.len()
        ));
    }
    let mut text = format!(
        "name = {}\ndescription = {}\ncsv = {}\nsystem_mva = {}\nnominal_hz = {}\n\n",
        toml::Value::String(event.name.clone()),
        toml::Value::String(desc),
        toml::Value::String(csv_name),
        format_g17(event.system_mva),
        format_g17(event.nominal_hz),
    );
    let (what, onset) = match event.onset_s() {
        Some(t) => (
            format!(
                "Detected by itaipu-calib import: the disturbance's onset (its first sample) and \
                 the pre-event init window it implies (from the start to {ONSET_GUARD_SAMPLES} \
                 samples before the onset)."
            ),
            format_g17(t),
        ),
        None => (
            "Detected by itaipu-calib import: no disturbance (ambient data); the init window is \
             the default, 0.5 s from the start."
                .to_string(),
            "\"none\"".to_string(),
        ),
    };
    let comment = format!(
        "{what} {}. To override: set onset_s to the time you read off the record (or \
         onset_s = \"none\" for data without a disturbance) and edit [init] (or delete it: its \
         default follows onset_s).",
        event.onset.detection.describe()
    );
    for line in wrap(&comment, 98) {
        text.push_str(&format!("# {line}\n"));
    }
    text.push_str(&format!("onset_s = {onset}\n"));
    if !event.import_notes.is_empty() {
        text.push_str(
            "# What the import found wrong with the recording, said again by every command that \
             reads\n# this event (see import.json).\nimport_notes = [\n",
        );
        for n in &event.import_notes {
            text.push_str(&format!("  {},\n", toml::Value::String(n.clone())));
        }
        text.push_str("]\n");
    }
    text.push_str(&format!(
        "\n[init]\nstart_s = {}\nend_s = {}\n",
        format_g17(event.init.start_s),
        format_g17(event.init.end_s),
    ));
    std::fs::write(&toml_path, text).map_err(|e| io(&toml_path, e))?;
    let json_path = dir.join("import.json");
    let j = serde_json::to_string_pretty(report).expect("a report serialises") + "\n";
    std::fs::write(&json_path, j).map_err(|e| io(&json_path, e))?;
    Ok(vec![toml_path, csv, json_path])
}
