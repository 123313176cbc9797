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
//! onset_s = 1.0167                     # optional: when the disturbance starts; default detected
//! input_lowpass_hz = 4.0               # optional: the played-back |V| and angle's low-pass, or "none" (below)
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
//! A staged test also declares what was recorded and what was done (`channels`, `time_base`,
//! `[[step]]`: the `declare` module, [`Declaration`]): a record without an angle (`channels`
//! without `"angle"`, |V| as `v_pu` alone), a non-uniform time base (kept as recorded), and
//! set-point steps (`time_s`, `size_pu`, `reference = "v_ref"`) inside the playback window, the
//! default init window ending before the first.
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
//!   Default: the steady pre-event part, from the playback start to [`ONSET_GUARD_SAMPLES`]
//!   (3) samples before the event's onset (below), but at least [`MIN_SAMPLES`] samples. An
//!   event without an onset (ambient data) keeps the older rule: [`DEFAULT_INIT_S`] (0.5 s) from
//!   the playback start, extended to the first [`DEFAULT_INIT_MIN_SAMPLES`] (10) samples if those
//!   0.5 s hold fewer (slow recordings), never past the playback window. If only `init.start_s`
//!   is given, the same rule is applied from that start (the onset rule if the onset lies after
//!   it).
//! * `fit` must lie inside the playback window and hold at least [`MIN_SAMPLES`] samples.
//!   Default: the playback window.
//!
//! A window with `end_s <= start_s` is an error naming `<window>.end_s`.
//!
//! # Onset
//!
//! Every event knows when its disturbance starts ([`Event::onset`]): the time of the first
//! sample that departs from the pre-event course, found in the playback record by
//! [`detect_onset`] (the rule and its justification are in the `onset` module's
//! documentation), or `None` for ambient data. The same detector runs on every path (event TOML,
//! [`Event::from_record`], the PMU import), so they all get the same value. The TOML key
//! `onset_s` overrides it: a time in seconds inside the playback window (an error naming the
//! file and the key otherwise), or `onset_s = "none"` for data without a disturbance. The
//! default init window ends before it; the diagnosis takes its evidence windows, its noise and
//! its fit/held-out split from it.
//!
//! # Played-back voltage
//!
//! A phasor record's |V| and angle are played back through a zero-phase low-pass between their
//! discontinuities, which stay as recorded ([`smoothing`]: why a playback should not feed its
//! input's noise to the model, and how the edges are found), at
//! [`smoothing::DEFAULT_CUTOFF_HZ`] (4 Hz) by default, on every path (event file,
//! [`Event::from_record`], the PMU import). `input_lowpass_hz` names another cut-off (Hz, above
//! 0 and below the Nyquist frequency; the record's time stamps uniform within 1 %), or
//! `input_lowpass_hz = "none"` plays the record back as recorded. A record whose stamps are not
//! uniform, or whose Nyquist frequency is at or below the default, and a record without an
//! angle are played back as recorded unless a cut-off is named. In memory:
//! [`Event::set_input_lowpass`].
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
//! `angle_deg`; or `v_pu` alone when the event declares its channels without the angle. Any other column, a duplicated column or a missing required column is an error.
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
//!
//! # Layout
//!
//! * this file: the [`Event`], [`Record`] and [`OperatingPoint`] types, the format constants and
//!   building an event from memory ([`Event::from_record`]);
//! * `error.rs`: [`EventError`] and [`Location`];
//! * `spec.rs`: the event TOML file and its parsing ([`Event::from_toml_file`]);
//! * `csv.rs`: reading ([`read_csv`]) and writing ([`Event::write_csv`]) the measurement CSV, and
//!   the validation shared by CSV and in-memory records;
//! * `window.rs`: [`Window`] and the resolution of the playback, init and fit windows;
//! * `onset.rs`: [`detect_onset`], the disturbance's onset found in the data;
//! * `declare.rs`, `declare_check.rs`: the declaration (channels, time base, steps) and its
//!   checks against the record.

use std::ops::Range;
use std::path::PathBuf;

mod csv;
mod declare;
mod error;
mod field;
mod onset;
pub mod smoothing;
mod spec;
mod window;

pub(crate) use self::csv::read_csv_channels;
pub use self::csv::{format_g17, read_csv};
pub use declare::{
    step_level, Channel, Declaration, SetpointStep, StepReference, TimeBase, FIELD_LIMIT_PU,
    NON_UNIFORM_SPREAD,
};
pub use error::{EventError, Location};
pub use field::{field_recorded_by_all, FIELD_CHANNELS};
pub use onset::{
    detect_onset, Crossing, OnsetChannel, OnsetDetection, ONSET_FALSE_ALARM, ONSET_LOCATE_SD,
    ONSET_MAX_WINDOW_S, ONSET_MIN_WINDOW, ONSET_REFERENCE_S,
};
pub(crate) use onset::{normal_upper_quantile, quantum, robust_sd};
pub use window::{Window, TIME_TOL_S};

use self::csv::{check_record_shape, validate_record, ColumnLabels};
use spec::{check_bases, OnsetSpec, WindowSpec};
use window::{assemble, Declared};

mod declare_check;

/// Minimum number of samples in the record, the playback window, the init window and the fit
/// window.
pub const MIN_SAMPLES: usize = 3;

/// Default length of the init window, s.
pub const DEFAULT_INIT_S: f64 = 0.5;

/// The default init window is extended to hold at least this many samples.
pub const DEFAULT_INIT_MIN_SAMPLES: usize = 10;

/// The default init window of an event with an onset ends this many samples before it: a PMU's
/// phasor filter spreads an abrupt change over a sample or two, and the onset is the first
/// sample found to depart, not necessarily the first touched.
pub const ONSET_GUARD_SAMPLES: usize = 3;

/// Accepted range of the median |V|, pu.
pub const V_MEDIAN_RANGE_PU: (f64, f64) = (0.5, 1.5);

/// |P| and |Q| must stay below this value, pu on the system base.
pub const PQ_LIMIT_PU: f64 = 20.0;

/// `freq_hz` values must lie within this fraction of `nominal_hz` around it.
pub const FREQ_TOLERANCE: f64 = 0.10;

/// Columns accepted in an event CSV, in canonical order.
pub const ACCEPTED_COLUMNS: [&str; 12] = [
    "time_s",
    "v_re_pu",
    "v_im_pu",
    "v_pu",
    "angle_deg",
    "v_mag_pu",
    "v_ang_rad",
    "p_pu",
    "q_pu",
    "freq_hz",
    "efd_pu",
    "ifd_pu",
];

const TAU: f64 = std::f64::consts::TAU;

// ---------------------------------------------------------------------------------------------
// Data types
// ---------------------------------------------------------------------------------------------

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
    /// the first sample lies in `[-π, π]`. Zeros when the record has no angle (an event whose
    /// declared channels leave it out: [`Event::has_angle`]).
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

/// How far a time stamp may lie from the reporting grid and still be taken as on it [s]: a time
/// stamp written to the microsecond (or with more digits) is within 0.5 µs of the instant it
/// stands for.
pub const SNAP_TOL_S: f64 = 1e-6;

/// A PMU reports at whole multiples of its reporting period (IEEE C37.118: a whole-number rate,
/// the fraction of second counted in its time base). When the mean interval of `time` is within
/// 1e-4 of a whole-number rate R and every time stamp lies within [`SNAP_TOL_S`] of a multiple of
/// 1/R (measured from 0), the time stamps are set to those multiples: the rounding of written
/// time stamps (`0.01666666667`, `1.016667`) is not the PMU's, and every path to the same
/// record (a CSV, a COMTRADE file, an array) then plays back the same instants. Returns R when
/// it changed anything. Irregular time bases (a trending recorder's) are left as they are.
pub fn snap_to_rate(time: &mut [f64]) -> Option<f64> {
    let n = time.len();
    if n < 3 {
        return None;
    }
    let dt = (time[n - 1] - time[0]) / (n - 1) as f64;
    if !(dt > 0.0) {
        return None;
    }
    let rate = (1.0 / dt).round();
    if !(rate >= 1.0) || ((1.0 / dt) - rate).abs() > 1e-4 * rate {
        return None;
    }
    let grid = |t: f64| (t * rate).round() / rate;
    if !time.iter().all(|t| (t - grid(*t)).abs() <= SNAP_TOL_S) {
        return None;
    }
    // Consecutive samples on distinct grid points (no duplicate after snapping).
    if time.windows(2).any(|w| grid(w[1]) <= grid(w[0])) {
        return None;
    }
    if time.iter().all(|t| *t == grid(*t)) {
        return None;
    }
    for t in time.iter_mut() {
        *t = grid(*t);
    }
    Some(rate)
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

/// Where an event's onset comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum OnsetSource {
    /// Found in the playback record by [`detect_onset`].
    Detected,
    /// Written by the user (`onset_s` in the event TOML).
    Given,
}

/// When an event's disturbance starts, and why that time.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Onset {
    /// Time of the first disturbed sample, s (on the record's time axis); `None`: no
    /// disturbance (ambient data).
    pub time_s: Option<f64>,
    pub source: OnsetSource,
    /// What the detector found on the playback record (also when the user gave the onset).
    pub detection: OnsetDetection,
}

impl Onset {
    /// One line for a report: the onset, where it comes from and the evidence.
    pub fn describe(&self) -> String {
        match self.source {
            OnsetSource::Detected => format!("detected: {}", self.detection.describe()),
            OnsetSource::Given => {
                let given = match self.time_s {
                    Some(t) => format!("onset {t} s given in the event file (onset_s)"),
                    None => "no onset: onset_s = \"none\" in the event file".to_string(),
                };
                format!("{given}; the detector's: {}", self.detection.describe())
            }
        }
    }
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
    /// When the disturbance starts (see "Onset" in the module documentation).
    pub onset: Onset,
    /// Samples inside the playback window.
    pub record: Record,
    /// The recorded channels (declared with `channels`, else those of the CSV: a phasor record).
    pub channels: Vec<Channel>,
    /// How the recorder's stamps are spaced (`time_base`; kept as recorded either way).
    pub time_base: TimeBase,
    /// Known set-point steps of a staged test (`[[step]]`), in increasing time.
    pub steps: Vec<SetpointStep>,
    /// Cut-off of the zero-phase low-pass the playback applies to the recorded |V| and angle
    /// between their discontinuities ([`smoothing`]), Hz; `None` plays the record back as
    /// recorded. [`smoothing::default_cutoff`] unless the event file names it; set with
    /// [`Event::set_input_lowpass`], which checks it.
    pub input_lowpass_hz: Option<f64>,
    /// What the import of the recording found wrong with it that the record itself no longer
    /// shows (a data file shorter than its header declares): one line each, kept in the event
    /// file (`import_notes`) and repeated as a warning by every command that reads the event
    /// ([`crate::plausibility::check_event`]).
    pub import_notes: Vec<String>,
}

impl Event {
    /// Builds an event from in-memory arrays (used by the Python API and for synthetic events)
    /// and validates it the same way as a file: equal vector lengths, finite values,
    /// non-negative |V|, strictly increasing time, at least [`MIN_SAMPLES`] samples, unit sanity
    /// checks, bases, windows. The whole record is the playback window. The onset is detected
    /// ([`detect_onset`]) as for a file; `init` and `fit` default as described in the module
    /// documentation. The angle is unwrapped (a no-op for an already
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
        Self::from_record_declared(
            name,
            record,
            system_mva,
            nominal_hz,
            init,
            fit,
            &Declaration::default(),
        )
    }

    /// [`Event::from_record`] with a [`Declaration`]: the recorded channels (a record without
    /// `angle` holds zeros in `v_ang_rad`; the optional channels present must be the declared
    /// ones), the time base and the set-point steps, checked as an event file's are.
    pub fn from_record_declared(
        name: &str,
        record: Record,
        system_mva: f64,
        nominal_hz: f64,
        init: Option<Window>,
        fit: Option<Window>,
        declaration: &Declaration,
    ) -> Result<Event, EventError> {
        let src = PathBuf::from(format!("<in-memory event '{name}'>"));
        check_bases(&src, system_mva, nominal_hz)?;
        let mut record = record;
        check_record_shape(&src, &record)?;
        let has_angle = declaration.has_angle();
        if has_angle {
            record.v_ang_rad = unwrap_angles(&record.v_ang_rad);
        } else {
            record.v_ang_rad = vec![0.0; record.len()];
        }
        let labels = ColumnLabels::in_memory();
        validate_record(&src, &record, nominal_hz, &labels, &|i| Location::Sample(i))?;
        let found = self::csv::record_channels(&record, has_angle);
        let channels = declare_check::resolve_channels(&src, declaration, &found, "the record")?;
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
            OnsetSpec::Detect,
            Declared {
                channels,
                time_base: declaration.time_base,
                steps: declaration.steps.clone(),
            },
        )
    }

    /// Plays the recorded |V| and angle back low-passed at `cutoff_hz` between their
    /// discontinuities ([`smoothing`]), or as recorded (`None`).
    ///
    /// # Errors
    /// The record's time stamps are not uniform within 1 %, or the cut-off is not a positive
    /// frequency below the Nyquist frequency.
    pub fn set_input_lowpass(
        &mut self,
        cutoff_hz: Option<f64>,
    ) -> Result<(), crate::filter::FilterError> {
        if let Some(fc) = cutoff_hz {
            smoothing::check(&self.record.time_s, fc)?;
        }
        self.input_lowpass_hz = cutoff_hz;
        Ok(())
    }

    /// The |V| and angle the playback plays: the record's, low-passed between its
    /// discontinuities where [`Event::input_lowpass_hz`] asks for it.
    pub fn playback_voltage(&self) -> (Vec<f64>, Vec<f64>) {
        let r = &self.record;
        self.input_lowpass_hz
            .and_then(|fc| smoothing::smoothed_input(&r.time_s, &r.v_mag_pu, &r.v_ang_rad, fc).ok())
            .unwrap_or_else(|| (r.v_mag_pu.clone(), r.v_ang_rad.clone()))
    }

    /// The input the playback interpolates: [`Event::playback_voltage`] at the record's
    /// stamps, linear between them, with the natural cubic spline through its smoothed
    /// stretches for a playback that steps over their samples ([`crate::unit::PlaybackInput`]).
    pub fn playback_input(&self) -> crate::unit::PlaybackInput {
        let r = &self.record;
        let t = r.time_s.clone();
        match self.input_lowpass_hz.and_then(|fc| {
            smoothing::smoothed_input_marked(&r.time_s, &r.v_mag_pu, &r.v_ang_rad, fc).ok()
        }) {
            Some((m, a, smoothed)) => crate::unit::PlaybackInput::with_splines(t, m, a, &smoothed),
            None => crate::unit::PlaybackInput::linear(t, r.v_mag_pu.clone(), r.v_ang_rad.clone()),
        }
    }

    /// Whether the record holds the voltage angle (a phasor record).
    pub fn has_angle(&self) -> bool {
        self.channels.contains(&Channel::Angle)
    }

    /// Whether the record holds channel `c`.
    pub fn has(&self, c: Channel) -> bool {
        self.channels.contains(&c)
    }

    /// What the event declares beyond its samples, one line each, for reports: the channels
    /// (when not a phasor record), the played-back voltage of a phasor record (when not
    /// smoothed at the default cut-off), the time base (when not uniform) and the set-point
    /// steps. Empty for a plain phasor record.
    pub fn declaration_notes(&self) -> Vec<String> {
        let mut out = vec![];
        if self.has_angle() {
            match self.input_lowpass_hz {
                Some(fc) if fc == smoothing::DEFAULT_CUTOFF_HZ => {}
                Some(fc) => out.push(format!(
                    "played-back |V| and angle: low-passed at {fc} Hz between their edges (the \
                     default is {} Hz)",
                    smoothing::DEFAULT_CUTOFF_HZ
                )),
                None => out.push(
                    "played-back |V| and angle: as recorded, not smoothed (input_lowpass_hz = \
                     \"none\", or time stamps the low-pass cannot run on)"
                        .into(),
                ),
            }
        }
        if !self.has_angle() {
            out.push(format!(
                "recorded channels: {} (no voltage angle: no phasor playback; the playback modes \
                 exciter_alone, machine_from_efd and closed_loop need none)",
                self.channels
                    .iter()
                    .map(|c| c.name())
                    .collect::<Vec<_>>()
                    .join(", ")
            ));
        }
        if self.time_base == TimeBase::NonUniform {
            let dt: Vec<f64> = self.record.time_s.windows(2).map(|w| w[1] - w[0]).collect();
            let lo = dt.iter().copied().fold(f64::INFINITY, f64::min);
            let hi = dt.iter().copied().fold(0.0, f64::max);
            out.push(format!(
                "time base: non-uniform, intervals {:.2}-{:.2} ms; kept as recorded (played back \
                 and compared at the recorded stamps, inputs linear between them; no resampling)",
                lo * 1e3,
                hi * 1e3
            ));
        }
        for (k, s) in self.steps.iter().enumerate() {
            out.push(format!(
                "step[{k}]: {} {:+} pu at {} s",
                s.reference.name(),
                s.size_pu,
                s.time_s
            ));
        }
        out
    }

    /// The recorded samples of channel `c` (`None` when it was not recorded; the angle only in
    /// a phasor record).
    pub fn series(&self, c: Channel) -> Option<&[f64]> {
        let rec = &self.record;
        Some(match c {
            Channel::V => &rec.v_mag_pu,
            Channel::Angle => self.has_angle().then_some(rec.v_ang_rad.as_slice())?,
            Channel::P => &rec.p_pu,
            Channel::Q => &rec.q_pu,
            Channel::Freq => rec.freq_hz.as_deref()?,
            Channel::Efd => rec.efd_pu.as_deref()?,
            Channel::Ifd => rec.ifd_pu.as_deref()?,
        })
    }

    /// [`Event::series`], to change in place (a surrogate record, say).
    pub fn series_mut(&mut self, c: Channel) -> Option<&mut [f64]> {
        let has_angle = self.has_angle();
        let rec = &mut self.record;
        Some(match c {
            Channel::V => &mut rec.v_mag_pu,
            Channel::Angle => has_angle.then_some(rec.v_ang_rad.as_mut_slice())?,
            Channel::P => &mut rec.p_pu,
            Channel::Q => &mut rec.q_pu,
            Channel::Freq => rec.freq_hz.as_deref_mut()?,
            Channel::Efd => rec.efd_pu.as_deref_mut()?,
            Channel::Ifd => rec.ifd_pu.as_deref_mut()?,
        })
    }

    /// Mean of a recorded channel over the init window (`None` when not recorded): E_fd0 and
    /// X_adI_fd0 of the record.
    pub fn init_mean(&self, c: Channel) -> Option<f64> {
        let s = &self.series(c)?[self.init_range()];
        (!s.is_empty()).then(|| s.iter().sum::<f64>() / s.len() as f64)
    }

    /// The time of the disturbance's onset, s (`None`: ambient data). Shorthand for
    /// `self.onset.time_s`.
    pub fn onset_s(&self) -> Option<f64> {
        self.onset.time_s
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
}
