//! [`EventError`], everything that can go wrong while reading, validating or writing an event,
//! with its stable [`EventError::kind`] identifier, and [`Location`], where in the data it went
//! wrong.

use std::fmt;
use std::path::{Path, PathBuf};

use super::ACCEPTED_COLUMNS;

/// Where in a data source a problem was found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Location {
    /// 1-based line of a CSV file (the header is line 1).
    Line(usize),
    /// 0-based sample index of an in-memory [`Record`](super::Record).
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
/// with [`Event::from_record`](super::Event::from_record), the label `<in-memory event 'NAME'>`).
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

    /// An in-memory [`Record`](super::Record) is malformed (vectors of different lengths).
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

    /// A window (or the whole record) holds fewer than [`MIN_SAMPLES`](super::MIN_SAMPLES) samples.
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

    /// What the event declares (`channels`, `time_base`, `[[step]]`) is wrong or does not match
    /// its record.
    #[error("{}: {field}: {message}", path.display())]
    Declaration {
        path: PathBuf,
        /// e.g. `channels`, `step[1].time_s`
        field: String,
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
            EventError::Declaration { .. } => "declaration",
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
            | EventError::BadWindow { path, .. }
            | EventError::Declaration { path, .. } => path,
        }
    }
}
