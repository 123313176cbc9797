//! Reading a cause file ([`super::user_cause`]): each field checked, every block built once,
//! every error naming the file and the field.

use std::path::{Path, PathBuf};

use itaipu_dynamics::registry;
use itaipu_dynamics::unit_file::{build_block, build_diagram_block, BuiltBlock};

use crate::bounds::FreeBound;

use super::catalog;
use super::report::NO_CAUSE_VERDICTS;

/// A bad cause file: the file, the field and what is wrong.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{}: {field}: {msg}", path.display())]
pub struct UserCauseError {
    pub path: PathBuf,
    pub field: String,
    pub msg: String,
}

/// A `[[free]]` entry of a cause file: its bound (`min`, `max`, `start`, `scan`) or, with a
/// `factor`, a band around the unit's value within the declared range, which gives the bound's
/// `min` and `max` per unit (they are unset, NaN, until then).
#[derive(Debug, Clone)]
pub(super) struct UserFree {
    pub(super) bound: FreeBound,
    pub(super) factor: Option<f64>,
    /// The entry's field in the file (messages).
    pub(super) field: String,
}

pub(super) fn valid_id(s: &str) -> bool {
    !s.is_empty()
        && s.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
        && !s.starts_with(|c: char| c.is_ascii_digit())
}

fn num(v: &toml::Value) -> Option<f64> {
    match v {
        toml::Value::Float(f) => Some(*f),
        toml::Value::Integer(i) => Some(*i as f64),
        _ => None,
    }
}

/// Builds one block of a cause file (a diagram or a library model).
pub(super) fn build(
    ctx: &str,
    bt: &toml::Table,
    base: &Path,
    path: &Path,
) -> Result<BuiltBlock, UserCauseError> {
    let model = bt
        .get("model")
        .and_then(|v| v.as_str())
        .ok_or_else(|| UserCauseError {
            path: path.into(),
            field: format!("{ctx}.model"),
            msg: format!("missing (one of: {}, diagram)", registry::names()),
        })?;
    if model.eq_ignore_ascii_case(itaipu_dynamics::diagram::MODEL) {
        return build_diagram_block(ctx, bt, base, path).map_err(|e| UserCauseError {
            path: path.into(),
            field: ctx.to_string(),
            msg: e.to_string(),
        });
    }
    let info = registry::find(model).ok_or_else(|| UserCauseError {
        path: path.into(),
        field: format!("{ctx}.model"),
        msg: format!(
            "unknown model '{model}' (known: {}, diagram)",
            registry::names()
        ),
    })?;
    build_block(info, ctx, bt).map_err(|(field, msg)| UserCauseError {
        path: path.into(),
        field,
        msg,
    })
}

/// A cause file's table being read (`path` names it in messages and resolves diagram files).
pub(super) struct CauseFile<'f> {
    pub(super) t: &'f toml::Table,
    pub(super) path: &'f Path,
}

/// The blocks a cause file adds, `(instance name, section, field prefix)`, and each built.
type Blocks = (
    Vec<(String, toml::Table, String)>,
    Vec<(String, BuiltBlock)>,
);

impl CauseFile<'_> {
    fn err(&self, field: &str, msg: impl Into<String>) -> UserCauseError {
        UserCauseError {
            path: self.path.into(),
            field: field.to_string(),
            msg: msg.into(),
        }
    }

    /// Every key is one a cause file has.
    pub(super) fn check_keys(&self) -> Result<(), UserCauseError> {
        let known = [
            "id",
            "title",
            "signature",
            "extension",
            "search_factor",
            "from_datasheet",
            "band_top_hz",
            "block",
            "rewire",
            "free",
            "interacting",
            "tie",
        ];
        match self.t.keys().find(|k| !known.contains(&k.as_str())) {
            Some(k) => Err(self.err(
                k,
                format!("unknown key (expected one of: {})", known.join(", ")),
            )),
            None => Ok(()),
        }
    }

    /// The text of `key` (trimmed; empty when absent and not `required`).
    pub(super) fn text(&self, key: &str, required: bool) -> Result<String, UserCauseError> {
        match self.t.get(key) {
            Some(toml::Value::String(s)) => Ok(s.trim().to_string()),
            Some(_) => Err(self.err(key, "must be a string")),
            None if required => Err(self.err(key, "missing")),
            None => Ok(String::new()),
        }
    }

    /// The cause's id: an identifier that is no catalog cause's and no verdict's.
    pub(super) fn id(&self) -> Result<String, UserCauseError> {
        let id = self.text("id", true)?;
        if !valid_id(&id) {
            return Err(self.err(
                "id",
                format!("'{id}' is not an identifier (letters, digits and _)"),
            ));
        }
        if catalog::find(&id).is_some() || NO_CAUSE_VERDICTS.contains(&id.as_str()) {
            return Err(self.err(
                "id",
                format!(
                    "'{id}' is taken (the built-in causes: {}; and {})",
                    catalog::ids(),
                    NO_CAUSE_VERDICTS.join(", ")
                ),
            ));
        }
        Ok(id)
    }

    pub(super) fn search_factor(&self) -> Result<usize, UserCauseError> {
        match self.t.get("search_factor") {
            None => Ok(1),
            Some(toml::Value::Integer(n)) if (1..=20).contains(n) => Ok(*n as usize),
            Some(_) => Err(self.err("search_factor", "must be an integer from 1 to 20")),
        }
    }

    pub(super) fn reads_from_datasheet(&self) -> Result<bool, UserCauseError> {
        match self.t.get("from_datasheet") {
            None => Ok(false),
            Some(toml::Value::Boolean(b)) => Ok(*b),
            Some(_) => Err(self.err("from_datasheet", "must be true or false")),
        }
    }

    /// A mode the re-fits must reproduce: positive and finite (whether it lies above an
    /// event's cut-off is decided per event).
    pub(super) fn band_top_hz(&self) -> Result<Option<f64>, UserCauseError> {
        let Some(v) = self.t.get("band_top_hz") else {
            return Ok(None);
        };
        match v.as_float().or_else(|| v.as_integer().map(|n| n as f64)) {
            Some(f) if f.is_finite() && f > 0.0 => Ok(Some(f)),
            _ => Err(self.err("band_top_hz", "must be a positive number of hertz")),
        }
    }

    /// The `[[block]]` tables, each named and built.
    pub(super) fn blocks(&self) -> Result<Blocks, UserCauseError> {
        let base = self.path.parent().unwrap_or(Path::new("."));
        let list = match self.t.get("block") {
            Some(toml::Value::Array(a)) if !a.is_empty() => a,
            Some(_) => return Err(self.err("block", "must be one or more [[block]] tables")),
            None => {
                return Err(self.err(
                    "block",
                    "missing: a cause adds one or more [[block]] (its model extension)",
                ))
            }
        };
        let mut blocks: Vec<(String, toml::Table, String)> = vec![];
        let mut built: Vec<(String, BuiltBlock)> = vec![];
        for (k, b) in list.iter().enumerate() {
            let f = format!("block[{k}]");
            let bt = b
                .as_table()
                .ok_or_else(|| self.err(&f, "must be a table"))?;
            let name = match bt.get("name") {
                Some(toml::Value::String(s)) if valid_id(s) => s.clone(),
                Some(_) => {
                    return Err(self.err(
                        &format!("{f}.name"),
                        "must be an identifier (letters, digits and _)",
                    ))
                }
                None => return Err(self.err(&format!("{f}.name"), "missing")),
            };
            let ctx = format!("block '{name}'");
            if blocks.iter().any(|(n, _, _)| *n == name) {
                return Err(self.err(&format!("{ctx}.name"), "two blocks have this name"));
            }
            let bb = build(&ctx, bt, base, self.path)?;
            built.push((name.clone(), bb));
            blocks.push((name, bt.clone(), ctx));
        }
        Ok((blocks, built))
    }

    /// The `[rewire]` table: `instance = { port = "signal" }`.
    pub(super) fn rewire(&self) -> Result<Vec<Rewiring>, UserCauseError> {
        let rw = match self.t.get("rewire") {
            None => return Ok(vec![]),
            Some(toml::Value::Table(rw)) => rw,
            Some(_) => {
                return Err(self.err(
                    "rewire",
                    "must be a table: instance = { port = \"signal\" }",
                ))
            }
        };
        let mut rewire = vec![];
        for (inst, ports) in rw {
            let f = format!("rewire.{inst}");
            let pt = ports
                .as_table()
                .ok_or_else(|| self.err(&f, "must be a table { port = \"signal\" }"))?;
            let mut v = vec![];
            for (port, sig) in pt {
                let s = sig
                    .as_str()
                    .ok_or_else(|| self.err(&format!("{f}.{port}"), "must be a signal name"))?;
                v.push((port.clone(), s.to_string()));
            }
            rewire.push((inst.clone(), v));
        }
        Ok(rewire)
    }

    /// A parameter of an added block must exist in that block (checked now); one of the
    /// unit's is checked against each unit.
    pub(super) fn check_params<'e>(
        &self,
        entries: impl Iterator<Item = &'e UserFree>,
        built: &[(String, BuiltBlock)],
    ) -> Result<(), UserCauseError> {
        for s in entries {
            let param = &s.bound.param;
            let (inst, p) = param.split_once('.').unwrap_or((param, ""));
            if let Some((_, (b, _))) = built.iter().find(|(n, _)| n == inst) {
                if b.params().index_of(p).is_none() {
                    let names: Vec<&str> = b.params().specs().iter().map(|x| x.name).collect();
                    return Err(self.err(
                        &s.field,
                        format!(
                            "block '{inst}' has no parameter '{p}' (parameters: {})",
                            names.join(", ")
                        ),
                    ));
                }
            }
        }
        Ok(())
    }

    /// The `[tie]` table: `follower = "leader"`, as `(leader, follower)`.
    pub(super) fn ties(&self) -> Result<Vec<(String, String)>, UserCauseError> {
        let tt = match self.t.get("tie") {
            None => return Ok(vec![]),
            Some(toml::Value::Table(tt)) => tt,
            Some(_) => return Err(self.err("tie", "must be a table: follower = \"leader\"")),
        };
        let mut ties = vec![];
        for (follower, leader) in tt {
            let l = leader.as_str().ok_or_else(|| {
                self.err(
                    &format!("tie.{follower}"),
                    "must be the parameter it follows",
                )
            })?;
            ties.push((l.to_string(), follower.clone()));
        }
        Ok(ties)
    }

    /// The `[[free]]` (or `[[interacting]]`) entries under `key` (`required`: at least one).
    pub(super) fn free_list(
        &self,
        key: &str,
        required: bool,
    ) -> Result<Vec<UserFree>, UserCauseError> {
        let list = match self.t.get(key) {
            Some(toml::Value::Array(a)) if !a.is_empty() || !required => a.clone(),
            None if !required => vec![],
            None => return Err(self.err(
                key,
                "missing: a cause frees one or more [[free]] { param, min, max } (its own parameters)",
            )),
            Some(_) => return Err(self.err(key, "must be one or more tables")),
        };
        let mut out: Vec<UserFree> = vec![];
        for (k, v) in list.iter().enumerate() {
            let f = format!("{key}[{k}]");
            let e = v
                .as_table()
                .ok_or_else(|| self.err(&f, "must be a table"))?;
            let entry = self.free_entry(&f, e, &out)?;
            out.push(entry);
        }
        Ok(out)
    }

    /// One `[[free]]` entry `e` at field `f` (`before`: the entries read before it): its
    /// parameter, its bounds (`min` and `max`, or a `factor` around the unit's value), its start
    /// and its scan.
    fn free_entry(
        &self,
        f: &str,
        e: &toml::Table,
        before: &[UserFree],
    ) -> Result<UserFree, UserCauseError> {
        let keys = ["param", "min", "max", "factor", "start", "scan"];
        if let Some(bad) = e.keys().find(|x| !keys.contains(&x.as_str())) {
            return Err(self.err(
                &format!("{f}.{bad}"),
                "unknown key (expected param, min, max, factor, start, scan)",
            ));
        }
        let param = match e.get("param").and_then(|p| p.as_str()) {
            Some(p)
                if p.split_once('.')
                    .is_some_and(|(a, b)| valid_id(a) && valid_id(b)) =>
            {
                p.to_string()
            }
            Some(_) => return Err(self.err(&format!("{f}.param"), "must be block.parameter")),
            None => return Err(self.err(&format!("{f}.param"), "missing")),
        };
        if before.iter().any(|o| o.bound.param == param) {
            return Err(self.err(&format!("{f}.param"), "given twice"));
        }
        let get = |n: &str| -> Result<Option<f64>, UserCauseError> {
            match e.get(n) {
                None => Ok(None),
                Some(v) => num(v)
                    .filter(|x| x.is_finite())
                    .map(Some)
                    .ok_or_else(|| self.err(&format!("{f}.{n}"), "must be a finite number")),
            }
        };
        let (min, max, factor) = self.range(f, get("min")?, get("max")?, get("factor")?)?;
        let start = get("start")?;
        if let (Some(s), None) = (start, factor) {
            if !(s >= min && s <= max) {
                return Err(self.err(&format!("{f}.start"), "must lie within [min, max]"));
            }
        }
        let scan = match e.get("scan") {
            None => 0,
            Some(toml::Value::Integer(n)) if (0..=200).contains(n) => *n as usize,
            Some(_) => {
                return Err(self.err(&format!("{f}.scan"), "must be an integer from 0 to 200"))
            }
        };
        Ok(UserFree {
            bound: FreeBound {
                start,
                ..FreeBound::new(param, min, max).scanned(scan)
            },
            factor,
            field: format!("{f}.param"),
        })
    }

    /// An entry's `(min, max, factor)`: `min` and `max` (max above min), or a factor above 1
    /// (the bounds unset, NaN, until a unit gives its value), not both.
    fn range(
        &self,
        f: &str,
        min: Option<f64>,
        max: Option<f64>,
        factor: Option<f64>,
    ) -> Result<(f64, f64, Option<f64>), UserCauseError> {
        match (min, max, factor) {
            (Some(min), Some(max), None) => {
                if !(max > min) {
                    return Err(self.err(&format!("{f}.max"), "must exceed min"));
                }
                Ok((min, max, None))
            }
            (None, None, Some(fa)) => {
                if !(fa > 1.0) {
                    return Err(self.err(&format!("{f}.factor"), "must be > 1"));
                }
                Ok((f64::NAN, f64::NAN, Some(fa)))
            }
            _ => Err(self.err(
                f,
                "give min and max, or a factor around the unit's value (not both)",
            )),
        }
    }
}

/// The extension's text when the file gives none: the blocks it adds.
pub(super) fn default_extension(blocks: &[(String, toml::Table, String)]) -> String {
    let names: Vec<String> = blocks
        .iter()
        .map(|(n, bt, _)| {
            let m = bt.get("model").and_then(|v| v.as_str()).unwrap_or("?");
            format!("{n} ({m})")
        })
        .collect();
    format!("user-defined: {} added", names.join(", "))
}

/// One instance's rewiring in a cause file: the instance and its `(port, signal)` pairs.
pub(super) type Rewiring = (String, Vec<(String, String)>);
