//! Measured events: a PMU recording of a generating unit's terminal quantities, read from disk.
//!
//! An *event* is a small TOML file that points to a CSV recording and says how to use it:
//!
//! ```toml
//! name = "itaipu-60hz-fault"
//! description = "free text"            # optional, default ""
//! csv = "itaipu_pmu_60sps.csv"         # path relative to the TOML file's folder (or absolute)
//! system_mva = 1000.0                  # MVA base of p_pu and q_pu in the CSV
//! nominal_hz = 60.0                    # nominal frequency of the PMU reference frame
//! [playback]   # optional: trim the record used for playback; default = whole record
//! start_s = 0.0
//! end_s = 4.65
//! [init]       # optional: pre-event window for the operating point; default see below
//! start_s = 0.0
//! end_s = 0.95
//! [fit]        # optional: fit window; default = playback window
//! start_s = 0.0
//! end_s = 4.65
//! ```
//!
//! `name`, `csv`, `system_mva` and `nominal_hz` are required; `system_mva` and `nominal_hz` must
//! be finite and > 0 (any positive nominal frequency is accepted, no warning for values other
//! than 50/60 Hz). Integers are accepted where floats are expected. Every key of a window table
//! is optional on its own: a missing `start_s`/`end_s` takes the default for that bound.
//! Unknown keys anywhere are errors naming the key (and its line).
//!
//! # Windows
//!
//! A [`Window`] is the closed time interval `[start_s, end_s]` in the time axis of the CSV
//! (seconds). A sample belongs to a window if its time lies inside, with a tolerance of
//! [`TIME_TOL_S`] (1 µs) on both ends so that `end_s = 4.65` matches a sample stamped
//! `4.6499999999`.
//!
//! * `playback` must lie inside the record and hold at least [`MIN_SAMPLES`] samples.
//!   Default: the whole record.
//! * `init` must lie inside the playback window and hold at least [`MIN_SAMPLES`] samples.
//!   Default: starts at the playback start and lasts [`DEFAULT_INIT_S`] (0.5 s); if those
//!   0.5 s hold fewer than [`DEFAULT_INIT_MIN_SAMPLES`] (10) samples (slow recordings) it is
//!   extended to the first 10 samples. It never extends past the playback window. If only
//!   `init.start_s` is given, the same rule is applied from that start.
//! * `fit` must lie inside the playback window and hold at least [`MIN_SAMPLES`] samples.
//!   Default: the playback window.
//!
//! A window with `end_s <= start_s` is an error naming `<window>.end_s`.
//!
//! # CSV format
//!
//! A header line followed by one sample per line. Columns (order free, surrounding whitespace in
//! headers and fields is trimmed):
//!
//! | column      | required | meaning                                                            |
//! |-------------|----------|--------------------------------------------------------------------|
//! | `time_s`    | yes      | time, s, strictly increasing                                       |
//! | `v_re_pu`   | (a)      | real part of the terminal-voltage phasor, pu of rated voltage      |
//! | `v_im_pu`   | (a)      | imaginary part of the phasor, pu                                   |
//! | `v_pu`      | (b)      | magnitude of the phasor, pu (≥ 0)                                  |
//! | `angle_deg` | (b)      | angle of the phasor, degrees (wrapped or not)                      |
//! | `p_pu`      | yes      | active power, pu on `system_mva`, generator convention (out > 0)   |
//! | `q_pu`      | yes      | reactive power, pu on `system_mva`, generator convention (out > 0) |
//! | `freq_hz`   | no       | measured frequency, Hz (absolute, not a deviation)                 |
//! | `efd_pu`    | no       | field voltage, pu                                                  |
//! | `ifd_pu`    | no       | field current, pu                                                  |
//!
//! Exactly one voltage form must be present: (a) `v_re_pu` + `v_im_pu` or (b) `v_pu` +
//! `angle_deg`. Any other column, a duplicated column or a missing required column is an error.
//! Every field must be a finite number. Line numbers in messages are 1-based with the header on
//! line 1.
//!
//! # Unit sanity checks
//!
//! To catch data given in the wrong units, a record is rejected if the median |V| lies outside
//! `[0.5, 1.5]` pu (kV or volts instead of per unit), if any |P| or |Q| reaches 20 pu (MW/Mvar
//! instead of per unit on `system_mva`), or if a `freq_hz` value lies more than 10 % away from
//! `nominal_hz` (frequency given as a deviation or in per unit). An angle column in radians
//! instead of degrees cannot be detected reliably and is not checked. The checks look at the
//! whole file, before the playback window trims it.
//!
//! # Angle convention
//!
//! The phasor is referred to a rotating frame at the *nominal* frequency, as PMU phasors are, so
//! its angle drifts at `2π (f − f_nominal)` rad/s when the grid frequency `f` is off nominal (the
//! Itaipu record drifts by about −320° in 3.5 s). The angle is therefore *unwrapped*: jumps of
//! more than π between consecutive samples are taken as 2π wraps and removed, which gives a
//! continuous angle as long as the frequency error stays below half the sample rate. After
//! unwrapping, the whole angle series is shifted by a multiple of 2π so that the first sample
//! of the [`Record`] lies in `[-π, π]`.
//!
//! # Errors
//!
//! All failures are reported as [`EventError`], whose message always names the file (the path
//! as given by the caller), and the line, column or TOML field where that applies. Events built
//! in memory ([`Event::from_record`]) are named `<in-memory event 'NAME'>` and locate bad data by
//! 0-based sample index. [`EventError::kind`] gives a short stable identifier for matching.

use std::fmt;
use std::fs;
use std::io::{BufWriter, Write};
use std::ops::Range;
use std::path::{Path, PathBuf};

use serde::Deserialize;

/// Tolerance, in seconds, when deciding whether a sample time lies inside a window or a window
/// bound lies inside the record.
pub const TIME_TOL_S: f64 = 1e-6;

/// Minimum number of samples in the record, the playback window, the init window and the fit
/// window.
pub const MIN_SAMPLES: usize = 3;

/// Default length of the init window, s.
pub const DEFAULT_INIT_S: f64 = 0.5;

/// The default init window is extended to hold at least this many samples.
pub const DEFAULT_INIT_MIN_SAMPLES: usize = 10;

/// Accepted range of the median |V|, pu.
pub const V_MEDIAN_RANGE_PU: (f64, f64) = (0.5, 1.5);

/// |P| and |Q| must stay below this value, pu on the system base.
pub const PQ_LIMIT_PU: f64 = 20.0;

/// `freq_hz` values must lie within this fraction of `nominal_hz` around it.
pub const FREQ_TOLERANCE: f64 = 0.10;

/// Columns accepted in an event CSV, in canonical order.
pub const ACCEPTED_COLUMNS: [&str; 10] = [
    "time_s",
    "v_re_pu",
    "v_im_pu",
    "v_pu",
    "angle_deg",
    "p_pu",
    "q_pu",
    "freq_hz",
    "efd_pu",
    "ifd_pu",
];

const TOP_KEYS: [&str; 8] = [
    "name",
    "description",
    "csv",
    "system_mva",
    "nominal_hz",
    "playback",
    "init",
    "fit",
];
const REQUIRED_KEYS: [&str; 4] = ["name", "csv", "system_mva", "nominal_hz"];
const WINDOW_TABLES: [&str; 3] = ["playback", "init", "fit"];
const WINDOW_KEYS: [&str; 2] = ["start_s", "end_s"];

const TAU: f64 = std::f64::consts::TAU;

// ---------------------------------------------------------------------------------------------
// Errors
// ---------------------------------------------------------------------------------------------

/// Where in a data source a problem was found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Location {
    /// 1-based line of a CSV file (the header is line 1).
    Line(usize),
    /// 0-based sample index of an in-memory [`Record`].
    Sample(usize),
}

impl fmt::Display for Location {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Location::Line(n) => write!(f, "line {n}"),
            Location::Sample(i) => write!(f, "sample {i}"),
        }
    }
}

fn opt_loc(at: &Option<Location>) -> String {
    match at {
        Some(l) => format!(" {l}"),
        None => String::new(),
    }
}

fn opt_line(line: &Option<usize>) -> String {
    match line {
        Some(n) => format!(" line {n}"),
        None => String::new(),
    }
}

/// Everything that can go wrong while reading, validating or writing an event.
///
/// `path` is always the file the problem is in, as given by the caller (or, for events built
/// with [`Event::from_record`], the label `<in-memory event 'NAME'>`).
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum EventError {
    /// The file could not be opened, read or written.
    #[error("{}: {action}: {source}", path.display())]
    Io {
        path: PathBuf,
        /// What was attempted, e.g. "cannot open the CSV file (named in event.toml)".
        action: String,
        #[source]
        source: std::io::Error,
    },

    /// The TOML file is not valid TOML. `message` is toml's message, with line and column.
    #[error("{}: invalid TOML: {message}", path.display())]
    TomlSyntax { path: PathBuf, message: String },

    /// A TOML value has the wrong type (e.g. a string where a number is expected). `message`
    /// is toml's message, with line and column.
    #[error("{}: invalid value in event file: {message}", path.display())]
    TomlValue { path: PathBuf, message: String },

    /// The TOML file has a key the event format does not know.
    #[error("{}{}: unknown key `{field}`; accepted keys here: {accepted}", path.display(), opt_line(line))]
    UnknownField {
        path: PathBuf,
        /// Dotted key, e.g. `init.stop_s`.
        field: String,
        /// 1-based line of the key in the TOML file.
        line: Option<usize>,
        accepted: String,
    },

    /// A required TOML key is missing.
    #[error("{}: missing required key `{field}`", path.display())]
    MissingField { path: PathBuf, field: String },

    /// A TOML or API value is out of range (e.g. `system_mva <= 0`).
    #[error("{}: {field} = {value}: {message}", path.display())]
    InvalidValue {
        path: PathBuf,
        field: String,
        value: f64,
        message: String,
    },

    /// The CSV text is malformed: empty file, wrong number of fields, invalid UTF-8, ...
    #[error("{}{}: {message}", path.display(), opt_line(line))]
    CsvStructure {
        path: PathBuf,
        line: Option<usize>,
        message: String,
    },

    /// An in-memory [`Record`] is malformed (vectors of different lengths).
    #[error("{}: {message}", path.display())]
    RecordShape { path: PathBuf, message: String },

    /// A required CSV column is missing.
    #[error("{} line 1: missing column '{column}' {detail}", path.display())]
    MissingColumn {
        path: PathBuf,
        column: String,
        detail: String,
    },

    /// The CSV header has a column the format does not know.
    #[error("{} line 1: unknown column '{column}'; accepted columns are: {}", path.display(), ACCEPTED_COLUMNS.join(", "))]
    UnknownColumn { path: PathBuf, column: String },

    /// A column appears twice in the CSV header.
    #[error("{} line 1: column '{column}' appears more than once", path.display())]
    DuplicateColumn { path: PathBuf, column: String },

    /// Both voltage forms (re/im and magnitude/angle) are present.
    #[error("{} line 1: {message}", path.display())]
    ConflictingColumns { path: PathBuf, message: String },

    /// A field is not a finite number (or is negative where that is impossible).
    #[error("{} {at}, column {column}: '{text}' {reason}", path.display())]
    BadNumber {
        path: PathBuf,
        at: Location,
        column: String,
        /// The field text as found (trimmed).
        text: String,
        reason: &'static str,
    },

    /// Time does not increase strictly from one sample to the next.
    #[error(
        "{} {at}, column time_s: time {time_s} s is not after the previous sample's time {prev_time_s} s ({prev_at}); time must increase strictly",
        path.display()
    )]
    NonMonotonicTime {
        path: PathBuf,
        at: Location,
        prev_at: Location,
        prev_time_s: f64,
        time_s: f64,
    },

    /// A window (or the whole record) holds fewer than [`MIN_SAMPLES`] samples.
    #[error("{}: {what} holds {count} sample(s); at least {min} are needed", path.display())]
    TooFewSamples {
        path: PathBuf,
        /// Which data: "the record", "the playback window [0, 0.02] s", ...
        what: String,
        count: usize,
        min: usize,
    },

    /// The data look like they are in the wrong units.
    #[error("{}{}, column {column}: {message}", path.display(), opt_loc(at))]
    Units {
        path: PathBuf,
        column: String,
        at: Option<Location>,
        message: String,
    },

    /// A window is upside down, not finite, or not inside the data it must lie in.
    #[error("{}: {field}: {message}", path.display())]
    BadWindow {
        path: PathBuf,
        /// e.g. `init.end_s`
        field: String,
        message: String,
    },
}

impl EventError {
    /// Short stable identifier of the error variant, e.g. `"missing_column"`.
    pub fn kind(&self) -> &'static str {
        match self {
            EventError::Io { .. } => "io",
            EventError::TomlSyntax { .. } => "toml_syntax",
            EventError::TomlValue { .. } => "toml_value",
            EventError::UnknownField { .. } => "unknown_field",
            EventError::MissingField { .. } => "missing_field",
            EventError::InvalidValue { .. } => "invalid_value",
            EventError::CsvStructure { .. } => "csv_structure",
            EventError::RecordShape { .. } => "record_shape",
            EventError::MissingColumn { .. } => "missing_column",
            EventError::UnknownColumn { .. } => "unknown_column",
            EventError::DuplicateColumn { .. } => "duplicate_column",
            EventError::ConflictingColumns { .. } => "conflicting_columns",
            EventError::BadNumber { .. } => "bad_number",
            EventError::NonMonotonicTime { .. } => "non_monotonic_time",
            EventError::TooFewSamples { .. } => "too_few_samples",
            EventError::Units { .. } => "units",
            EventError::BadWindow { .. } => "bad_window",
        }
    }

    /// The file the error is about (or the in-memory label).
    pub fn path(&self) -> &Path {
        match self {
            EventError::Io { path, .. }
            | EventError::TomlSyntax { path, .. }
            | EventError::TomlValue { path, .. }
            | EventError::UnknownField { path, .. }
            | EventError::MissingField { path, .. }
            | EventError::InvalidValue { path, .. }
            | EventError::CsvStructure { path, .. }
            | EventError::RecordShape { path, .. }
            | EventError::MissingColumn { path, .. }
            | EventError::UnknownColumn { path, .. }
            | EventError::DuplicateColumn { path, .. }
            | EventError::ConflictingColumns { path, .. }
            | EventError::BadNumber { path, .. }
            | EventError::NonMonotonicTime { path, .. }
            | EventError::TooFewSamples { path, .. }
            | EventError::Units { path, .. }
            | EventError::BadWindow { path, .. } => path,
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Data types
// ---------------------------------------------------------------------------------------------

/// A closed time interval `[start_s, end_s]`, seconds on the record's time axis.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Window {
    pub start_s: f64,
    pub end_s: f64,
}

impl Window {
    /// A window from `start_s` to `end_s` (not validated).
    pub fn new(start_s: f64, end_s: f64) -> Window {
        Window { start_s, end_s }
    }

    /// Length of the window, s.
    pub fn duration_s(&self) -> f64 {
        self.end_s - self.start_s
    }

    /// Whether time `t` lies in the window, with tolerance [`TIME_TOL_S`].
    pub fn contains(&self, t: f64) -> bool {
        t >= self.start_s - TIME_TOL_S && t <= self.end_s + TIME_TOL_S
    }
}

impl fmt::Display for Window {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "[{}, {}] s", self.start_s, self.end_s)
    }
}

/// Measured samples, one entry per sample in every vector (all of equal length).
///
/// In an [`Event`] this holds the samples inside the playback window only.
#[derive(Debug, Clone, PartialEq)]
pub struct Record {
    /// Time, s, strictly increasing.
    pub time_s: Vec<f64>,
    /// Terminal-voltage magnitude |V|, pu of rated terminal voltage.
    pub v_mag_pu: Vec<f64>,
    /// Terminal-voltage angle, rad, in the nominal-frequency PMU frame, unwrapped (continuous);
    /// the first sample lies in `[-π, π]`.
    pub v_ang_rad: Vec<f64>,
    /// Active power, pu on the system base, generator convention (delivered > 0).
    pub p_pu: Vec<f64>,
    /// Reactive power, pu on the system base, generator convention (delivered > 0).
    pub q_pu: Vec<f64>,
    /// Measured frequency, Hz, if recorded.
    pub freq_hz: Option<Vec<f64>>,
    /// Field voltage, pu, if recorded.
    pub efd_pu: Option<Vec<f64>>,
    /// Field current, pu, if recorded.
    pub ifd_pu: Option<Vec<f64>>,
}

impl Record {
    /// Builds a record from rectangular phasor components (`v_re_pu`, `v_im_pu`, pu) and P, Q
    /// (pu, system base). Magnitude and angle are computed; the angle is unwrapped. Optional
    /// channels are left empty. No validation is done here ([`Event::from_record`] validates).
    pub fn from_rectangular(
        time_s: Vec<f64>,
        v_re_pu: &[f64],
        v_im_pu: &[f64],
        p_pu: Vec<f64>,
        q_pu: Vec<f64>,
    ) -> Record {
        let v_mag_pu = v_re_pu
            .iter()
            .zip(v_im_pu)
            .map(|(r, i)| r.hypot(*i))
            .collect();
        let raw: Vec<f64> = v_re_pu
            .iter()
            .zip(v_im_pu)
            .map(|(r, i)| i.atan2(*r))
            .collect();
        Record {
            time_s,
            v_mag_pu,
            v_ang_rad: unwrap_angles(&raw),
            p_pu,
            q_pu,
            freq_hz: None,
            efd_pu: None,
            ifd_pu: None,
        }
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.time_s.len()
    }

    /// Whether the record has no samples.
    pub fn is_empty(&self) -> bool {
        self.time_s.is_empty()
    }

    /// Time of the first sample, s (NaN if empty).
    pub fn start_s(&self) -> f64 {
        self.time_s.first().copied().unwrap_or(f64::NAN)
    }

    /// Time of the last sample, s (NaN if empty).
    pub fn end_s(&self) -> f64 {
        self.time_s.last().copied().unwrap_or(f64::NAN)
    }

    /// The window from the first to the last sample.
    pub fn span(&self) -> Window {
        Window::new(self.start_s(), self.end_s())
    }

    /// Real part of the voltage phasor, pu: `|V| cos(angle)`.
    pub fn v_re_pu(&self) -> Vec<f64> {
        self.v_mag_pu
            .iter()
            .zip(&self.v_ang_rad)
            .map(|(m, a)| m * a.cos())
            .collect()
    }

    /// Imaginary part of the voltage phasor, pu: `|V| sin(angle)`.
    pub fn v_im_pu(&self) -> Vec<f64> {
        self.v_mag_pu
            .iter()
            .zip(&self.v_ang_rad)
            .map(|(m, a)| m * a.sin())
            .collect()
    }

    /// Indices of the samples inside `w` (with tolerance [`TIME_TOL_S`]). Time must be sorted.
    pub fn window_range(&self, w: &Window) -> Range<usize> {
        let lo = self.time_s.partition_point(|&t| t < w.start_s - TIME_TOL_S);
        let hi = self.time_s.partition_point(|&t| t <= w.end_s + TIME_TOL_S);
        lo..hi.max(lo)
    }

    /// A copy of the samples in `range` (all channels).
    pub fn slice(&self, range: Range<usize>) -> Record {
        let s = |v: &Vec<f64>| v[range.clone()].to_vec();
        Record {
            time_s: s(&self.time_s),
            v_mag_pu: s(&self.v_mag_pu),
            v_ang_rad: s(&self.v_ang_rad),
            p_pu: s(&self.p_pu),
            q_pu: s(&self.q_pu),
            freq_hz: self.freq_hz.as_ref().map(s),
            efd_pu: self.efd_pu.as_ref().map(s),
            ifd_pu: self.ifd_pu.as_ref().map(s),
        }
    }

    /// Shifts the whole angle series by a multiple of 2π so that the first sample lies in
    /// `[-π, π]`.
    fn normalize_angle_start(&mut self) {
        if let Some(&a0) = self.v_ang_rad.first() {
            let k = (a0 / TAU).round();
            if k != 0.0 {
                let shift = k * TAU;
                for a in &mut self.v_ang_rad {
                    *a -= shift;
                }
            }
        }
    }
}

/// Removes 2π jumps from a sequence of angles (rad): every step between consecutive samples is
/// brought into `[-π, π]` by adding a multiple of 2π to all later samples. The first sample is
/// kept as is. A sequence that is already continuous is returned unchanged (bit for bit).
pub fn unwrap_angles(raw: &[f64]) -> Vec<f64> {
    let mut out = Vec::with_capacity(raw.len());
    let mut k = 0.0_f64; // number of turns added so far
    for (i, &a) in raw.iter().enumerate() {
        if i > 0 {
            let d = a - raw[i - 1];
            k -= (d / TAU).round();
        }
        out.push(if k == 0.0 { a } else { a + k * TAU });
    }
    out
}

/// Operating point estimated from the init window, on the SYSTEM base.
///
/// It is the state the simulation should start from. Each quantity is an average over the whole
/// init (pre-event) window rather than the value of a single sample, so that PMU noise and
/// quantisation (P and Q of the Itaipu record move in steps of 1.4 MW) average out.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OperatingPoint {
    /// Mean |V| over the init window, pu.
    pub v_mag_pu: f64,
    /// Voltage angle at `t0_s`, rad (nominal-frequency frame): the least-squares straight line
    /// fitted to the unwrapped angle over the init window, evaluated at `t0_s`.
    pub v_ang_rad: f64,
    /// Mean P over the init window, pu system base, generator convention.
    pub p_pu: f64,
    /// Mean Q over the init window, pu system base, generator convention.
    pub q_pu: f64,
    /// Grid frequency, Hz: the mean of the `freq_hz` channel over the init window if the record
    /// has one, otherwise `nominal_hz + slope / 2π` with the slope (rad/s) of the fitted line.
    pub freq_hz: f64,
    /// Time of the first playback sample, s: where the simulation starts.
    pub t0_s: f64,
    /// Number of samples the estimate is based on.
    pub n_samples: usize,
}

/// A measured event: the playback record plus its bases and windows.
#[derive(Debug, Clone, PartialEq)]
pub struct Event {
    /// Short identifier.
    pub name: String,
    /// Free text (empty if not given).
    pub description: String,
    /// The TOML file the event was read from (`None` for in-memory events).
    pub toml_path: Option<PathBuf>,
    /// The CSV file (resolved against the TOML file's folder; empty for in-memory events).
    pub csv_path: PathBuf,
    /// MVA base of `p_pu` and `q_pu`.
    pub system_mva: f64,
    /// Nominal frequency of the grid and of the PMU reference frame, Hz.
    pub nominal_hz: f64,
    /// Playback window; `record` holds exactly the samples inside it.
    pub playback: Window,
    /// Pre-event window used by [`Event::operating_point`].
    pub init: Window,
    /// Window over which a fit should compare simulation and measurement.
    pub fit: Window,
    /// Samples inside the playback window.
    pub record: Record,
}

// ---------------------------------------------------------------------------------------------
// TOML
// ---------------------------------------------------------------------------------------------

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct EventSpec {
    name: String,
    #[serde(default)]
    description: String,
    csv: PathBuf,
    system_mva: f64,
    nominal_hz: f64,
    #[serde(default)]
    playback: Option<WindowSpec>,
    #[serde(default)]
    init: Option<WindowSpec>,
    #[serde(default)]
    fit: Option<WindowSpec>,
}

/// A window as written by the user; missing bounds take defaults.
#[derive(Debug, Default, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
struct WindowSpec {
    #[serde(default)]
    start_s: Option<f64>,
    #[serde(default)]
    end_s: Option<f64>,
}

impl From<Window> for WindowSpec {
    fn from(w: Window) -> Self {
        WindowSpec {
            start_s: Some(w.start_s),
            end_s: Some(w.end_s),
        }
    }
}

fn line_of(text: &str, byte_offset: usize) -> usize {
    let end = byte_offset.min(text.len());
    text.as_bytes()[..end]
        .iter()
        .filter(|&&b| b == b'\n')
        .count()
        + 1
}

/// Checks the key structure of an event TOML (syntax, unknown keys, missing keys), so that the
/// messages can name the key and its line.
fn check_toml_keys(text: &str, path: &Path) -> Result<(), EventError> {
    use toml::de::{DeTable, DeValue};
    let doc = DeTable::parse(text).map_err(|e| EventError::TomlSyntax {
        path: path.to_path_buf(),
        message: e.to_string().trim_end().to_string(),
    })?;
    let table = doc.get_ref();

    // (byte offset, dotted key, accepted keys)
    let mut unknown: Vec<(usize, String, String)> = Vec::new();
    for (k, v) in table.iter() {
        let key: &str = k.get_ref();
        if !TOP_KEYS.contains(&key) {
            unknown.push((k.span().start, key.to_string(), TOP_KEYS.join(", ")));
            continue;
        }
        if WINDOW_TABLES.contains(&key) {
            if let DeValue::Table(sub) = v.get_ref() {
                for (k2, _) in sub.iter() {
                    let key2: &str = k2.get_ref();
                    if !WINDOW_KEYS.contains(&key2) {
                        unknown.push((
                            k2.span().start,
                            format!("{key}.{key2}"),
                            WINDOW_KEYS.join(", "),
                        ));
                    }
                }
            }
        }
    }
    if let Some((offset, field, accepted)) = unknown.into_iter().min_by_key(|u| u.0) {
        return Err(EventError::UnknownField {
            path: path.to_path_buf(),
            field,
            line: Some(line_of(text, offset)),
            accepted,
        });
    }
    for req in REQUIRED_KEYS {
        if !table.iter().any(|(k, _)| {
            let key: &str = k.get_ref();
            key == req
        }) {
            return Err(EventError::MissingField {
                path: path.to_path_buf(),
                field: req.to_string(),
            });
        }
    }
    Ok(())
}

fn check_bases(src: &Path, system_mva: f64, nominal_hz: f64) -> Result<(), EventError> {
    if !(system_mva.is_finite() && system_mva > 0.0) {
        return Err(EventError::InvalidValue {
            path: src.to_path_buf(),
            field: "system_mva".into(),
            value: system_mva,
            message: "the system MVA base must be a finite number > 0".into(),
        });
    }
    check_nominal_hz(src, nominal_hz)
}

fn check_nominal_hz(src: &Path, nominal_hz: f64) -> Result<(), EventError> {
    if !(nominal_hz.is_finite() && nominal_hz > 0.0) {
        return Err(EventError::InvalidValue {
            path: src.to_path_buf(),
            field: "nominal_hz".into(),
            value: nominal_hz,
            message: "the nominal frequency must be a finite number > 0 (Hz)".into(),
        });
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------------
// Event
// ---------------------------------------------------------------------------------------------

impl Event {
    /// Reads an event TOML file and the CSV it points to, and validates everything (see the
    /// module documentation for the format and the checks).
    pub fn from_toml_file(path: &Path) -> Result<Event, EventError> {
        let text = fs::read_to_string(path).map_err(|source| EventError::Io {
            path: path.to_path_buf(),
            action: "cannot read the event file".into(),
            source,
        })?;
        check_toml_keys(&text, path)?;
        let spec: EventSpec = toml::from_str(&text).map_err(|e| EventError::TomlValue {
            path: path.to_path_buf(),
            message: e.to_string().trim_end().to_string(),
        })?;
        check_bases(path, spec.system_mva, spec.nominal_hz)?;

        let folder = path.parent().unwrap_or_else(|| Path::new(""));
        let csv_path = folder.join(&spec.csv);
        let full = read_csv(&csv_path, spec.nominal_hz).map_err(|e| match e {
            EventError::Io {
                path: p,
                action,
                source,
            } => EventError::Io {
                path: p,
                action: format!("{action} named in {}", path.display()),
                source,
            },
            other => other,
        })?;

        assemble(
            path,
            spec.name,
            spec.description,
            Some(path.to_path_buf()),
            csv_path,
            spec.system_mva,
            spec.nominal_hz,
            full,
            spec.playback.unwrap_or_default(),
            spec.init.unwrap_or_default(),
            spec.fit.unwrap_or_default(),
        )
    }

    /// Builds an event from in-memory arrays (used by the Python API and for synthetic events)
    /// and validates it the same way as a file: equal vector lengths, finite values,
    /// non-negative |V|, strictly increasing time, at least [`MIN_SAMPLES`] samples, unit sanity
    /// checks, bases, windows. The whole record is the playback window. `init` and `fit` default
    /// as described in the module documentation. The angle is unwrapped (a no-op for an already
    /// continuous angle) and shifted by a multiple of 2π so that it starts in `[-π, π]`.
    ///
    /// Errors name the source `<in-memory event 'NAME'>` and locate samples by 0-based index.
    /// The returned event has `toml_path = None` and an empty `csv_path`.
    pub fn from_record(
        name: &str,
        record: Record,
        system_mva: f64,
        nominal_hz: f64,
        init: Option<Window>,
        fit: Option<Window>,
    ) -> Result<Event, EventError> {
        let src = PathBuf::from(format!("<in-memory event '{name}'>"));
        check_bases(&src, system_mva, nominal_hz)?;
        let mut record = record;
        check_record_shape(&src, &record)?;
        record.v_ang_rad = unwrap_angles(&record.v_ang_rad);
        let labels = ColumnLabels::in_memory();
        validate_record(&src, &record, nominal_hz, &labels, &|i| Location::Sample(i))?;
        assemble(
            &src,
            name.to_string(),
            String::new(),
            None,
            PathBuf::new(),
            system_mva,
            nominal_hz,
            record,
            WindowSpec::default(),
            init.map(WindowSpec::from).unwrap_or_default(),
            fit.map(WindowSpec::from).unwrap_or_default(),
        )
    }

    /// Indices (into `record`) of the samples in the init window.
    pub fn init_range(&self) -> Range<usize> {
        self.record.window_range(&self.init)
    }

    /// Indices (into `record`) of the samples in the fit window.
    pub fn fit_range(&self) -> Range<usize> {
        self.record.window_range(&self.fit)
    }

    /// Estimates the pre-event operating point from the init window (see [`OperatingPoint`]).
    ///
    /// |V|, P and Q are window means. The angle and the frequency come from a least-squares
    /// straight line `angle(t) = a + b t` fitted to the unwrapped angle over the window: the
    /// frequency is `nominal_hz + b / 2π` (replaced by the window mean of `freq_hz` if that
    /// channel exists), and the angle is the line evaluated at `t0_s`, the first playback
    /// sample. Fitting a line over the whole pre-event window averages out PMU noise instead of
    /// trusting a single noisy sample, and accounts for the angle drift of an off-nominal
    /// frequency between `t0_s` and the window.
    pub fn operating_point(&self) -> OperatingPoint {
        let r = self.init_range();
        let rec = &self.record;
        let n = r.len();
        let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
        let t = &rec.time_s[r.clone()];
        let a = &rec.v_ang_rad[r.clone()];
        let t0_s = rec.time_s[0];
        let (slope, angle_at_t0) = if n >= 2 {
            let tm = mean(t);
            let am = mean(a);
            let mut sxy = 0.0;
            let mut sxx = 0.0;
            for (ti, ai) in t.iter().zip(a) {
                sxy += (ti - tm) * (ai - am);
                sxx += (ti - tm) * (ti - tm);
            }
            let slope = if sxx > 0.0 { sxy / sxx } else { 0.0 };
            (slope, am + slope * (t0_s - tm))
        } else {
            // Not reachable for validated events (the init window holds >= MIN_SAMPLES).
            (0.0, a.first().copied().unwrap_or(0.0))
        };
        let freq_hz = match &rec.freq_hz {
            Some(f) => mean(&f[r.clone()]),
            None => self.nominal_hz + slope / TAU,
        };
        OperatingPoint {
            v_mag_pu: mean(&rec.v_mag_pu[r.clone()]),
            v_ang_rad: angle_at_t0,
            p_pu: mean(&rec.p_pu[r.clone()]),
            q_pu: mean(&rec.q_pu[r.clone()]),
            freq_hz,
            t0_s,
            n_samples: n,
        }
    }

    /// Writes the playback record as a canonical CSV: header
    /// `time_s,v_re_pu,v_im_pu,p_pu,q_pu` followed by `freq_hz`, `efd_pu`, `ifd_pu` for the
    /// optional channels present. Numbers are written with 17 significant digits (like C's
    /// `%.17g`), which reproduces every `f64` exactly when read back. The real and imaginary
    /// parts are computed from |V| and the angle, so reading the file back gives |V| and the
    /// angle to within rounding (~1e-16 relative).
    pub fn write_csv(&self, path: &Path) -> Result<(), EventError> {
        let io_err = |source| EventError::Io {
            path: path.to_path_buf(),
            action: "cannot write the CSV file".into(),
            source,
        };
        let file = fs::File::create(path).map_err(io_err)?;
        let mut w = BufWriter::new(file);
        let rec = &self.record;
        let re = rec.v_re_pu();
        let im = rec.v_im_pu();
        let mut cols: Vec<(&str, &[f64])> = vec![
            ("time_s", &rec.time_s),
            ("v_re_pu", &re),
            ("v_im_pu", &im),
            ("p_pu", &rec.p_pu),
            ("q_pu", &rec.q_pu),
        ];
        if let Some(f) = &rec.freq_hz {
            cols.push(("freq_hz", f));
        }
        if let Some(e) = &rec.efd_pu {
            cols.push(("efd_pu", e));
        }
        if let Some(i) = &rec.ifd_pu {
            cols.push(("ifd_pu", i));
        }
        let header: Vec<&str> = cols.iter().map(|c| c.0).collect();
        writeln!(w, "{}", header.join(",")).map_err(io_err)?;
        let mut line = String::new();
        for i in 0..rec.len() {
            line.clear();
            for (j, (_, v)) in cols.iter().enumerate() {
                if j > 0 {
                    line.push(',');
                }
                line.push_str(&format_g17(v[i]));
            }
            writeln!(w, "{line}").map_err(io_err)?;
        }
        w.flush().map_err(io_err)?;
        Ok(())
    }
}

/// Formats `x` with 17 significant digits in the style of C's `%.17g` (trailing zeros removed,
/// exponent form for exponents < -4 or >= 17). Parsing the result gives back `x` exactly.
pub fn format_g17(x: f64) -> String {
    if !x.is_finite() {
        return format!("{x}");
    }
    if x == 0.0 {
        return if x.is_sign_negative() {
            "-0".into()
        } else {
            "0".into()
        };
    }
    let sci = format!("{x:.16e}"); // d.dddddddddddddddde±x
    let (mant, exp) = sci.split_once('e').expect("exponent");
    let exp: i32 = exp.parse().expect("integer exponent");
    let trim = |s: &str| -> String {
        if s.contains('.') {
            s.trim_end_matches('0').trim_end_matches('.').to_string()
        } else {
            s.to_string()
        }
    };
    if !(-4..17).contains(&exp) {
        let sign = if exp < 0 { '-' } else { '+' };
        format!("{}e{}{:02}", trim(mant), sign, exp.abs())
    } else {
        let decimals = (16 - exp) as usize;
        trim(&format!("{x:.decimals$}"))
    }
}

/// Resolves window specs against the record, validates them and builds the event.
#[allow(clippy::too_many_arguments)]
fn assemble(
    src: &Path,
    name: String,
    description: String,
    toml_path: Option<PathBuf>,
    csv_path: PathBuf,
    system_mva: f64,
    nominal_hz: f64,
    full: Record,
    playback: WindowSpec,
    init: WindowSpec,
    fit: WindowSpec,
) -> Result<Event, EventError> {
    let record_span = full.span();
    let record_desc = if csv_path.as_os_str().is_empty() {
        format!("the record {record_span}")
    } else {
        format!("the record {record_span} in {}", csv_path.display())
    };

    // Playback.
    let pb = resolve(playback, record_span.start_s, record_span.end_s);
    check_window(src, "playback", &pb, &record_span, &record_desc)?;
    let pb_range = full.window_range(&pb.window);
    check_count(src, "playback", &pb.window, pb_range.len())?;
    let mut record = full.slice(pb_range);
    record.normalize_angle_start();
    let pb_win = pb.window;
    let pb_desc = format!("the playback window {pb_win}");

    // Init.
    let init_start = init.start_s.unwrap_or(pb_win.start_s);
    let init_default_end = default_init_end(&record, init_start, pb_win.end_s);
    let iw = resolve(init, pb_win.start_s, init_default_end);
    check_window(src, "init", &iw, &pb_win, &pb_desc)?;
    check_count(
        src,
        "init",
        &iw.window,
        record.window_range(&iw.window).len(),
    )?;

    // Fit.
    let fw = resolve(fit, pb_win.start_s, pb_win.end_s);
    check_window(src, "fit", &fw, &pb_win, &pb_desc)?;
    check_count(
        src,
        "fit",
        &fw.window,
        record.window_range(&fw.window).len(),
    )?;

    Ok(Event {
        name,
        description,
        toml_path,
        csv_path,
        system_mva,
        nominal_hz,
        playback: pb_win,
        init: iw.window,
        fit: fw.window,
        record,
    })
}

/// The default end of the init window starting at `start`: `start + DEFAULT_INIT_S`, extended
/// to hold `DEFAULT_INIT_MIN_SAMPLES` samples if needed, never past `limit`.
fn default_init_end(rec: &Record, start: f64, limit: f64) -> f64 {
    let mut end = start + DEFAULT_INIT_S;
    let first = rec.time_s.partition_point(|&t| t < start - TIME_TOL_S);
    let in_default = rec.window_range(&Window::new(start, end)).len();
    if in_default < DEFAULT_INIT_MIN_SAMPLES {
        let idx = (first + DEFAULT_INIT_MIN_SAMPLES - 1).min(rec.len().saturating_sub(1));
        if let Some(&t) = rec.time_s.get(idx) {
            end = end.max(t);
        }
    }
    if start.is_finite() && end > limit && limit > start {
        end = limit;
    }
    end
}

struct Resolved {
    window: Window,
    start_default: bool,
    end_default: bool,
}

fn resolve(spec: WindowSpec, default_start: f64, default_end: f64) -> Resolved {
    Resolved {
        window: Window::new(
            spec.start_s.unwrap_or(default_start),
            spec.end_s.unwrap_or(default_end),
        ),
        start_default: spec.start_s.is_none(),
        end_default: spec.end_s.is_none(),
    }
}

fn check_window(
    src: &Path,
    name: &str,
    r: &Resolved,
    bounds: &Window,
    bounds_desc: &str,
) -> Result<(), EventError> {
    let w = &r.window;
    let tag = |default: bool| if default { " (default)" } else { "" };
    let err = |field: &str, message: String| EventError::BadWindow {
        path: src.to_path_buf(),
        field: format!("{name}.{field}"),
        message,
    };
    if !w.start_s.is_finite() {
        return Err(err(
            "start_s",
            format!("{} is not a finite number", w.start_s),
        ));
    }
    if !w.end_s.is_finite() {
        return Err(err("end_s", format!("{} is not a finite number", w.end_s)));
    }
    if w.end_s <= w.start_s {
        return Err(err(
            "end_s",
            format!(
                "{}{} s is not after {name}.start_s = {}{} s (window upside down or empty)",
                w.end_s,
                tag(r.end_default),
                w.start_s,
                tag(r.start_default)
            ),
        ));
    }
    if w.start_s < bounds.start_s - TIME_TOL_S {
        return Err(err(
            "start_s",
            format!(
                "{}{} s lies before the start of {bounds_desc}",
                w.start_s,
                tag(r.start_default)
            ),
        ));
    }
    if w.end_s > bounds.end_s + TIME_TOL_S {
        return Err(err(
            "end_s",
            format!(
                "{}{} s lies after the end of {bounds_desc}",
                w.end_s,
                tag(r.end_default)
            ),
        ));
    }
    Ok(())
}

fn check_count(src: &Path, name: &str, w: &Window, count: usize) -> Result<(), EventError> {
    if count < MIN_SAMPLES {
        return Err(EventError::TooFewSamples {
            path: src.to_path_buf(),
            what: format!("the {name} window {w}"),
            count,
            min: MIN_SAMPLES,
        });
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------------
// Record validation (shared by CSV and in-memory records)
// ---------------------------------------------------------------------------------------------

/// Names of the data columns as the user knows them (CSV header names or `Record` fields).
struct ColumnLabels {
    voltage: &'static str,
    magnitude: &'static str,
}

impl ColumnLabels {
    fn in_memory() -> Self {
        ColumnLabels {
            voltage: "v_mag_pu",
            magnitude: "v_mag_pu",
        }
    }
}

fn check_record_shape(src: &Path, rec: &Record) -> Result<(), EventError> {
    let n = rec.time_s.len();
    let mut fields: Vec<(&str, usize)> = vec![
        ("v_mag_pu", rec.v_mag_pu.len()),
        ("v_ang_rad", rec.v_ang_rad.len()),
        ("p_pu", rec.p_pu.len()),
        ("q_pu", rec.q_pu.len()),
    ];
    if let Some(v) = &rec.freq_hz {
        fields.push(("freq_hz", v.len()));
    }
    if let Some(v) = &rec.efd_pu {
        fields.push(("efd_pu", v.len()));
    }
    if let Some(v) = &rec.ifd_pu {
        fields.push(("ifd_pu", v.len()));
    }
    for (name, len) in fields {
        if len != n {
            return Err(EventError::RecordShape {
                path: src.to_path_buf(),
                message: format!("{name} has {len} samples but time_s has {n}"),
            });
        }
    }
    Ok(())
}

/// Validates a record whose vectors have equal lengths: sample count, finite values,
/// |V| >= 0, strictly increasing time and unit sanity.
fn validate_record(
    src: &Path,
    rec: &Record,
    nominal_hz: f64,
    labels: &ColumnLabels,
    loc: &dyn Fn(usize) -> Location,
) -> Result<(), EventError> {
    if rec.len() < MIN_SAMPLES {
        return Err(EventError::TooFewSamples {
            path: src.to_path_buf(),
            what: "the record".into(),
            count: rec.len(),
            min: MIN_SAMPLES,
        });
    }
    let mut channels: Vec<(&str, &[f64])> = vec![
        ("time_s", &rec.time_s),
        (labels.magnitude, &rec.v_mag_pu),
        ("v_ang_rad", &rec.v_ang_rad),
        ("p_pu", &rec.p_pu),
        ("q_pu", &rec.q_pu),
    ];
    if let Some(v) = &rec.freq_hz {
        channels.push(("freq_hz", v));
    }
    if let Some(v) = &rec.efd_pu {
        channels.push(("efd_pu", v));
    }
    if let Some(v) = &rec.ifd_pu {
        channels.push(("ifd_pu", v));
    }
    for (name, v) in &channels {
        if let Some(i) = v.iter().position(|x| !x.is_finite()) {
            return Err(EventError::BadNumber {
                path: src.to_path_buf(),
                at: loc(i),
                column: name.to_string(),
                text: v[i].to_string(),
                reason: "is not a finite number",
            });
        }
    }
    if let Some(i) = rec.v_mag_pu.iter().position(|&m| m < 0.0) {
        return Err(EventError::BadNumber {
            path: src.to_path_buf(),
            at: loc(i),
            column: labels.magnitude.to_string(),
            text: rec.v_mag_pu[i].to_string(),
            reason: "is negative; a voltage magnitude must be >= 0",
        });
    }
    for i in 1..rec.len() {
        if rec.time_s[i] <= rec.time_s[i - 1] {
            return Err(EventError::NonMonotonicTime {
                path: src.to_path_buf(),
                at: loc(i),
                prev_at: loc(i - 1),
                prev_time_s: rec.time_s[i - 1],
                time_s: rec.time_s[i],
            });
        }
    }

    // Units.
    let mut mags = rec.v_mag_pu.clone();
    mags.sort_by(f64::total_cmp);
    let n = mags.len();
    let median = if n % 2 == 1 {
        mags[n / 2]
    } else {
        0.5 * (mags[n / 2 - 1] + mags[n / 2])
    };
    let (vlo, vhi) = V_MEDIAN_RANGE_PU;
    if median > vhi {
        return Err(EventError::Units {
            path: src.to_path_buf(),
            column: labels.voltage.to_string(),
            at: None,
            message: format!(
                "median |V| = {median} is above {vhi}: the voltage looks like it is in kV or volts, \
                 not per unit; give it per unit of the rated terminal voltage"
            ),
        });
    }
    if median < vlo {
        return Err(EventError::Units {
            path: src.to_path_buf(),
            column: labels.voltage.to_string(),
            at: None,
            message: format!(
                "median |V| = {median} is below {vlo}: the voltage does not look like per unit \
                 of the rated terminal voltage (wrong base or units?); it must be per unit"
            ),
        });
    }
    for (name, v, what) in [("p_pu", &rec.p_pu, "MW"), ("q_pu", &rec.q_pu, "Mvar")] {
        if let Some((i, x)) = v
            .iter()
            .enumerate()
            .max_by(|a, b| a.1.abs().total_cmp(&b.1.abs()))
        {
            if x.abs() >= PQ_LIMIT_PU {
                return Err(EventError::Units {
                    path: src.to_path_buf(),
                    column: name.to_string(),
                    at: Some(loc(i)),
                    message: format!(
                        "|{name}| = {} is not below {PQ_LIMIT_PU} pu: this looks like {what}, not \
                         per unit; give it per unit on the system base ({what} / system_mva)",
                        x.abs()
                    ),
                });
            }
        }
    }
    if let Some(f) = &rec.freq_hz {
        // Rounded to µHz for the message (60 * 1.1 is 66.00000000000001 in f64).
        let lo = (nominal_hz * (1.0 - FREQ_TOLERANCE) * 1e6).round() / 1e6;
        let hi = (nominal_hz * (1.0 + FREQ_TOLERANCE) * 1e6).round() / 1e6;
        if let Some(i) = f.iter().position(|&x| x < lo || x > hi) {
            return Err(EventError::Units {
                path: src.to_path_buf(),
                column: "freq_hz".into(),
                at: Some(loc(i)),
                message: format!(
                    "{} Hz lies outside {lo}..{hi} Hz (nominal_hz = {nominal_hz} ± {} %): freq_hz \
                     must be the absolute frequency in Hz (maybe it was given as a deviation or \
                     in per unit?)",
                    f[i],
                    FREQ_TOLERANCE * 100.0
                ),
            });
        }
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------------
// CSV
// ---------------------------------------------------------------------------------------------

/// Reads an event CSV (format in the module documentation) into a [`Record`] holding every
/// sample of the file, with |V| and the unwrapped angle computed from whichever voltage form is
/// present. `nominal_hz` (> 0) is needed for the `freq_hz` sanity check. The file must hold at
/// least [`MIN_SAMPLES`] samples.
pub fn read_csv(path: &Path, nominal_hz: f64) -> Result<Record, EventError> {
    check_nominal_hz(path, nominal_hz)?;
    let file = fs::File::open(path).map_err(|source| EventError::Io {
        path: path.to_path_buf(),
        action: "cannot open the CSV file".into(),
        source,
    })?;
    let mut rdr = csv::ReaderBuilder::new()
        .has_headers(true)
        .flexible(true)
        .trim(csv::Trim::All)
        .from_reader(std::io::BufReader::new(file));

    let csv_err = |e: csv::Error| -> EventError {
        let line = e.position().map(|p| p.line() as usize);
        match e.into_kind() {
            csv::ErrorKind::Io(source) => EventError::Io {
                path: path.to_path_buf(),
                action: "cannot read the CSV file".into(),
                source,
            },
            other => EventError::CsvStructure {
                path: path.to_path_buf(),
                line,
                message: csv_kind_message(&other),
            },
        }
    };

    let headers = rdr.headers().map_err(csv_err)?.clone();
    if headers.is_empty() || (headers.len() == 1 && headers[0].is_empty()) {
        return Err(EventError::CsvStructure {
            path: path.to_path_buf(),
            line: Some(1),
            message: format!(
                "the file is empty; expected a header line with the columns {}",
                ACCEPTED_COLUMNS.join(", ")
            ),
        });
    }

    // Map columns (index into ACCEPTED_COLUMNS -> index in the record).
    let mut col: [Option<usize>; ACCEPTED_COLUMNS.len()] = [None; ACCEPTED_COLUMNS.len()];
    for (j, h) in headers.iter().enumerate() {
        match ACCEPTED_COLUMNS.iter().position(|c| *c == h) {
            None => {
                return Err(EventError::UnknownColumn {
                    path: path.to_path_buf(),
                    column: h.to_string(),
                })
            }
            Some(k) => {
                if col[k].is_some() {
                    return Err(EventError::DuplicateColumn {
                        path: path.to_path_buf(),
                        column: h.to_string(),
                    });
                }
                col[k] = Some(j);
            }
        }
    }
    let idx = |name: &str| col[ACCEPTED_COLUMNS.iter().position(|c| *c == name).unwrap()];
    let missing = |column: &str, detail: &str| EventError::MissingColumn {
        path: path.to_path_buf(),
        column: column.to_string(),
        detail: detail.to_string(),
    };
    for req in ["time_s", "p_pu", "q_pu"] {
        if idx(req).is_none() {
            return Err(missing(req, "(required)"));
        }
    }
    let (re, im, mag, ang) = (
        idx("v_re_pu"),
        idx("v_im_pu"),
        idx("v_pu"),
        idx("angle_deg"),
    );
    let rectangular = re.is_some() || im.is_some();
    let polar = mag.is_some() || ang.is_some();
    if rectangular && polar {
        return Err(EventError::ConflictingColumns {
            path: path.to_path_buf(),
            message: "both voltage forms are present (v_re_pu/v_im_pu and v_pu/angle_deg); \
                      give exactly one of them"
                .into(),
        });
    }
    const VOLTAGE_HINT: &str =
        "(the voltage is given either as v_re_pu and v_im_pu, or as v_pu and angle_deg)";
    let (va, vb, labels) = if polar {
        match (mag, ang) {
            (Some(a), Some(b)) => (
                a,
                b,
                ColumnLabels {
                    voltage: "v_pu",
                    magnitude: "v_pu",
                },
            ),
            (None, _) => return Err(missing("v_pu", VOLTAGE_HINT)),
            (_, None) => return Err(missing("angle_deg", VOLTAGE_HINT)),
        }
    } else {
        match (re, im) {
            (Some(a), Some(b)) => (
                a,
                b,
                ColumnLabels {
                    voltage: "v_re_pu/v_im_pu",
                    magnitude: "|V| from v_re_pu/v_im_pu",
                },
            ),
            (None, _) => return Err(missing("v_re_pu", VOLTAGE_HINT)),
            (_, None) => return Err(missing("v_im_pu", VOLTAGE_HINT)),
        }
    };
    let (t_i, p_i, q_i) = (
        idx("time_s").unwrap(),
        idx("p_pu").unwrap(),
        idx("q_pu").unwrap(),
    );
    let (f_i, e_i, i_i) = (idx("freq_hz"), idx("efd_pu"), idx("ifd_pu"));

    let mut lines: Vec<usize> = Vec::new();
    let mut time_s = Vec::new();
    let mut va_v = Vec::new();
    let mut vb_v = Vec::new();
    let mut p = Vec::new();
    let mut q = Vec::new();
    let mut fr = f_i.map(|_| Vec::new());
    let mut efd = e_i.map(|_| Vec::new());
    let mut ifd = i_i.map(|_| Vec::new());

    let mut row = csv::StringRecord::new();
    loop {
        match rdr.read_record(&mut row) {
            Ok(false) => break,
            Ok(true) => {}
            Err(e) => return Err(csv_err(e)),
        }
        let line = row.position().map(|p| p.line() as usize).unwrap_or(0);
        if row.len() != headers.len() {
            return Err(EventError::CsvStructure {
                path: path.to_path_buf(),
                line: Some(line),
                message: format!(
                    "expected {} fields (as in the header), found {}",
                    headers.len(),
                    row.len()
                ),
            });
        }
        let num = |j: usize| -> Result<f64, EventError> {
            let text = &row[j];
            match text.parse::<f64>() {
                Ok(x) if x.is_finite() => Ok(x),
                _ => Err(EventError::BadNumber {
                    path: path.to_path_buf(),
                    at: Location::Line(line),
                    column: headers[j].to_string(),
                    text: text.to_string(),
                    reason: if text.is_empty() {
                        "(empty field) is not a finite number"
                    } else {
                        "is not a finite number"
                    },
                }),
            }
        };
        time_s.push(num(t_i)?);
        va_v.push(num(va)?);
        vb_v.push(num(vb)?);
        p.push(num(p_i)?);
        q.push(num(q_i)?);
        if let (Some(j), Some(v)) = (f_i, fr.as_mut()) {
            v.push(num(j)?);
        }
        if let (Some(j), Some(v)) = (e_i, efd.as_mut()) {
            v.push(num(j)?);
        }
        if let (Some(j), Some(v)) = (i_i, ifd.as_mut()) {
            v.push(num(j)?);
        }
        lines.push(line);
    }

    let (v_mag_pu, raw_ang): (Vec<f64>, Vec<f64>) = if polar {
        (va_v, vb_v.iter().map(|d| d.to_radians()).collect())
    } else {
        (
            va_v.iter().zip(&vb_v).map(|(r, i)| r.hypot(*i)).collect(),
            va_v.iter().zip(&vb_v).map(|(r, i)| i.atan2(*r)).collect(),
        )
    };
    let mut rec = Record {
        time_s,
        v_mag_pu,
        v_ang_rad: unwrap_angles(&raw_ang),
        p_pu: p,
        q_pu: q,
        freq_hz: fr,
        efd_pu: efd,
        ifd_pu: ifd,
    };
    rec.normalize_angle_start();
    validate_record(path, &rec, nominal_hz, &labels, &|i| {
        Location::Line(lines[i])
    })?;
    Ok(rec)
}

fn csv_kind_message(kind: &csv::ErrorKind) -> String {
    match kind {
        csv::ErrorKind::Utf8 { err, .. } => format!("invalid UTF-8 text: {err}"),
        csv::ErrorKind::UnequalLengths {
            expected_len, len, ..
        } => format!("expected {expected_len} fields, found {len}"),
        other => format!("malformed CSV: {other:?}"),
    }
}

// ---------------------------------------------------------------------------------------------
// Tests
// ---------------------------------------------------------------------------------------------

#[cfg(test)]
#[allow(clippy::needless_range_loop)] // parallel per-sample arrays read best with an index
mod tests {
    use super::*;
    use std::f64::consts::PI;
    use std::sync::atomic::{AtomicUsize, Ordering};

    // ---- helpers ------------------------------------------------------------------------------

    /// A fresh, uniquely named directory under the system temp dir, removed on drop.
    struct TempDir(PathBuf);

    impl TempDir {
        fn new(tag: &str) -> TempDir {
            static COUNTER: AtomicUsize = AtomicUsize::new(0);
            let n = COUNTER.fetch_add(1, Ordering::SeqCst);
            let nanos = std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map(|d| d.subsec_nanos())
                .unwrap_or(0);
            let dir = std::env::temp_dir().join(format!(
                "itaipu-event-test-{}-{tag}-{n}-{nanos}",
                std::process::id()
            ));
            fs::create_dir_all(&dir).unwrap();
            TempDir(dir)
        }

        fn write(&self, name: &str, text: &str) -> PathBuf {
            let p = self.0.join(name);
            if let Some(parent) = p.parent() {
                fs::create_dir_all(parent).unwrap();
            }
            fs::write(&p, text).unwrap();
            p
        }
    }

    impl Drop for TempDir {
        fn drop(&mut self) {
            let _ = fs::remove_dir_all(&self.0);
        }
    }

    /// Seeded test data in [-1, 1): the workspace's one random source.
    struct Lcg(crate::rng::SplitMix64);

    impl Lcg {
        fn new(seed: u64) -> Self {
            Lcg(crate::rng::SplitMix64::new(seed))
        }
        fn uniform(&mut self) -> f64 {
            self.0.uniform_in(-1.0, 1.0)
        }
    }

    fn g(x: f64) -> String {
        format_g17(x)
    }

    /// CSV text in canonical re/im form from per-sample values.
    fn rect_csv(t: &[f64], mag: &[f64], ang: &[f64], p: &[f64], q: &[f64]) -> String {
        let mut s = String::from("time_s,v_re_pu,v_im_pu,p_pu,q_pu\n");
        for i in 0..t.len() {
            s += &format!(
                "{},{},{},{},{}\n",
                g(t[i]),
                g(mag[i] * ang[i].cos()),
                g(mag[i] * ang[i].sin()),
                g(p[i]),
                g(q[i])
            );
        }
        s
    }

    /// A simple valid CSV with `n` samples at 60 samples/s.
    fn simple_csv(n: usize) -> String {
        let t: Vec<f64> = (0..n).map(|i| i as f64 / 60.0).collect();
        let mag = vec![1.0; n];
        let ang: Vec<f64> = t.iter().map(|t| 0.1 + 0.05 * t).collect();
        rect_csv(&t, &mag, &ang, &vec![0.6; n], &vec![0.02; n])
    }

    fn toml_text(csv: &str, extra: &str) -> String {
        format!(
            "name = \"test-event\"\ndescription = \"unit test\"\ncsv = \"{csv}\"\nsystem_mva = 1000.0\nnominal_hz = 60.0\n{extra}"
        )
    }

    /// Asserts the kind and that the message contains every piece in `needles`.
    fn assert_err(e: &EventError, kind: &str, needles: &[&str]) {
        let msg = e.to_string();
        assert_eq!(e.kind(), kind, "wrong kind; message: {msg}");
        for n in needles {
            assert!(msg.contains(n), "message lacks {n:?}: {msg}");
        }
    }

    fn csv_err(tag: &str, text: &str) -> (TempDir, PathBuf, EventError) {
        let dir = TempDir::new(tag);
        let p = dir.write("data.csv", text);
        let e = read_csv(&p, 60.0).expect_err("expected an error");
        (dir, p, e)
    }

    fn ps(p: &Path) -> String {
        p.display().to_string()
    }

    /// Per-sample columns: time, |V|, angle (rad), P, Q.
    type Columns = (Vec<f64>, Vec<f64>, Vec<f64>, Vec<f64>, Vec<f64>);

    /// An Itaipu-like record, synthesised: 280 samples at 60/s (t = 0 … 4.65 s), |V| = 0.986,
    /// P = 0.6235, Q = 0.0225 at 60.01 Hz before a dip at 1.02–1.10 s, then the frequency falls
    /// linearly to 59.6 Hz, so the angle drifts by several hundred degrees and wraps at -180°.
    fn itaipu_like() -> Columns {
        let n = 280;
        let dt = 1.0 / 60.0;
        let mut t = Vec::new();
        let mut mag = Vec::new();
        let mut ang = Vec::new();
        let mut p = Vec::new();
        let mut q = Vec::new();
        let mut theta: f64 = 0.0;
        for i in 0..n {
            let ti = i as f64 * dt;
            let f = if ti < 1.1 {
                60.01
            } else {
                (60.01 - 0.4 * (ti - 1.1) / 1.0).max(59.6)
            };
            if i > 0 {
                theta += TAU * (f - 60.0) * dt;
            }
            let dip = (1.02..=1.10).contains(&ti);
            t.push(ti);
            mag.push(if dip { 0.856 } else { 0.986 });
            ang.push(theta);
            p.push(if dip {
                0.37
            } else {
                0.6235 + 0.2 * (ti - 1.1).max(0.0).sin()
            });
            q.push(if dip { 0.39 } else { 0.0225 });
        }
        (t, mag, ang, p, q)
    }

    // ---- reading valid data -------------------------------------------------------------------

    #[test]
    fn parses_itaipu_like_record_with_exact_header_and_unwraps() {
        let (t, mag, ang, p, q) = itaipu_like();
        // Sanity: the wrapped angle really crosses -180° (else this test proves nothing).
        let raw: Vec<f64> = ang.iter().map(|a| a.sin().atan2(a.cos())).collect();
        assert!(raw.windows(2).any(|w| (w[1] - w[0]).abs() > PI));
        let dir = TempDir::new("itaipu");
        let csv = dir.write("itaipu_pmu_60sps.csv", &rect_csv(&t, &mag, &ang, &p, &q));
        let rec = read_csv(&csv, 60.0).unwrap();
        assert_eq!(rec.len(), 280);
        assert_eq!(rec.time_s[0], 0.0);
        assert!((rec.end_s() - 4.65).abs() < 1e-12);
        assert!((rec.v_mag_pu[0] - 0.986).abs() < 1e-15);
        assert_eq!(rec.v_ang_rad[0], 0.0);
        assert!((rec.p_pu[0] - 0.6235).abs() < 1e-15);
        assert!((rec.q_pu[0] - 0.0225).abs() < 1e-15);
        assert!(rec.freq_hz.is_none() && rec.efd_pu.is_none() && rec.ifd_pu.is_none());
        for i in 0..rec.len() {
            assert!((rec.v_ang_rad[i] - ang[i]).abs() < 1e-12, "sample {i}");
        }
        // The drift is large (well beyond -180°).
        assert!(rec.v_ang_rad.last().unwrap().to_degrees() < -300.0);

        // As an event with the example windows; the operating point sees 60.01 Hz.
        let toml = dir.write(
            "itaipu.toml",
            &toml_text(
                "itaipu_pmu_60sps.csv",
                "[playback]\nstart_s = 0.0\nend_s = 4.65\n[init]\nstart_s = 0.0\nend_s = 0.95\n[fit]\nstart_s = 1.0\nend_s = 4.65\n",
            ),
        );
        let ev = Event::from_toml_file(&toml).unwrap();
        assert_eq!(ev.record.len(), 280);
        assert_eq!(ev.init, Window::new(0.0, 0.95));
        assert_eq!(ev.init_range(), 0..58);
        assert_eq!(ev.fit_range(), 60..280);
        let op = ev.operating_point();
        assert!((op.freq_hz - 60.01).abs() < 1e-9, "{}", op.freq_hz);
        assert!(op.v_ang_rad.abs() < 1e-9);
        assert!((op.v_mag_pu - 0.986).abs() < 1e-12);
        assert!((op.p_pu - 0.6235).abs() < 1e-12);
        assert_eq!(op.n_samples, 58);
    }

    #[test]
    fn unwraps_synthetic_record_0p4_hz_off_nominal() {
        // 0.4 Hz above and below nominal for 10 s: the wrapped angle crosses ±180° four times.
        for df in [0.4, -0.4] {
            let n = 600;
            let t: Vec<f64> = (0..n).map(|i| i as f64 / 60.0).collect();
            let theta0 = 170f64.to_radians();
            let ang: Vec<f64> = t.iter().map(|t| theta0 + TAU * df * t).collect();
            let wraps = ang
                .iter()
                .map(|a| a.sin().atan2(a.cos()))
                .collect::<Vec<_>>()
                .windows(2)
                .filter(|w| (w[1] - w[0]).abs() > PI)
                .count();
            assert!(wraps >= 3, "test data must wrap several times, got {wraps}");
            let dir = TempDir::new("unwrap");
            let p = dir.write(
                "u.csv",
                &rect_csv(&t, &vec![1.02; n], &ang, &vec![0.5; n], &vec![0.1; n]),
            );
            let rec = read_csv(&p, 60.0).unwrap();
            for i in 0..n {
                assert!(
                    (rec.v_ang_rad[i] - ang[i]).abs() < 1e-9,
                    "df {df} sample {i}: {} vs {}",
                    rec.v_ang_rad[i],
                    ang[i]
                );
            }
            // Frequency recovered from the unwrapped slope over the whole record.
            let ev = Event::from_toml_file(
                &dir.write("u.toml", &toml_text("u.csv", "[init]\nend_s = 9.9\n")),
            )
            .unwrap();
            assert!((ev.operating_point().freq_hz - (60.0 + df)).abs() < 1e-9);
        }
    }

    #[test]
    fn unwrap_angles_basic() {
        let raw = [3.0, -3.0, 3.1, -3.1, -2.0];
        let u = unwrap_angles(&raw);
        let expect = [3.0, -3.0 + TAU, 3.1, -3.1 + TAU, -2.0 + TAU];
        for (a, b) in u.iter().zip(expect) {
            assert!((a - b).abs() < 1e-12, "{u:?}");
        }
        // Continuous input is returned bit for bit.
        let smooth: Vec<f64> = (0..50).map(|i| -7.0 + 0.3 * i as f64).collect();
        assert_eq!(unwrap_angles(&smooth), smooth);
        assert!(unwrap_angles(&[]).is_empty());
    }

    #[test]
    fn polar_form_equals_rectangular_form() {
        let n = 300;
        let t: Vec<f64> = (0..n).map(|i| 0.25 + i as f64 / 50.0).collect();
        let mut lcg = Lcg::new(7);
        let mag: Vec<f64> = (0..n).map(|_| 1.0 + 0.05 * lcg.uniform()).collect();
        let ang: Vec<f64> = t.iter().map(|t| 2.5 - TAU * 0.3 * t).collect();
        let p: Vec<f64> = (0..n).map(|_| 0.7 + 0.1 * lcg.uniform()).collect();
        let q: Vec<f64> = (0..n).map(|_| -0.1 + 0.1 * lcg.uniform()).collect();
        let dir = TempDir::new("polar");
        let rect = dir.write("rect.csv", &rect_csv(&t, &mag, &ang, &p, &q));

        // Polar file: other column order, padded headers and fields, angle wrapped to ±180°.
        let mut s = String::from(" q_pu , angle_deg,time_s,  v_pu ,p_pu\n");
        for i in 0..n {
            let wrapped = ang[i].sin().atan2(ang[i].cos()).to_degrees();
            s += &format!(
                "{} , {},{},  {} ,{}\n",
                g(q[i]),
                g(wrapped),
                g(t[i]),
                g(mag[i]),
                g(p[i])
            );
        }
        let polar = dir.write("polar.csv", &s);
        // Polar file with the angle already unwrapped in degrees (< -360°).
        let mut s2 = String::from("time_s,v_pu,angle_deg,p_pu,q_pu\n");
        for i in 0..n {
            s2 += &format!(
                "{},{},{},{},{}\n",
                g(t[i]),
                g(mag[i]),
                g(ang[i].to_degrees()),
                g(p[i]),
                g(q[i])
            );
        }
        let polar2 = dir.write("polar2.csv", &s2);

        let a = read_csv(&rect, 60.0).unwrap();
        for b in [
            read_csv(&polar, 60.0).unwrap(),
            read_csv(&polar2, 60.0).unwrap(),
        ] {
            assert_eq!(a.time_s, b.time_s);
            assert_eq!(a.p_pu, b.p_pu);
            assert_eq!(a.q_pu, b.q_pu);
            for i in 0..n {
                assert!((a.v_mag_pu[i] - b.v_mag_pu[i]).abs() < 1e-14, "mag {i}");
                assert!((a.v_ang_rad[i] - b.v_ang_rad[i]).abs() < 1e-12, "ang {i}");
                assert!((a.v_ang_rad[i] - ang[i]).abs() < 1e-12, "truth {i}");
            }
        }
        assert!(a.v_ang_rad.last().unwrap().to_degrees() < -360.0);
    }

    #[test]
    fn optional_columns_blank_lines_and_bom_are_accepted() {
        let text = "\u{feff}time_s,v_re_pu,v_im_pu,p_pu,q_pu,ifd_pu,freq_hz,efd_pu\n\
                    0,1,0,0.5,0.1,1.5,60.02,2.0\n\n\
                    0.1,1,0,0.5,0.1,1.6,60.01,2.1\r\n\
                    0.2,1,0,0.5,0.1,1.7,59.99,2.2\n";
        let dir = TempDir::new("optional");
        let p = dir.write("o.csv", text);
        let rec = read_csv(&p, 60.0).unwrap();
        assert_eq!(rec.len(), 3);
        assert_eq!(rec.freq_hz, Some(vec![60.02, 60.01, 59.99]));
        assert_eq!(rec.efd_pu, Some(vec![2.0, 2.1, 2.2]));
        assert_eq!(rec.ifd_pu, Some(vec![1.5, 1.6, 1.7]));
    }

    // ---- operating point ----------------------------------------------------------------------

    /// Noisy record at 60.012 Hz: returns the CSV text and the true values.
    fn noisy_record(freq_col: Option<f64>) -> String {
        let n = 240; // 4 s at 60/s
        let mut lcg = Lcg::new(12345);
        let theta0 = 0.3;
        let df = 0.012;
        let mut s = String::from("time_s,v_re_pu,v_im_pu,p_pu,q_pu");
        if freq_col.is_some() {
            s += ",freq_hz";
        }
        s += "\n";
        for i in 0..n {
            let t = 2.0 + i as f64 / 60.0; // time axis that does not start at 0
            let mag = 1.01 + 0.003 * lcg.uniform();
            let ang = theta0 + TAU * df * (t - 2.0) + 0.003 * lcg.uniform();
            let p = 0.8 + 0.004 * lcg.uniform();
            let q = -0.05 + 0.004 * lcg.uniform();
            s += &format!(
                "{},{},{},{},{}",
                g(t),
                g(mag * ang.cos()),
                g(mag * ang.sin()),
                g(p),
                g(q)
            );
            if let Some(f) = freq_col {
                s += &format!(",{}", g(f + 0.01 * lcg.uniform()));
            }
            s += "\n";
        }
        s
    }

    #[test]
    fn operating_point_recovers_frequency_offset_and_means_from_noisy_data() {
        let dir = TempDir::new("op");
        dir.write("n.csv", &noisy_record(None));
        let toml = dir.write(
            "n.toml",
            &toml_text("n.csv", "[init]\nstart_s = 2.0\nend_s = 3.0\n"),
        );
        let ev = Event::from_toml_file(&toml).unwrap();
        assert_eq!(ev.init_range().len(), 61);
        let op = ev.operating_point();
        assert_eq!(op.t0_s, 2.0);
        assert_eq!(op.n_samples, 61);
        // Angle noise of ±0.003 rad per sample gives up to ±0.06 Hz from a two-sample
        // difference; the line fit gets within 1e-3 Hz of the true 60.012 Hz.
        assert!((op.freq_hz - 60.012).abs() < 1e-3, "freq {}", op.freq_hz);
        assert!(
            (op.v_ang_rad - 0.3).abs() < 1.5e-3,
            "angle {}",
            op.v_ang_rad
        );
        // Means of 61 samples with uniform noise ±0.003 (|V|) and ±0.004 (P, Q): standard
        // errors 2.2e-4 and 3.0e-4; tolerances are 4 standard errors.
        assert!((op.v_mag_pu - 1.01).abs() < 9e-4, "v {}", op.v_mag_pu);
        assert!((op.p_pu - 0.8).abs() < 1.2e-3, "p {}", op.p_pu);
        assert!((op.q_pu + 0.05).abs() < 1.2e-3, "q {}", op.q_pu);

        // Init window starting later than the playback start: the fitted line is extrapolated
        // back to t0 (the first playback sample), accounting for the drift in between.
        let toml2 = dir.write(
            "n2.toml",
            &toml_text("n.csv", "[init]\nstart_s = 3.0\nend_s = 4.0\n"),
        );
        let op2 = Event::from_toml_file(&toml2).unwrap().operating_point();
        assert_eq!(op2.t0_s, 2.0);
        assert!((op2.freq_hz - 60.012).abs() < 1e-3, "freq {}", op2.freq_hz);
        assert!(
            (op2.v_ang_rad - 0.3).abs() < 3e-3,
            "angle {}",
            op2.v_ang_rad
        );

        // Trimmed playback: t0 moves to the first playback sample and the angle follows the drift.
        let toml3 = dir.write(
            "n3.toml",
            &toml_text("n.csv", "[playback]\nstart_s = 3.0\n"),
        );
        let ev3 = Event::from_toml_file(&toml3).unwrap();
        assert_eq!(ev3.record.time_s[0], 3.0);
        assert_eq!(ev3.init, Window::new(3.0, 3.5));
        let op3 = ev3.operating_point();
        assert_eq!(op3.t0_s, 3.0);
        let expect = 0.3 + TAU * 0.012 * 1.0;
        assert!(
            (op3.v_ang_rad - expect).abs() < 3e-3,
            "angle {}",
            op3.v_ang_rad
        );
    }

    #[test]
    fn operating_point_uses_freq_column_mean_but_fitted_angle() {
        let dir = TempDir::new("opf");
        dir.write("f.csv", &noisy_record(Some(59.95)));
        let toml = dir.write("f.toml", &toml_text("f.csv", "[init]\nend_s = 3.0\n"));
        let ev = Event::from_toml_file(&toml).unwrap();
        let op = ev.operating_point();
        let r = ev.init_range();
        let f = ev.record.freq_hz.as_ref().unwrap();
        let mean = f[r.clone()].iter().sum::<f64>() / r.len() as f64;
        assert!((op.freq_hz - mean).abs() < 1e-12);
        assert!((op.freq_hz - 59.95).abs() < 3e-3);
        assert!(
            (op.v_ang_rad - 0.3).abs() < 1.5e-3,
            "angle {}",
            op.v_ang_rad
        );
    }

    // ---- TOML ---------------------------------------------------------------------------------

    #[test]
    fn toml_defaults_integers_and_relative_csv_path() {
        let dir = TempDir::new("defaults");
        dir.write("sub/data.csv", &simple_csv(120)); // 2 s at 60/s
        let toml = dir.write(
            "ev.toml",
            "name = \"x\"\ncsv = \"sub/data.csv\"\nsystem_mva = 100\nnominal_hz = 60\n",
        );
        let ev = Event::from_toml_file(&toml).unwrap();
        assert_eq!(ev.name, "x");
        assert_eq!(ev.description, "");
        assert_eq!(ev.system_mva, 100.0);
        assert_eq!(ev.nominal_hz, 60.0);
        assert_eq!(ev.toml_path.as_deref(), Some(toml.as_path()));
        assert_eq!(ev.csv_path, dir.0.join("sub/data.csv"));
        let last = 119.0 / 60.0;
        assert_eq!(ev.playback, Window::new(0.0, last));
        assert_eq!(ev.fit, ev.playback);
        assert_eq!(ev.init, Window::new(0.0, 0.5));
        assert_eq!(ev.init_range(), 0..31);
        assert_eq!(ev.record.len(), 120);
    }

    #[test]
    fn default_init_window_is_extended_to_ten_samples_for_slow_records() {
        // 10 samples/s: 0.5 s holds only 6 samples, so the default takes the first 10.
        let n = 50;
        let t: Vec<f64> = (0..n).map(|i| i as f64 / 10.0).collect();
        let dir = TempDir::new("slow");
        dir.write(
            "s.csv",
            &rect_csv(
                &t,
                &vec![1.0; n],
                &vec![0.0; n],
                &vec![0.5; n],
                &vec![0.0; n],
            ),
        );
        let ev = Event::from_toml_file(&dir.write("s.toml", &toml_text("s.csv", ""))).unwrap();
        assert_eq!(ev.init_range().len(), 10);
        assert!((ev.init.end_s - 0.9).abs() < 1e-12);
    }

    #[test]
    fn playback_trimming_keeps_only_window_samples_and_normalises_angle() {
        let n = 600;
        let t: Vec<f64> = (0..n).map(|i| i as f64 / 60.0).collect();
        let ang: Vec<f64> = t.iter().map(|t| -TAU * 0.5 * t).collect(); // -0.5 Hz
        let dir = TempDir::new("trim");
        dir.write(
            "t.csv",
            &rect_csv(&t, &vec![1.0; n], &ang, &vec![0.5; n], &vec![0.0; n]),
        );
        let toml = dir.write(
            "t.toml",
            &toml_text("t.csv", "[playback]\nstart_s = 4.5\nend_s = 8.0\n"),
        );
        let ev = Event::from_toml_file(&toml).unwrap();
        assert_eq!(ev.record.time_s[0], 4.5);
        assert!((ev.record.end_s() - 8.0).abs() < 1e-12);
        assert_eq!(ev.record.len(), 211);
        // True angle at 4.5 s is -4.5π; the record starts in [-π, π] and stays continuous.
        let a0 = ev.record.v_ang_rad[0];
        assert!((-PI..=PI).contains(&a0), "{a0}");
        assert!((a0 - (-4.5 * PI + 4.0 * PI)).abs() < 1e-9);
        assert!(ev
            .record
            .v_ang_rad
            .windows(2)
            .all(|w| (w[1] - w[0] + TAU * 0.5 / 60.0).abs() < 1e-9));
    }

    #[test]
    fn window_membership_uses_microsecond_tolerance() {
        let mut rec = mem_record(6);
        rec.time_s = vec![0.0, 0.1 + 3e-7, 0.2, 0.3 - 2e-7, 0.3 + 4e-6, 0.5];
        let w = Window::new(0.1 + 5e-7, 0.3 + 5e-7);
        // 0.1+3e-7 is 0.2 µs before the start and 0.3+4e-6 is 3.5 µs after the end.
        assert_eq!(rec.window_range(&w), 1..4);
        assert!(w.contains(0.1) && w.contains(0.3 + 1.4e-6));
        assert!(!w.contains(0.1 - 1e-6) && !w.contains(0.3 + 2e-6));
        assert_eq!(rec.window_range(&Window::new(0.6, 0.7)), 6..6);
        assert!((w.duration_s() - 0.2).abs() < 1e-15);
    }

    #[test]
    fn full_example_toml_parses() {
        let dir = TempDir::new("example");
        let (t, mag, ang, p, q) = itaipu_like();
        dir.write("itaipu_pmu_60sps.csv", &rect_csv(&t, &mag, &ang, &p, &q));
        let text = r#"
name = "itaipu-60hz-fault"
description = "free text"
csv = "itaipu_pmu_60sps.csv"     # path relative to the TOML file's folder
system_mva = 1000.0               # base of p_pu, q_pu in the CSV
nominal_hz = 60.0
[playback]            # optional
start_s = 0.0
end_s = 4.25
[init]
start_s = 0.0
end_s = 0.95
[fit]
start_s = 1.0
end_s = 4.25
"#;
        let ev = Event::from_toml_file(&dir.write("ev.toml", text)).unwrap();
        assert_eq!(ev.name, "itaipu-60hz-fault");
        assert_eq!(ev.description, "free text");
        assert_eq!(ev.playback, Window::new(0.0, 4.25));
        assert_eq!(ev.fit, Window::new(1.0, 4.25));
        assert_eq!(ev.record.len(), 256);
    }

    // ---- write / read round trip --------------------------------------------------------------

    #[test]
    fn write_csv_round_trips() {
        let n = 100;
        let mut lcg = Lcg::new(99);
        let t: Vec<f64> = (0..n)
            .map(|i| 10.0 + i as f64 * 0.02 + 1e-7 * lcg.uniform())
            .collect();
        let rec = Record {
            v_mag_pu: (0..n).map(|_| 1.0 + 0.1 * lcg.uniform()).collect(),
            v_ang_rad: t.iter().map(|t| 1.0 + TAU * 0.7 * (t - 10.0)).collect(),
            p_pu: (0..n).map(|_| 0.5 + 0.3 * lcg.uniform()).collect(),
            q_pu: (0..n).map(|_| 1e-9 * lcg.uniform()).collect(),
            freq_hz: Some((0..n).map(|_| 60.7 + 0.01 * lcg.uniform()).collect()),
            efd_pu: Some((0..n).map(|_| 2.0 + lcg.uniform()).collect()),
            ifd_pu: Some((0..n).map(|_| 1e6 * lcg.uniform().abs() + 1e-300).collect()),
            time_s: t,
        };
        let ev = Event::from_record("rt", rec.clone(), 500.0, 60.0, None, None).unwrap();
        assert_eq!(ev.record, rec, "from_record must not alter a valid record");
        let dir = TempDir::new("roundtrip");
        let path = dir.0.join("out.csv");
        ev.write_csv(&path).unwrap();
        let text = fs::read_to_string(&path).unwrap();
        assert_eq!(
            text.lines().next().unwrap(),
            "time_s,v_re_pu,v_im_pu,p_pu,q_pu,freq_hz,efd_pu,ifd_pu"
        );
        let back = read_csv(&path, 60.0).unwrap();
        // Stored channels are reproduced bit for bit (17 significant digits).
        assert_eq!(back.time_s, rec.time_s);
        assert_eq!(back.p_pu, rec.p_pu);
        assert_eq!(back.q_pu, rec.q_pu);
        assert_eq!(back.freq_hz, rec.freq_hz);
        assert_eq!(back.efd_pu, rec.efd_pu);
        assert_eq!(back.ifd_pu, rec.ifd_pu);
        // |V| and angle go through re/im: equal to rounding.
        for i in 0..n {
            assert!(
                (back.v_mag_pu[i] - rec.v_mag_pu[i]).abs() < 1e-15,
                "mag {i}"
            );
            assert!(
                (back.v_ang_rad[i] - rec.v_ang_rad[i]).abs() < 1e-13,
                "ang {i}"
            );
        }
    }

    #[test]
    fn format_g17_matches_c_printf() {
        // Expected strings are C's printf("%.17g").
        assert_eq!(format_g17(4.65), "4.6500000000000004");
        assert_eq!(format_g17(0.1), "0.10000000000000001");
        assert_eq!(format_g17(1e-7), "9.9999999999999995e-08");
        assert_eq!(format_g17(-623.5), "-623.5");
        assert_eq!(format_g17(1e20), "1e+20");
        assert_eq!(format_g17(1e16), "10000000000000000");
        assert_eq!(format_g17(0.0001), "0.0001");
        assert_eq!(format_g17(1e-5), "1.0000000000000001e-05");
        assert_eq!(format_g17(0.0), "0");
        let mut lcg = Lcg::new(3);
        for _ in 0..2000 {
            let x = lcg.uniform() * 10f64.powi((lcg.uniform() * 300.0) as i32);
            assert_eq!(format_g17(x).parse::<f64>().unwrap(), x);
        }
    }

    // ---- in-memory events ---------------------------------------------------------------------

    fn mem_record(n: usize) -> Record {
        let t: Vec<f64> = (0..n).map(|i| i as f64 / 60.0).collect();
        Record {
            v_mag_pu: vec![1.0; n],
            v_ang_rad: vec![0.2; n],
            p_pu: vec![0.5; n],
            q_pu: vec![0.1; n],
            freq_hz: None,
            efd_pu: None,
            ifd_pu: None,
            time_s: t,
        }
    }

    #[test]
    fn from_record_unwraps_and_applies_windows() {
        let n = 300;
        let t: Vec<f64> = (0..n).map(|i| i as f64 / 60.0).collect();
        let truth: Vec<f64> = t.iter().map(|t| 3.0 + TAU * 0.4 * t).collect();
        let re: Vec<f64> = truth.iter().map(|a| a.cos()).collect();
        let im: Vec<f64> = truth.iter().map(|a| a.sin()).collect();
        let rec = Record::from_rectangular(t, &re, &im, vec![0.5; n], vec![0.1; n]);
        let ev = Event::from_record(
            "syn",
            rec,
            100.0,
            60.0,
            Some(Window::new(0.0, 1.0)),
            Some(Window::new(1.0, 4.0)),
        )
        .unwrap();
        assert_eq!(ev.toml_path, None);
        assert_eq!(ev.fit_range(), 60..241);
        for (a, b) in ev.record.v_ang_rad.iter().zip(&truth) {
            assert!((a - b).abs() < 1e-9);
        }
        let op = ev.operating_point();
        assert!((op.freq_hz - 60.4).abs() < 1e-9);
        assert!((op.v_ang_rad - 3.0).abs() < 1e-9);

        // A wrapped angle handed in directly is unwrapped too.
        let mut rec2 = mem_record(10);
        rec2.v_ang_rad = vec![3.0, -3.0, -2.9, 3.1, 3.0, 2.9, -3.1, 3.1, 3.0, 2.9];
        let ev2 = Event::from_record("w", rec2, 100.0, 60.0, None, None).unwrap();
        assert!(ev2
            .record
            .v_ang_rad
            .windows(2)
            .all(|w| (w[1] - w[0]).abs() < PI));
    }

    #[test]
    fn from_record_errors_name_source_and_sample() {
        let mut r = mem_record(10);
        r.p_pu.pop();
        let e = Event::from_record("m", r, 100.0, 60.0, None, None).unwrap_err();
        assert_err(
            &e,
            "record_shape",
            &["<in-memory event 'm'>", "p_pu has 9 samples"],
        );

        let mut r = mem_record(10);
        r.q_pu[4] = f64::NAN;
        let e = Event::from_record("m", r, 100.0, 60.0, None, None).unwrap_err();
        assert_err(
            &e,
            "bad_number",
            &["<in-memory event 'm'>", "sample 4", "q_pu", "NaN"],
        );

        let mut r = mem_record(10);
        r.time_s[6] = r.time_s[5];
        let e = Event::from_record("m", r, 100.0, 60.0, None, None).unwrap_err();
        assert_err(
            &e,
            "non_monotonic_time",
            &["<in-memory event 'm'>", "sample 6", "sample 5"],
        );

        let mut r = mem_record(10);
        r.v_mag_pu = vec![400.0; 10];
        let e = Event::from_record("m", r, 100.0, 60.0, None, None).unwrap_err();
        assert_err(&e, "units", &["<in-memory event 'm'>", "v_mag_pu", "kV"]);

        let e = Event::from_record("m", mem_record(10), 0.0, 60.0, None, None).unwrap_err();
        assert_err(
            &e,
            "invalid_value",
            &["<in-memory event 'm'>", "system_mva"],
        );
        let e = Event::from_record("m", mem_record(10), 100.0, f64::NAN, None, None).unwrap_err();
        assert_err(&e, "invalid_value", &["nominal_hz"]);

        let e = Event::from_record(
            "m",
            mem_record(10),
            100.0,
            60.0,
            Some(Window::new(0.1, 0.05)),
            None,
        )
        .unwrap_err();
        assert_err(&e, "bad_window", &["<in-memory event 'm'>", "init.end_s"]);
        let e = Event::from_record(
            "m",
            mem_record(10),
            100.0,
            60.0,
            None,
            Some(Window::new(0.0, 1.0)),
        )
        .unwrap_err();
        assert_err(&e, "bad_window", &["fit.end_s", "after the end"]);
    }

    // ---- CSV errors ---------------------------------------------------------------------------

    #[test]
    fn error_missing_column() {
        let (_d, p, e) = csv_err(
            "miss",
            "time_s,v_re_pu,v_im_pu,p_pu\n0,1,0,0.5\n0.1,1,0,0.5\n0.2,1,0,0.5\n",
        );
        assert_err(&e, "missing_column", &[&ps(&p), "line 1", "'q_pu'"]);

        let (_d, p, e) = csv_err(
            "miss2",
            "time_s,v_re_pu,p_pu,q_pu\n0,1,0.5,0\n0.1,1,0.5,0\n0.2,1,0.5,0\n",
        );
        assert_err(
            &e,
            "missing_column",
            &[&ps(&p), "'v_im_pu'", "v_pu and angle_deg"],
        );

        let (_d, p, e) = csv_err("miss3", "time_s,p_pu,q_pu\n0,0.5,0\n0.1,0.5,0\n0.2,0.5,0\n");
        assert_err(&e, "missing_column", &[&ps(&p), "'v_re_pu'"]);

        let (_d, p, e) = csv_err(
            "miss4",
            "time_s,angle_deg,p_pu,q_pu\n0,1,0.5,0\n0.1,1,0.5,0\n0.2,1,0.5,0\n",
        );
        assert_err(&e, "missing_column", &[&ps(&p), "'v_pu'"]);
    }

    #[test]
    fn error_both_voltage_forms() {
        let (_d, p, e) = csv_err(
            "both",
            "time_s,v_re_pu,v_im_pu,v_pu,angle_deg,p_pu,q_pu\n0,1,0,1,0,0.5,0\n",
        );
        assert_err(&e, "conflicting_columns", &[&ps(&p), "exactly one"]);
    }

    #[test]
    fn error_unknown_column() {
        let (_d, p, e) = csv_err("unk", "time_s,v_re_pu,v_im_pu,p_mw,q_pu\n0,1,0,500,0\n");
        assert_err(
            &e,
            "unknown_column",
            &[
                &ps(&p),
                "line 1",
                "'p_mw'",
                "time_s, v_re_pu, v_im_pu, v_pu, angle_deg, p_pu, q_pu, freq_hz, efd_pu, ifd_pu",
            ],
        );
    }

    #[test]
    fn error_duplicate_column() {
        let (_d, p, e) = csv_err(
            "dup",
            "time_s,v_re_pu,v_im_pu,p_pu,q_pu, p_pu\n0,1,0,0.5,0,0.5\n",
        );
        assert_err(&e, "duplicate_column", &[&ps(&p), "line 1", "'p_pu'"]);
    }

    #[test]
    fn error_nan_field() {
        // Only one bad value, on line 17.
        let mut rows: Vec<String> = simple_csv(20).lines().map(String::from).collect();
        rows[16] = rows[16].replacen(",0.59999999999999998,", ",NaN,", 1);
        let (_d, p, e) = csv_err("nan17", &(rows.join("\n") + "\n"));
        assert_err(
            &e,
            "bad_number",
            &[
                &ps(&p),
                "line 17, column p_pu: 'NaN' is not a finite number",
            ],
        );

        let mut rows: Vec<String> = simple_csv(20).lines().map(String::from).collect();
        rows[3] = rows[3].replacen(",0.02", ",inf", 1);
        let (_d, p, e) = csv_err("inf", &(rows.join("\n") + "\n"));
        assert_err(&e, "bad_number", &[&ps(&p), "line 4, column q_pu", "'inf'"]);

        let mut rows: Vec<String> = simple_csv(20).lines().map(String::from).collect();
        rows[5] = rows[5].replacen("0.", "zero.", 1);
        let (_d, p, e) = csv_err("text", &(rows.join("\n") + "\n"));
        assert_err(
            &e,
            "bad_number",
            &[&ps(&p), "line 6, column time_s", "'zero."],
        );
    }

    #[test]
    fn error_empty_field() {
        let text = "time_s,v_re_pu,v_im_pu,p_pu,q_pu\n0,1,0,0.5,0\n0.1,1, ,0.5,0\n0.2,1,0,0.5,0\n";
        let (_d, p, e) = csv_err("empty", text);
        assert_err(
            &e,
            "bad_number",
            &[&ps(&p), "line 3, column v_im_pu", "empty field"],
        );
    }

    #[test]
    fn error_wrong_field_count() {
        let text = "time_s,v_re_pu,v_im_pu,p_pu,q_pu\n0,1,0,0.5,0\n0.1,1,0,0.5\n0.2,1,0,0.5,0\n";
        let (_d, p, e) = csv_err("count", text);
        assert_err(
            &e,
            "csv_structure",
            &[&ps(&p), "line 3", "expected 5 fields", "found 4"],
        );
        let text =
            "time_s,v_re_pu,v_im_pu,p_pu,q_pu\n0,1,0,0.5,0\n0.1,1,0,0.5,0\n0.2,1,0,0.5,0,7\n";
        let (_d, p, e) = csv_err("count2", text);
        assert_err(&e, "csv_structure", &[&ps(&p), "line 4", "found 6"]);
    }

    #[test]
    fn error_empty_file() {
        let (_d, p, e) = csv_err("emptyfile", "");
        assert_err(&e, "csv_structure", &[&ps(&p), "empty"]);
    }

    #[test]
    fn error_non_monotonic_time() {
        let text = "time_s,v_re_pu,v_im_pu,p_pu,q_pu\n0,1,0,0.5,0\n0.1,1,0,0.5,0\n0.2,1,0,0.5,0\n0.15,1,0,0.5,0\n";
        let (_d, p, e) = csv_err("mono", text);
        assert_err(
            &e,
            "non_monotonic_time",
            &[&ps(&p), "line 5", "0.15", "0.2", "line 4"],
        );
    }

    #[test]
    fn error_duplicate_time() {
        let text = "time_s,v_re_pu,v_im_pu,p_pu,q_pu\n0,1,0,0.5,0\n0.1,1,0,0.5,0\n0.1,1,0,0.5,0\n0.2,1,0,0.5,0\n";
        let (_d, p, e) = csv_err("duptime", text);
        assert_err(
            &e,
            "non_monotonic_time",
            &[&ps(&p), "line 4", "time 0.1 s", "time 0.1 s (line 3)"],
        );
    }

    #[test]
    fn error_too_few_samples() {
        // Whole file.
        let text = "time_s,v_re_pu,v_im_pu,p_pu,q_pu\n0,1,0,0.5,0\n0.1,1,0,0.5,0\n";
        let (_d, p, e) = csv_err("few", text);
        assert_err(
            &e,
            "too_few_samples",
            &[&ps(&p), "holds 2 sample(s)", "at least 3"],
        );
        // Header only.
        let (_d, p, e) = csv_err("few0", "time_s,v_re_pu,v_im_pu,p_pu,q_pu\n");
        assert_err(&e, "too_few_samples", &[&ps(&p), "holds 0"]);
        // Playback window holding 2 samples of a longer record.
        let dir = TempDir::new("fewpb");
        dir.write("d.csv", &simple_csv(60));
        let toml = dir.write(
            "e.toml",
            &toml_text("d.csv", "[playback]\nstart_s = 0.5\nend_s = 0.52\n"),
        );
        let e = Event::from_toml_file(&toml).unwrap_err();
        assert_err(
            &e,
            "too_few_samples",
            &[&ps(&toml), "playback window", "holds 2"],
        );
        // Init window holding 2 samples.
        let toml = dir.write(
            "i.toml",
            &toml_text("d.csv", "[init]\nstart_s = 0.1\nend_s = 0.12\n"),
        );
        let e = Event::from_toml_file(&toml).unwrap_err();
        assert_err(
            &e,
            "too_few_samples",
            &[&ps(&toml), "init window", "holds 2"],
        );
    }

    #[test]
    fn error_kv_instead_of_pu() {
        let n = 30;
        let t: Vec<f64> = (0..n).map(|i| i as f64 / 60.0).collect();
        let text = rect_csv(
            &t,
            &vec![13.8; n],
            &vec![0.1; n],
            &vec![0.5; n],
            &vec![0.0; n],
        );
        let (_d, p, e) = csv_err("kv", &text);
        assert_err(&e, "units", &[&ps(&p), "v_re_pu/v_im_pu", "kV", "per unit"]);
        // Volts in polar form.
        let mut s = String::from("time_s,v_pu,angle_deg,p_pu,q_pu\n");
        for ti in &t {
            s += &format!("{ti},13800,5,0.5,0\n");
        }
        let (_d, p, e) = csv_err("volts", &s);
        assert_err(&e, "units", &[&ps(&p), "column v_pu", "volts"]);
        // Too small (e.g. a wrong base).
        let text = rect_csv(
            &t,
            &vec![0.0138; n],
            &vec![0.1; n],
            &vec![0.5; n],
            &vec![0.0; n],
        );
        let (_d, p, e) = csv_err("small", &text);
        assert_err(&e, "units", &[&ps(&p), "per unit"]);
        // A record with a deep but short dip is fine (median, not minimum).
        let mut mag = vec![1.0; n];
        mag[10] = 0.2;
        mag[11] = 0.2;
        let dir = TempDir::new("dip");
        let ok = dir.write(
            "dip.csv",
            &rect_csv(&t, &mag, &vec![0.1; n], &vec![0.5; n], &vec![0.0; n]),
        );
        assert!(read_csv(&ok, 60.0).is_ok());
    }

    #[test]
    fn error_mw_instead_of_pu() {
        let n = 30;
        let t: Vec<f64> = (0..n).map(|i| i as f64 / 60.0).collect();
        let mut p = vec![0.6235; n];
        p[7] = 623.5;
        let text = rect_csv(&t, &vec![1.0; n], &vec![0.0; n], &p, &vec![0.02; n]);
        let (_d, path, e) = csv_err("mw", &text);
        assert_err(
            &e,
            "units",
            &[
                &ps(&path),
                "line 9, column p_pu",
                "MW",
                "per unit",
                "system_mva",
            ],
        );
        let mut q = vec![0.02; n];
        q[0] = -22.5;
        let text = rect_csv(&t, &vec![1.0; n], &vec![0.0; n], &vec![0.6; n], &q);
        let (_d, path, e) = csv_err("mvar", &text);
        assert_err(&e, "units", &[&ps(&path), "line 2, column q_pu", "Mvar"]);
        // 19.9 pu is accepted (limit is 20).
        let text = rect_csv(
            &t,
            &vec![1.0; n],
            &vec![0.0; n],
            &vec![19.9; n],
            &vec![0.0; n],
        );
        let dir = TempDir::new("mwok");
        assert!(read_csv(&dir.write("ok.csv", &text), 60.0).is_ok());
    }

    #[test]
    fn error_bad_freq() {
        let mut s = String::from("time_s,v_re_pu,v_im_pu,p_pu,q_pu,freq_hz\n");
        for i in 0..10 {
            let f = if i < 4 { 60.0 } else { 0.01 }; // deviation instead of absolute
            s += &format!("{},1,0,0.5,0,{f}\n", i as f64 * 0.1);
        }
        let (_d, p, e) = csv_err("freq", &s);
        assert_err(
            &e,
            "units",
            &[&ps(&p), "line 6, column freq_hz", "deviation", "per unit"],
        );
        // Per unit frequency (1.0) with nominal 50 Hz.
        let mut s = String::from("time_s,v_re_pu,v_im_pu,p_pu,q_pu,freq_hz\n");
        for i in 0..10 {
            s += &format!("{},1,0,0.5,0,1.0\n", i as f64 * 0.1);
        }
        let dir = TempDir::new("freqpu");
        let p = dir.write("f.csv", &s);
        let e = read_csv(&p, 50.0).unwrap_err();
        assert_err(&e, "units", &[&ps(&p), "line 2", "outside 45..55 Hz"]);
        // Just inside the ±10 % band (54 … 66 Hz at 60 Hz nominal) is accepted.
        let mut s = String::from("time_s,v_re_pu,v_im_pu,p_pu,q_pu,freq_hz\n");
        for i in 0..10 {
            s += &format!("{},1,0,0.5,0,54.01\n", i as f64 * 0.1);
        }
        assert!(read_csv(&dir.write("ok.csv", &s), 60.0).is_ok());
    }

    #[test]
    fn error_missing_csv_file() {
        let dir = TempDir::new("nocsv");
        let toml = dir.write("e.toml", &toml_text("missing.csv", ""));
        let e = Event::from_toml_file(&toml).unwrap_err();
        let csv = dir.0.join("missing.csv");
        assert_err(
            &e,
            "io",
            &[
                &ps(&csv),
                &format!("cannot open the CSV file named in {}", ps(&toml)),
            ],
        );
        assert_eq!(e.path(), csv.as_path());
        let e = read_csv(&csv, 60.0).unwrap_err();
        assert_err(&e, "io", &[&ps(&csv)]);
        // A missing TOML file.
        let missing = dir.0.join("nope.toml");
        let e = Event::from_toml_file(&missing).unwrap_err();
        assert_err(&e, "io", &[&ps(&missing), "event file"]);
    }

    // ---- TOML errors --------------------------------------------------------------------------

    #[test]
    fn error_unknown_toml_key() {
        let dir = TempDir::new("unkkey");
        dir.write("d.csv", &simple_csv(60));
        let toml = dir.write("e.toml", &toml_text("d.csv", "nominal_freq = 60.0\n"));
        let e = Event::from_toml_file(&toml).unwrap_err();
        assert_err(
            &e,
            "unknown_field",
            &[&ps(&toml), "line 6", "`nominal_freq`", "nominal_hz"],
        );

        let toml = dir.write(
            "w.toml",
            &toml_text("d.csv", "[init]\nstart_s = 0.0\nstop_s = 0.5\n"),
        );
        let e = Event::from_toml_file(&toml).unwrap_err();
        assert_err(
            &e,
            "unknown_field",
            &[&ps(&toml), "line 8", "`init.stop_s`", "start_s, end_s"],
        );

        // An unknown table is an unknown key too.
        let toml = dir.write("t.toml", &toml_text("d.csv", "[initial]\nstart_s = 0.0\n"));
        let e = Event::from_toml_file(&toml).unwrap_err();
        assert_err(&e, "unknown_field", &[&ps(&toml), "`initial`"]);
    }

    #[test]
    fn error_missing_toml_key_syntax_and_types() {
        let dir = TempDir::new("tomlerr");
        dir.write("d.csv", &simple_csv(60));
        let toml = dir.write(
            "m.toml",
            "name = \"x\"\ncsv = \"d.csv\"\nnominal_hz = 60.0\n",
        );
        let e = Event::from_toml_file(&toml).unwrap_err();
        assert_err(&e, "missing_field", &[&ps(&toml), "`system_mva`"]);

        let toml = dir.write("s.toml", "name = \"x\"\ncsv = \"d.csv\nsystem_mva = 1\n");
        let e = Event::from_toml_file(&toml).unwrap_err();
        assert_err(&e, "toml_syntax", &[&ps(&toml), "line 2"]);

        let toml = dir.write(
            "ty.toml",
            "name = \"x\"\ncsv = \"d.csv\"\nsystem_mva = \"1000\"\nnominal_hz = 60.0\n",
        );
        let e = Event::from_toml_file(&toml).unwrap_err();
        assert_err(&e, "toml_value", &[&ps(&toml), "line 3", "system_mva"]);

        let toml = dir.write("z.toml", &toml_text("d.csv", "").replace("1000.0", "-5.0"));
        let e = Event::from_toml_file(&toml).unwrap_err();
        assert_err(&e, "invalid_value", &[&ps(&toml), "system_mva = -5"]);

        let toml = dir.write("nf.toml", &toml_text("d.csv", "").replace("60.0", "nan"));
        let e = Event::from_toml_file(&toml).unwrap_err();
        assert_err(&e, "invalid_value", &[&ps(&toml), "nominal_hz = NaN"]);
    }

    #[test]
    fn error_window_upside_down() {
        let dir = TempDir::new("upside");
        dir.write("d.csv", &simple_csv(120));
        let toml = dir.write(
            "e.toml",
            &toml_text("d.csv", "[init]\nstart_s = 0.9\nend_s = 0.2\n"),
        );
        let e = Event::from_toml_file(&toml).unwrap_err();
        assert_err(
            &e,
            "bad_window",
            &[&ps(&toml), "init.end_s", "0.2", "0.9", "upside down"],
        );

        let toml = dir.write(
            "p.toml",
            &toml_text("d.csv", "[playback]\nstart_s = 1.0\nend_s = 1.0\n"),
        );
        let e = Event::from_toml_file(&toml).unwrap_err();
        assert_err(&e, "bad_window", &[&ps(&toml), "playback.end_s"]);

        // Default end before an explicit start: the message says which value was defaulted.
        let toml = dir.write(
            "f.toml",
            &toml_text("d.csv", "[playback]\nend_s = 1.5\n[fit]\nstart_s = 1.6\n"),
        );
        let e = Event::from_toml_file(&toml).unwrap_err();
        assert_err(&e, "bad_window", &[&ps(&toml), "fit.end_s", "(default)"]);
    }

    #[test]
    fn error_window_outside_record() {
        let dir = TempDir::new("outside");
        dir.write("d.csv", &simple_csv(120)); // 0 … 1.983 s
        let toml = dir.write("e.toml", &toml_text("d.csv", "[playback]\nend_s = 10.0\n"));
        let e = Event::from_toml_file(&toml).unwrap_err();
        assert_err(
            &e,
            "bad_window",
            &[
                &ps(&toml),
                "playback.end_s",
                "10",
                "after the end of the record",
                "d.csv",
            ],
        );

        let toml = dir.write("s.toml", &toml_text("d.csv", "[fit]\nstart_s = -1.0\n"));
        let e = Event::from_toml_file(&toml).unwrap_err();
        assert_err(
            &e,
            "bad_window",
            &[
                &ps(&toml),
                "fit.start_s",
                "before the start of the playback window",
            ],
        );

        // init must lie inside the (trimmed) playback window.
        let toml = dir.write(
            "i.toml",
            &toml_text(
                "d.csv",
                "[playback]\nstart_s = 0.5\n[init]\nstart_s = 0.0\nend_s = 1.0\n",
            ),
        );
        let e = Event::from_toml_file(&toml).unwrap_err();
        assert_err(
            &e,
            "bad_window",
            &[&ps(&toml), "init.start_s", "playback window"],
        );

        // Non-finite bound.
        let toml = dir.write("n.toml", &toml_text("d.csv", "[fit]\nend_s = inf\n"));
        let e = Event::from_toml_file(&toml).unwrap_err();
        assert_err(
            &e,
            "bad_window",
            &[&ps(&toml), "fit.end_s", "not a finite number"],
        );

        // Sub-microsecond overshoot is tolerated.
        let last = 119.0 / 60.0;
        let toml = dir.write(
            "ok.toml",
            &toml_text("d.csv", &format!("[playback]\nend_s = {}\n", last + 5e-7)),
        );
        assert_eq!(Event::from_toml_file(&toml).unwrap().record.len(), 120);
    }
}
