//! [`Window`], a closed time interval on the record's time axis, and the resolution of the
//! playback, init and fit windows of an event: defaults, checks against the record, sample
//! counts, and assembling the validated [`Event`].

use std::fmt;
use std::path::{Path, PathBuf};

use super::declare_check::check_steps;
use super::onset::detect_onset;
use super::spec::{OnsetSpec, WindowSpec};
use super::{
    Channel, Event, EventError, Onset, OnsetSource, Record, SetpointStep, TimeBase,
    DEFAULT_INIT_MIN_SAMPLES, DEFAULT_INIT_S, MIN_SAMPLES, ONSET_GUARD_SAMPLES,
};

/// What an event declares, resolved against its record (channels checked).
pub(super) struct Declared {
    pub(super) channels: Vec<Channel>,
    pub(super) time_base: TimeBase,
    pub(super) steps: Vec<SetpointStep>,
}

/// A closed time interval `[start_s, end_s]`, seconds on the record's time axis.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Window {
    pub start_s: f64,
    pub end_s: f64,
}

/// Tolerance, in seconds, when deciding whether a sample time lies inside a window or a window
/// bound lies inside the record: the one rule of window membership ([`Window::contains`],
/// [`super::Record::window_range`], the fit's window in `itaipu-calib`).
pub const TIME_TOL_S: f64 = 1e-6;

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

/// Resolves window specs against the record, validates them and builds the event.
#[allow(clippy::too_many_arguments)]
pub(super) fn assemble(
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
    onset: OnsetSpec,
    declared: Declared,
) -> Result<Event, EventError> {
    // Time stamps on a PMU's reporting grid, as written, are the grid's instants.
    let mut full = full;
    super::snap_to_rate(&mut full.time_s);
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

    // Onset: the user's, checked against the playback window, or the detector's.
    let detection = detect_onset(&record);
    let onset = match onset {
        OnsetSpec::Detect => Onset {
            time_s: detection.onset_s,
            source: OnsetSource::Detected,
            detection,
        },
        OnsetSpec::Given(t) => {
            if let Some(t) = t {
                if !(t.is_finite()
                    && t >= pb_win.start_s - TIME_TOL_S
                    && t <= pb_win.end_s + TIME_TOL_S)
                {
                    return Err(EventError::InvalidValue {
                        path: src.to_path_buf(),
                        field: "onset_s".into(),
                        value: t,
                        message: format!(
                            "the onset must be a time inside {pb_desc} (seconds on the record's time axis)"
                        ),
                    });
                }
            }
            Onset {
                time_s: t,
                source: OnsetSource::Given,
                detection,
            }
        }
    };

    // Set-point steps: inside the playback record, after its first sample.
    check_steps(
        src,
        &declared.steps,
        record.start_s(),
        record.end_s(),
        &format!("{pb_desc} ({})", record_desc),
    )?;

    // Init.
    let init_start = init.start_s.unwrap_or(pb_win.start_s);
    let mut init_default_end = match onset.time_s {
        Some(t) if t > init_start => onset_init_end(&record, init_start, t),
        _ => default_init_end(&record, init_start, pb_win.end_s),
    };
    if let Some(first) = declared.steps.first() {
        // The operating point is the pre-step one: the default window ends before the step.
        if first.time_s > init_start {
            init_default_end =
                init_default_end.min(onset_init_end(&record, init_start, first.time_s));
        }
    }
    let iw = resolve(init, pb_win.start_s, init_default_end);
    check_window(src, "init", &iw, &pb_win, &pb_desc)?;
    if let Some(first) = declared.steps.first() {
        if iw.window.end_s >= first.time_s - TIME_TOL_S {
            return Err(EventError::BadWindow {
                path: src.to_path_buf(),
                field: "init.end_s".into(),
                message: format!(
                    "{}{} s is not before step[0].time_s = {} s: the operating point is the \
                     pre-step one; end the init window before the first step",
                    iw.window.end_s,
                    if iw.end_default { " (default)" } else { "" },
                    first.time_s
                ),
            });
        }
    }
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

    let has_angle = declared.channels.contains(&Channel::Angle);
    let input_lowpass_hz = super::smoothing::default_cutoff(&record.time_s, has_angle);
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
        onset,
        record,
        channels: declared.channels,
        time_base: declared.time_base,
        steps: declared.steps,
        input_lowpass_hz,
        import_notes: vec![],
    })
}

/// The default end of the init window starting at `start` for an event whose onset is at
/// `onset` (> `start`): the sample [`ONSET_GUARD_SAMPLES`] before the onset's, but never fewer
/// than [`MIN_SAMPLES`] samples from `start`.
fn onset_init_end(rec: &Record, start: f64, onset: f64) -> f64 {
    let first = rec.time_s.partition_point(|&t| t < start - TIME_TOL_S);
    let at_onset = rec.time_s.partition_point(|&t| t < onset - TIME_TOL_S);
    let end = at_onset
        .saturating_sub(ONSET_GUARD_SAMPLES)
        .max(first + MIN_SAMPLES - 1)
        .min(rec.len().saturating_sub(1));
    rec.time_s.get(end).copied().unwrap_or(onset)
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
