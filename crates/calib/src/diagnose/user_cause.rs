//! Causes written by the user: a cause of the diagnosis that is not in the built-in
//! [`catalog`](super::catalog), declared in a TOML file as the blocks its model extension adds
//! to the unit (user-defined diagrams or library models), the ports of the unit's blocks it
//! moves onto their signals, and the parameters the re-fit frees. `diagnose` tries it beside
//! the catalog's causes and judges it by the same rules (ΔBIC, held-out gain, null gain).
//!
//! ```toml
//! id = "reactive_droop"                   # letters, digits, _; not a catalog id
//! title = "reactive-current compensation (droop) in the AVR"
//! signature = "…"                         # optional: what it looks like in the residual
//! extension = "…"                         # optional: what the extension is (for the report)
//! search_factor = 1                       # optional: longer swarm for this cause
//! from_datasheet = false                  # optional: a limit's re-fit also starts from the
//!                                         # datasheet values (Extension::from_datasheet)
//! band_top_hz = 12.0                      # optional: the highest frequency its extension's
//!                                         # dynamics must reproduce [Hz] (Cause::band_top_hz):
//!                                         # above the events' input cut-off, its re-fits play
//!                                         # the record as recorded
//! [[block]]                               # one or more, as in a unit file's [[block]]
//! name = "droop"
//! model = "diagram"                       # or a library model
//! diagram = "reactive_droop.diagram.toml" # relative to the cause file
//! x_c = 0.0
//! [rewire]                                # optional: instance = { port = "signal" }
//! exciter = { v_term = "v_comp" }
//! [[free]]                                # one or more: the extension's own parameters
//! param = "droop.x_c"
//! min = -0.15
//! max = 0.15
//! start = 0.0                             # optional (default: the value in the unit)
//! scan = 13                               # optional: grid points before the swarm
//! [[interacting]]                         # optional: the unit's parameters it trades with
//! param = "exciter.k"
//! factor = 3.0                            # [v/factor, v·factor], or min = …, max = …
//! [tie]                                   # optional: "follower" = "leader"
//! ```
//!
//! The file is checked when it is read (every block is built, so a bad diagram is refused with
//! its file, block and field); whether it applies to a unit (the instances it rewires, the
//! parameters it frees) is decided per unit, as for a catalog cause.

use std::path::{Path, PathBuf};

use itaipu_dynamics::registry;
use itaipu_dynamics::unit::Unit;
use itaipu_dynamics::unit_file::{build_block, build_diagram_block, BuiltBlock};

use super::catalog::{self, CauseError, Context, Extension, HideError};
use crate::bounds::FreeBound;

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
struct UserFree {
    bound: FreeBound,
    factor: Option<f64>,
    /// The entry's field in the file (messages).
    field: String,
}

/// A cause read from a file.
#[derive(Debug, Clone)]
pub struct UserCause {
    pub id: String,
    pub title: String,
    pub signature: String,
    pub extension: String,
    /// The file it was read from (messages).
    pub path: PathBuf,
    search_factor: usize,
    /// The re-fit also starts from the datasheet values ([`Extension::from_datasheet`]).
    from_datasheet: bool,
    /// The highest frequency the extension's dynamics must reproduce [Hz], as a catalog
    /// cause's [`catalog::Cause::band_top_hz`] (`None`: the control band).
    band_top_hz: Option<f64>,
    /// `(instance name, section, field prefix)`.
    blocks: Vec<(String, toml::Table, String)>,
    rewire: Vec<(String, Vec<(String, String)>)>,
    free: Vec<UserFree>,
    interacting: Vec<UserFree>,
    /// `(leader, follower)`.
    ties: Vec<(String, String)>,
}

fn valid_id(s: &str) -> bool {
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

impl UserCause {
    /// Reads and checks a cause file.
    pub fn read(path: &Path) -> Result<Self, UserCauseError> {
        let text = std::fs::read_to_string(path).map_err(|e| UserCauseError {
            path: path.into(),
            field: "(file)".into(),
            msg: format!("cannot read it: {e}"),
        })?;
        Self::parse(&text, path)
    }

    /// Parses and checks cause-file text; `path` names it in messages and resolves diagram
    /// files.
    pub fn parse(text: &str, path: &Path) -> Result<Self, UserCauseError> {
        let err = |field: &str, msg: String| UserCauseError {
            path: path.into(),
            field: field.to_string(),
            msg,
        };
        let t: toml::Table = text.parse().map_err(|e: toml::de::Error| {
            err("(syntax)", e.to_string().trim().replace('\n', " "))
        })?;
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
        if let Some(k) = t.keys().find(|k| !known.contains(&k.as_str())) {
            return Err(err(
                k,
                format!("unknown key (expected one of: {})", known.join(", ")),
            ));
        }
        let text_of = |key: &str, required: bool| -> Result<String, UserCauseError> {
            match t.get(key) {
                Some(toml::Value::String(s)) => Ok(s.trim().to_string()),
                Some(_) => Err(err(key, "must be a string".into())),
                None if required => Err(err(key, "missing".into())),
                None => Ok(String::new()),
            }
        };
        let id = text_of("id", true)?;
        if !valid_id(&id) {
            return Err(err(
                "id",
                format!("'{id}' is not an identifier (letters, digits and _)"),
            ));
        }
        if catalog::find(&id).is_some() || super::NO_CAUSE_VERDICTS.contains(&id.as_str()) {
            return Err(err(
                "id",
                format!(
                    "'{id}' is taken (the built-in causes: {}; and {})",
                    catalog::ids(),
                    super::NO_CAUSE_VERDICTS.join(", ")
                ),
            ));
        }
        let title = text_of("title", true)?;
        let signature = text_of("signature", false)?;
        let search_factor = match t.get("search_factor") {
            None => 1,
            Some(toml::Value::Integer(n)) if (1..=20).contains(n) => *n as usize,
            Some(_) => {
                return Err(err(
                    "search_factor",
                    "must be an integer from 1 to 20".into(),
                ))
            }
        };
        let from_datasheet = match t.get("from_datasheet") {
            None => false,
            Some(toml::Value::Boolean(b)) => *b,
            Some(_) => return Err(err("from_datasheet", "must be true or false".into())),
        };
        // A mode the re-fits must reproduce: positive and finite (whether it lies above an
        // event's cut-off is decided per event).
        let band_top_hz = match t.get("band_top_hz") {
            None => None,
            Some(v) => match v.as_float().or_else(|| v.as_integer().map(|n| n as f64)) {
                Some(f) if f.is_finite() && f > 0.0 => Some(f),
                _ => {
                    return Err(err(
                        "band_top_hz",
                        "must be a positive number of hertz".into(),
                    ))
                }
            },
        };

        // Blocks: each built once here, so that a bad one is refused when the file is read.
        let base = path.parent().unwrap_or(Path::new("."));
        let list = match t.get("block") {
            Some(toml::Value::Array(a)) if !a.is_empty() => a,
            Some(_) => return Err(err("block", "must be one or more [[block]] tables".into())),
            None => {
                return Err(err(
                    "block",
                    "missing: a cause adds one or more [[block]] (its model extension)".into(),
                ))
            }
        };
        let mut blocks = vec![];
        let mut built: Vec<(String, BuiltBlock)> = vec![];
        for (k, b) in list.iter().enumerate() {
            let f = format!("block[{k}]");
            let bt = b
                .as_table()
                .ok_or_else(|| err(&f, "must be a table".into()))?;
            let name = match bt.get("name") {
                Some(toml::Value::String(s)) if valid_id(s) => s.clone(),
                Some(_) => {
                    return Err(err(
                        &format!("{f}.name"),
                        "must be an identifier (letters, digits and _)".into(),
                    ))
                }
                None => return Err(err(&format!("{f}.name"), "missing".into())),
            };
            let ctx = format!("block '{name}'");
            if blocks.iter().any(|(n, _, _)| *n == name) {
                return Err(err(
                    &format!("{ctx}.name"),
                    "two blocks have this name".into(),
                ));
            }
            let bb = build(&ctx, bt, base, path)?;
            built.push((name.clone(), bb));
            blocks.push((name, bt.clone(), ctx));
        }

        let mut rewire = vec![];
        match t.get("rewire") {
            None => {}
            Some(toml::Value::Table(rw)) => {
                for (inst, ports) in rw {
                    let f = format!("rewire.{inst}");
                    let pt = ports
                        .as_table()
                        .ok_or_else(|| err(&f, "must be a table { port = \"signal\" }".into()))?;
                    let mut v = vec![];
                    for (port, sig) in pt {
                        let s = sig.as_str().ok_or_else(|| {
                            err(&format!("{f}.{port}"), "must be a signal name".into())
                        })?;
                        v.push((port.clone(), s.to_string()));
                    }
                    rewire.push((inst.clone(), v));
                }
            }
            Some(_) => {
                return Err(err(
                    "rewire",
                    "must be a table: instance = { port = \"signal\" }".into(),
                ))
            }
        }

        let free = free_list(&t, "free", path, true)?;
        let interacting = free_list(&t, "interacting", path, false)?;
        // A parameter of an added block must exist in that block (checked now); one of the
        // unit's is checked against each unit.
        for s in free.iter().chain(&interacting) {
            let param = &s.bound.param;
            let (inst, p) = param.split_once('.').unwrap_or((param, ""));
            if let Some((_, (b, _))) = built.iter().find(|(n, _)| n == inst) {
                if b.params().index_of(p).is_none() {
                    let names: Vec<&str> = b.params().specs().iter().map(|x| x.name).collect();
                    return Err(err(
                        &s.field,
                        format!(
                            "block '{inst}' has no parameter '{p}' (parameters: {})",
                            names.join(", ")
                        ),
                    ));
                }
            }
        }
        let mut ties = vec![];
        match t.get("tie") {
            None => {}
            Some(toml::Value::Table(tt)) => {
                for (follower, leader) in tt {
                    let l = leader.as_str().ok_or_else(|| {
                        err(
                            &format!("tie.{follower}"),
                            "must be the parameter it follows".into(),
                        )
                    })?;
                    ties.push((l.to_string(), follower.clone()));
                }
            }
            Some(_) => return Err(err("tie", "must be a table: follower = \"leader\"".into())),
        }
        let mut extension = text_of("extension", false)?;
        if extension.is_empty() {
            let names: Vec<String> = blocks
                .iter()
                .map(|(n, bt, _)| {
                    let m = bt.get("model").and_then(|v| v.as_str()).unwrap_or("?");
                    format!("{n} ({m})")
                })
                .collect();
            extension = format!("user-defined: {} added", names.join(", "));
        }
        Ok(Self {
            id,
            title,
            signature,
            extension,
            path: path.into(),
            search_factor,
            from_datasheet,
            band_top_hz,
            blocks,
            rewire,
            free,
            interacting,
            ties,
        })
    }

    /// The extended unit, as [`catalog::extend`] builds one for a catalog cause:
    /// [`CauseError::NotApplicable`] when the cause does not apply to `unit` (a block name
    /// taken, an instance to rewire or a parameter to free missing), [`CauseError::Build`] when
    /// the extension cannot be built.
    pub fn extend(&self, unit: &Unit, _ctx: &Context) -> Result<Extension, CauseError> {
        let mut u = unit.clone();
        u.ensure_finished().map_err(CauseError::build)?;
        let base = self.path.parent().unwrap_or(Path::new("."));
        for (name, bt, ctx) in &self.blocks {
            if u.block(name).is_some() {
                return Err(CauseError::not_applicable(format!(
                    "the unit already has a block named '{name}'"
                )));
            }
            let (block, rw) = build(ctx, bt, base, &self.path).map_err(CauseError::build)?;
            u.add(name, block, &rw).map_err(CauseError::build)?;
        }
        for (inst, ports) in &self.rewire {
            if u.block(inst).is_none() {
                return Err(CauseError::not_applicable(format!(
                    "the unit has no block named '{inst}' to rewire"
                )));
            }
            u.rewire(inst, ports)
                .map_err(|e| CauseError::build(format!("rewire.{inst}: {e}")))?;
        }
        u.ensure_finished().map_err(|e| {
            CauseError::build(format!("{}: the extended unit: {e}", self.path.display()))
        })?;
        let bound = |s: &UserFree| -> Result<FreeBound, String> {
            let param = &s.bound.param;
            let v = u
                .params()
                .into_iter()
                .find(|(p, _, _)| p == param)
                .map(|(_, _, v)| v)
                .ok_or_else(|| format!("the unit has no parameter '{param}'"))?;
            let (min, max) = match s.factor {
                None => (s.bound.min, s.bound.max),
                // The band around the value within the declared range, as for a catalog cause.
                Some(f) => catalog::around(&u, param, f)
                    .map(|b| (b.min, b.max))
                    .ok_or_else(|| {
                        format!("{param} = {v} is not > 0, so it cannot be freed by a factor")
                    })?,
            };
            Ok(FreeBound {
                min,
                max,
                ..s.bound.clone()
            }
            .starting_at(s.bound.start.unwrap_or(v)))
        };
        let extension_free = self
            .free
            .iter()
            .map(bound)
            .collect::<Result<Vec<_>, _>>()
            .map_err(CauseError::NotApplicable)?;
        // An interacting parameter the unit lacks (another exciter model, say) is left out.
        let interacting_free: Vec<FreeBound> = self
            .interacting
            .iter()
            .filter_map(|s| bound(s).ok())
            .collect();
        for (leader, follower) in &self.ties {
            for p in [leader, follower] {
                if u.param(p).is_err() {
                    return Err(CauseError::not_applicable(format!(
                        "tie: the unit has no parameter '{p}'"
                    )));
                }
            }
        }
        let mut ext = Extension {
            cause: itaipu_dynamics::diagram::intern::str(&self.id),
            unit: u,
            extension_free,
            interacting_free,
            discrete_params: 0,
            ties: self.ties.clone(),
            description: self.extension.clone(),
            fixed: vec![],
            search_factor: self.search_factor,
            from_datasheet: self.from_datasheet,
        };
        catalog::free_nuisance(&mut ext);
        Ok(ext)
    }

    /// The unit with this cause in it at chosen values (`block.param` among the freed and the
    /// added blocks' parameters), the others of the extension at their starts: a synthetic
    /// truth for testing the cause.
    pub fn hide(
        &self,
        unit: &Unit,
        ctx: &Context,
        values: &[(&str, f64)],
    ) -> Result<Unit, HideError> {
        let ext = self
            .extend(unit, ctx)
            .map_err(|e| HideError::from_cause(&self.id, unit, e))?;
        let known = catalog::hideable_params(unit, &ext);
        if let Some((p, _)) = values.iter().find(|(p, _)| !known.iter().any(|k| k == p)) {
            return Err(HideError::Request(format!(
                "{}: unknown parameter '{p}' (its parameters: {})",
                self.id,
                known.join(", ")
            )));
        }
        catalog::hidden_unit(&ext, values.iter().copied())
    }
}

/// Builds one block of a cause file (a diagram or a library model).
fn build(
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

fn free_list(
    t: &toml::Table,
    key: &str,
    path: &Path,
    required: bool,
) -> Result<Vec<UserFree>, UserCauseError> {
    let err = |field: String, msg: &str| UserCauseError {
        path: path.into(),
        field,
        msg: msg.to_string(),
    };
    let list = match t.get(key) {
        Some(toml::Value::Array(a)) if !a.is_empty() || !required => a.clone(),
        None if !required => vec![],
        None => return Err(err(
            key.into(),
            "missing: a cause frees one or more [[free]] { param, min, max } (its own parameters)",
        )),
        Some(_) => return Err(err(key.into(), "must be one or more tables")),
    };
    let mut out: Vec<UserFree> = vec![];
    for (k, v) in list.iter().enumerate() {
        let f = format!("{key}[{k}]");
        let e = v
            .as_table()
            .ok_or_else(|| err(f.clone(), "must be a table"))?;
        if let Some(bad) = e
            .keys()
            .find(|x| !["param", "min", "max", "factor", "start", "scan"].contains(&x.as_str()))
        {
            return Err(err(
                format!("{f}.{bad}"),
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
            Some(_) => return Err(err(format!("{f}.param"), "must be block.parameter")),
            None => return Err(err(format!("{f}.param"), "missing")),
        };
        if out.iter().any(|o| o.bound.param == param) {
            return Err(err(format!("{f}.param"), "given twice"));
        }
        let get = |n: &str| -> Result<Option<f64>, UserCauseError> {
            match e.get(n) {
                None => Ok(None),
                Some(v) => num(v)
                    .filter(|x| x.is_finite())
                    .map(Some)
                    .ok_or_else(|| err(format!("{f}.{n}"), "must be a finite number")),
            }
        };
        let (min, max, factor) = match (get("min")?, get("max")?, get("factor")?) {
            (Some(min), Some(max), None) => {
                if !(max > min) {
                    return Err(err(format!("{f}.max"), "must exceed min"));
                }
                (min, max, None)
            }
            (None, None, Some(fa)) => {
                if !(fa > 1.0) {
                    return Err(err(format!("{f}.factor"), "must be > 1"));
                }
                (f64::NAN, f64::NAN, Some(fa))
            }
            _ => {
                return Err(err(
                    f.clone(),
                    "give min and max, or a factor around the unit's value (not both)",
                ))
            }
        };
        let start = get("start")?;
        if let (Some(s), None) = (start, factor) {
            if !(s >= min && s <= max) {
                return Err(err(format!("{f}.start"), "must lie within [min, max]"));
            }
        }
        let scan = match e.get("scan") {
            None => 0,
            Some(toml::Value::Integer(n)) if (0..=200).contains(n) => *n as usize,
            Some(_) => return Err(err(format!("{f}.scan"), "must be an integer from 0 to 200")),
        };
        out.push(UserFree {
            bound: FreeBound {
                start,
                ..FreeBound::new(param, min, max).scanned(scan)
            },
            factor,
            field: format!("{f}.param"),
        });
    }
    Ok(out)
}

/// Reads cause files, refusing two with the same id.
pub fn read_all(paths: &[PathBuf]) -> Result<Vec<UserCause>, UserCauseError> {
    let mut out: Vec<UserCause> = vec![];
    for p in paths {
        let c = UserCause::read(p)?;
        if let Some(o) = out.iter().find(|o| o.id == c.id) {
            return Err(UserCauseError {
                path: p.clone(),
                field: "id".into(),
                msg: format!("'{}' is also the id of {}", c.id, o.path.display()),
            });
        }
        out.push(c);
    }
    Ok(out)
}

// --- The hook used by `diagnose`: catalog and user causes behind one lookup. ---

/// Is `id` a catalog cause or one of `users`?
pub fn known(id: &str, users: &[UserCause]) -> bool {
    catalog::find(id).is_some() || users.iter().any(|u| u.id == id)
}

/// Every id: the catalog's, then the user causes', for messages.
pub fn ids(users: &[UserCause]) -> String {
    let mut s = catalog::ids();
    for u in users {
        s.push_str(", ");
        s.push_str(&u.id);
    }
    s
}

/// Title and extension text of a cause.
pub fn describe(id: &str, users: &[UserCause]) -> Option<(String, String)> {
    if let Some(c) = catalog::find(id) {
        return Some((c.title.to_string(), c.extension.to_string()));
    }
    users
        .iter()
        .find(|u| u.id == id)
        .map(|u| (u.title.clone(), u.extension.clone()))
}

/// The highest frequency cause `id`'s extension must reproduce [Hz]: a catalog cause's
/// [`catalog::Cause::band_top_hz`], a user cause's declared `band_top_hz`.
pub fn band_top_hz(id: &str, ctx: &Context, users: &[UserCause]) -> Option<f64> {
    match users.iter().find(|u| u.id == id) {
        Some(u) => u.band_top_hz,
        None => catalog::cause(id).and_then(|c| c.band_top_hz(ctx)),
    }
}

/// [`catalog::extend_all`] for a catalog cause (every variant), [`UserCause::extend`] for a
/// user one (one structure).
pub fn extend_all(
    id: &str,
    unit: &Unit,
    ctx: &Context,
    users: &[UserCause],
) -> Result<Vec<Extension>, catalog::CauseError> {
    match users.iter().find(|u| u.id == id) {
        Some(u) => Ok(vec![u.extend(unit, ctx)?]),
        None => catalog::extend_all(id, unit, ctx),
    }
}

/// [`catalog::extend`] for a catalog cause, [`UserCause::extend`] for a user one.
pub fn extend(
    id: &str,
    unit: &Unit,
    ctx: &Context,
    users: &[UserCause],
) -> Result<Extension, catalog::CauseError> {
    match users.iter().find(|u| u.id == id) {
        Some(u) => u.extend(unit, ctx),
        None => catalog::extend(id, unit, ctx),
    }
}
