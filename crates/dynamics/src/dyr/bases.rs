//! The values a `.dyr` does not hold ([`DyrBases`]: MVA base, nominal frequency, ZSORCE), from
//! the command line ([`PartialBases`]) and the `<stem>.bases.toml` side file.

use std::path::{Path, PathBuf};

use super::DyrError;

/// Values from the power-flow machine record that a `.dyr` does not hold.
#[derive(Debug, Clone, PartialEq)]
pub struct DyrBases {
    /// MBASE, MVA (the machine base of every per-unit CON).
    pub mbase: f64,
    /// Nominal frequency, Hz.
    pub nominal_hz: f64,
    /// ZSORCE R: armature resistance R_a, pu on MBASE (`None`: 0, with a warning).
    pub zr: Option<f64>,
    /// ZSORCE X, pu on MBASE: X'd of GENCLS; for the other machines checked against X''d.
    pub zx: Option<f64>,
    /// Unit name (default: `<file stem> bus N id ID`).
    pub name: Option<String>,
}

/// Keys of the side file.
const BASES_KEYS: [&str; 5] = ["mbase", "nominal_hz", "zr", "zx", "name"];

impl DyrBases {
    /// Reads a side file (TOML: `mbase`, `nominal_hz`, optional `zr`, `zx`, `name`).
    pub fn from_file(path: &Path) -> Result<DyrBases, DyrError> {
        let text = std::fs::read_to_string(path).map_err(|source| DyrError::Io {
            path: path.into(),
            source,
        })?;
        Self::parse(&text, path, None)
    }

    /// Parses side-file text; values in `over` (e.g. from the command line) replace the file's
    /// and may stand in for missing keys.
    pub fn parse(
        text: &str,
        path: &Path,
        over: Option<&PartialBases>,
    ) -> Result<DyrBases, DyrError> {
        let field = |f: &str, msg: String| DyrError::Bases {
            path: path.into(),
            field: f.into(),
            msg,
        };
        let table: toml::Table = text.parse().map_err(|e: toml::de::Error| DyrError::Bases {
            path: path.into(),
            field: "(syntax)".into(),
            msg: e.to_string().trim().replace('\n', " "),
        })?;
        for k in table.keys() {
            if !BASES_KEYS.contains(&k.as_str()) {
                return Err(field(
                    k,
                    format!("unknown key (accepted: {})", BASES_KEYS.join(", ")),
                ));
            }
        }
        let num = |k: &str| -> Result<Option<f64>, DyrError> {
            match table.get(k) {
                None => Ok(None),
                Some(toml::Value::Float(x)) => Ok(Some(*x)),
                Some(toml::Value::Integer(i)) => Ok(Some(*i as f64)),
                Some(_) => Err(field(k, "must be a number".into())),
            }
        };
        let mut p = PartialBases {
            mbase: num("mbase")?,
            nominal_hz: num("nominal_hz")?,
            zr: num("zr")?,
            zx: num("zx")?,
            name: match table.get("name") {
                None => None,
                Some(toml::Value::String(s)) => Some(s.clone()),
                Some(_) => return Err(field("name", "must be a string".into())),
            },
        };
        if let Some(o) = over {
            p.overlay(o);
        }
        p.finish(path)
    }
}

/// Bases as far as they are known (command-line options, or a side file being read).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PartialBases {
    pub mbase: Option<f64>,
    pub nominal_hz: Option<f64>,
    pub zr: Option<f64>,
    pub zx: Option<f64>,
    pub name: Option<String>,
}

impl PartialBases {
    /// Takes every value `o` has.
    pub fn overlay(&mut self, o: &PartialBases) {
        self.mbase = o.mbase.or(self.mbase);
        self.nominal_hz = o.nominal_hz.or(self.nominal_hz);
        self.zr = o.zr.or(self.zr);
        self.zx = o.zx.or(self.zx);
        self.name = o.name.clone().or(self.name.take());
    }

    /// Checks and completes; `src` names where the values came from in messages.
    pub fn finish(self, src: &Path) -> Result<DyrBases, DyrError> {
        let field = |f: &str, msg: String| DyrError::Bases {
            path: src.into(),
            field: f.into(),
            msg,
        };
        let mbase = self.mbase.ok_or_else(|| {
            field(
                "mbase",
                "missing: the machine base MBASE [MVA] from the power-flow machine record".into(),
            )
        })?;
        if !(mbase.is_finite() && mbase > 0.0) {
            return Err(field(
                "mbase",
                format!("must be a finite number > 0 MVA (got {mbase})"),
            ));
        }
        let nominal_hz = self
            .nominal_hz
            .ok_or_else(|| field("nominal_hz", "missing: the nominal frequency [Hz]".into()))?;
        if !(nominal_hz.is_finite() && nominal_hz > 0.0) {
            return Err(field(
                "nominal_hz",
                format!("must be a finite number > 0 Hz (got {nominal_hz})"),
            ));
        }
        for (k, v) in [("zr", self.zr), ("zx", self.zx)] {
            if let Some(x) = v {
                if !(x.is_finite() && x >= 0.0) {
                    return Err(field(
                        k,
                        format!("must be a finite number >= 0 pu (got {x})"),
                    ));
                }
            }
        }
        Ok(DyrBases {
            mbase,
            nominal_hz,
            zr: self.zr,
            zx: self.zx,
            name: self.name,
        })
    }
}

/// `<stem>.bases.toml` beside a `.dyr`: the side file read by default.
pub fn side_file(dyr: &Path) -> PathBuf {
    let stem = dyr
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    dyr.with_file_name(format!("{stem}.bases.toml"))
}

/// The bases of `dyr`: the side file `side` (else [`side_file`] if it exists) with the values
/// of `over` on top; without a side file, `over` alone (a missing value names the `.dyr`).
/// A `.dyr` that cannot be read is that error ([`DyrError::Io`] naming it), not a missing
/// base: the bases are looked for only beside a file that is there.
pub fn resolve_bases(
    dyr: &Path,
    side: Option<&Path>,
    over: &PartialBases,
) -> Result<DyrBases, DyrError> {
    if let Err(source) = std::fs::metadata(dyr) {
        return Err(DyrError::Io {
            path: dyr.to_path_buf(),
            source,
        });
    }
    let default = side_file(dyr);
    let side = side
        .map(Path::to_path_buf)
        .or_else(|| default.is_file().then_some(default));
    match side {
        Some(s) => {
            let text = std::fs::read_to_string(&s).map_err(|source| DyrError::Io {
                path: s.clone(),
                source,
            })?;
            DyrBases::parse(&text, &s, Some(over))
        }
        None => over.clone().finish(dyr),
    }
}
