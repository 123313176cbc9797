//! The event TOML file: its accepted keys, the serde spec it is read into, the key checks that
//! name the offending key and its line, and [`Event::from_toml_file`].

use std::fs;
use std::path::{Path, PathBuf};

use serde::Deserialize;

use super::csv::{read_csv_channels, record_channels};
use super::declare_check::resolve_channels;
use super::window::{assemble, Declared, Window};
use super::{Channel, Declaration, Event, EventError, SetpointStep, StepReference, TimeBase};

const TOP_KEYS: [&str; 14] = [
    "name",
    "description",
    "csv",
    "system_mva",
    "nominal_hz",
    "onset_s",
    "input_lowpass_hz",
    "channels",
    "time_base",
    "playback",
    "init",
    "fit",
    "step",
    "import_notes",
];
const STEP_KEYS: [&str; 3] = ["time_s", "size_pu", "reference"];
const REQUIRED_KEYS: [&str; 4] = ["name", "csv", "system_mva", "nominal_hz"];
const WINDOW_TABLES: [&str; 3] = ["playback", "init", "fit"];
const WINDOW_KEYS: [&str; 2] = ["start_s", "end_s"];

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
    onset_s: Option<NumberOrWord>,
    #[serde(default)]
    input_lowpass_hz: Option<NumberOrWord>,
    #[serde(default)]
    playback: Option<WindowSpec>,
    #[serde(default)]
    init: Option<WindowSpec>,
    #[serde(default)]
    fit: Option<WindowSpec>,
    #[serde(default)]
    channels: Option<Vec<String>>,
    #[serde(default)]
    time_base: Option<String>,
    #[serde(default)]
    step: Vec<StepSpec>,
    #[serde(default)]
    import_notes: Vec<String>,
}

/// A `[[step]]` table as written.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct StepSpec {
    time_s: f64,
    size_pu: f64,
    #[serde(default)]
    reference: Option<String>,
}

/// `onset_s` or `input_lowpass_hz` as written: a number or a word (only `"none"` is accepted).
#[derive(Debug, Deserialize)]
#[serde(untagged)]
enum NumberOrWord {
    Number(f64),
    Word(String),
}

/// How an event gets its onset.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum OnsetSpec {
    /// Found in the playback record.
    Detect,
    /// Given by the user: a time (s), or `None` for no disturbance.
    Given(Option<f64>),
}

/// A window as written by the user; missing bounds take defaults.
#[derive(Debug, Default, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct WindowSpec {
    #[serde(default)]
    pub(super) start_s: Option<f64>,
    #[serde(default)]
    pub(super) end_s: Option<f64>,
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
        if key == "step" {
            if let DeValue::Array(items) = v.get_ref() {
                for (i, item) in items.iter().enumerate() {
                    if let DeValue::Table(sub) = item.get_ref() {
                        for (k2, _) in sub.iter() {
                            let key2: &str = k2.get_ref();
                            if !STEP_KEYS.contains(&key2) {
                                unknown.push((
                                    k2.span().start,
                                    format!("step[{i}].{key2}"),
                                    STEP_KEYS.join(", "),
                                ));
                            }
                        }
                    }
                }
            }
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

pub(super) fn check_bases(src: &Path, system_mva: f64, nominal_hz: f64) -> Result<(), EventError> {
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

pub(super) fn check_nominal_hz(src: &Path, nominal_hz: f64) -> Result<(), EventError> {
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

impl Event {
    /// Reads an event TOML file and the CSV it points to, and validates everything (see the
    /// `event` module documentation for the format and the checks).
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
        let declaration = declaration(path, &spec)?;
        let onset = match spec.onset_s {
            None => OnsetSpec::Detect,
            Some(NumberOrWord::Number(t)) => OnsetSpec::Given(Some(t)),
            Some(NumberOrWord::Word(w)) if w.trim().eq_ignore_ascii_case("none") => {
                OnsetSpec::Given(None)
            }
            Some(NumberOrWord::Word(w)) => {
                return Err(EventError::TomlValue {
                    path: path.to_path_buf(),
                    message: format!(
                        "onset_s = {}: expected the onset's time in seconds (a number) or \"none\" for data without a disturbance",
                        toml::Value::String(w)
                    ),
                })
            }
        };

        let folder = path.parent().unwrap_or_else(|| Path::new(""));
        let csv_path = folder.join(&spec.csv);
        let magnitude_only_ok = !declaration.has_angle();
        let read = read_csv_channels(&csv_path, spec.nominal_hz, magnitude_only_ok);
        let (full, has_angle) = read.map_err(|e| match e {
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
        let found = record_channels(&full, has_angle);
        let data = format!("the CSV file {}", csv_path.display());
        let channels = resolve_channels(path, &declaration, &found, &data)?;

        let mut event = assemble(
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
            onset,
            Declared {
                channels,
                time_base: declaration.time_base,
                steps: declaration.steps,
            },
        )?;
        event.import_notes = spec.import_notes;
        // A number or "none" (as `onset_s`); absent, the default `assemble` chose.
        match spec.input_lowpass_hz {
            None => {}
            Some(NumberOrWord::Word(w)) if w.trim().eq_ignore_ascii_case("none") => {
                event.input_lowpass_hz = None;
            }
            Some(NumberOrWord::Word(w)) => {
                return Err(EventError::TomlValue {
                    path: path.to_path_buf(),
                    message: format!(
                        "input_lowpass_hz = {}: expected a cut-off in Hz (a number) or \"none\" to play |V| and the angle back as recorded",
                        toml::Value::String(w)
                    ),
                })
            }
            Some(NumberOrWord::Number(fc)) => {
                event
                    .set_input_lowpass(Some(fc))
                    .map_err(|e| EventError::InvalidValue {
                        path: path.to_path_buf(),
                        field: "input_lowpass_hz".into(),
                        value: fc,
                        message: e.to_string(),
                    })?;
            }
        }
        Ok(event)
    }
}

/// The declaration of an event file (`channels`, `time_base`, `[[step]]`), names checked.
fn declaration(path: &Path, spec: &EventSpec) -> Result<Declaration, EventError> {
    let err = |field: String, message: String| EventError::Declaration {
        path: path.to_path_buf(),
        field,
        message,
    };
    let channels = match &spec.channels {
        None => None,
        Some(names) => Some(
            names
                .iter()
                .map(|n| {
                    Channel::parse(n.trim()).ok_or_else(|| {
                        err(
                            "channels".into(),
                            format!("unknown channel \"{n}\" (channels: {})", Channel::names()),
                        )
                    })
                })
                .collect::<Result<Vec<_>, _>>()?,
        ),
    };
    let time_base = match spec.time_base.as_deref().map(str::trim) {
        None | Some("uniform") => TimeBase::Uniform,
        Some("non_uniform") => TimeBase::NonUniform,
        Some(other) => {
            return Err(err(
                "time_base".into(),
                format!("\"{other}\" is not one of \"uniform\", \"non_uniform\""),
            ))
        }
    };
    let mut steps = vec![];
    for (k, s) in spec.step.iter().enumerate() {
        let reference = match s.reference.as_deref() {
            None => {
                return Err(err(
                    format!("step[{k}].reference"),
                    format!(
                        "missing: say which reference the step moves ({})",
                        StepReference::NAMES.join(", ")
                    ),
                ))
            }
            Some(r) => StepReference::parse(r.trim()).ok_or_else(|| {
                err(
                    format!("step[{k}].reference"),
                    format!(
                        "\"{r}\" is not a reference a step can move (references: {})",
                        StepReference::NAMES.join(", ")
                    ),
                )
            })?,
        };
        steps.push(SetpointStep {
            time_s: s.time_s,
            size_pu: s.size_pu,
            reference,
        });
    }
    Ok(Declaration {
        channels,
        time_base,
        steps,
    })
}
