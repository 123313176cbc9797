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

use itaipu_dynamics::unit::Unit;

use super::catalog;
use super::cause::{
    extend_cause, hidden_unit, hideable_params, Acts, Cause, CauseError, CauseInfo, Context,
    Extension, HideError, NotApplicable, Roles,
};
pub use super::cause_file::UserCauseError;
use super::cause_file::{build, default_extension, CauseFile, UserFree};
use super::cause_kit::around;
use super::not_applicable::writer_of;
use crate::bounds::FreeBound;

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
    /// files. Every block is built once here, so that a bad one is refused when the file is
    /// read.
    pub fn parse(text: &str, path: &Path) -> Result<Self, UserCauseError> {
        let t: toml::Table = text.parse().map_err(|e: toml::de::Error| UserCauseError {
            path: path.into(),
            field: "(syntax)".into(),
            msg: e.to_string().trim().replace('\n', " "),
        })?;
        let file = CauseFile { t: &t, path };
        file.check_keys()?;
        let id = file.id()?;
        let title = file.text("title", true)?;
        let signature = file.text("signature", false)?;
        let search_factor = file.search_factor()?;
        let from_datasheet = file.reads_from_datasheet()?;
        let band_top_hz = file.band_top_hz()?;
        let (blocks, built) = file.blocks()?;
        let rewire = file.rewire()?;
        let free = file.free_list("free", true)?;
        let interacting = file.free_list("interacting", false)?;
        file.check_params(free.iter().chain(&interacting), &built)?;
        let ties = file.ties()?;
        let mut extension = file.text("extension", false)?;
        if extension.is_empty() {
            extension = default_extension(&blocks);
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

    /// The extended unit, as [`catalog::extend`] builds one for a catalog cause
    /// ([`extend_cause`]): [`CauseError::NotApplicable`] when the cause does not apply to `unit`
    /// (a block name taken, an instance to rewire, a port or a parameter missing, a signal its
    /// blocks read that nothing writes), [`CauseError::Build`] when the extension cannot be
    /// built.
    pub fn extend(&self, unit: &Unit, ctx: &Context) -> Result<Extension, CauseError> {
        extend_cause(self, unit, ctx, 0)
    }

    /// Adds the file's blocks to `u` (each built again from its table).
    fn add_blocks(&self, u: &mut Unit) -> Result<(), CauseError> {
        let base = self.path.parent().unwrap_or(Path::new("."));
        for (name, bt, ctx) in &self.blocks {
            if u.block(name).is_some() {
                return Err(NotApplicable::NameTaken { name: name.clone() }.into());
            }
            let (block, rw) = build(ctx, bt, base, &self.path).map_err(CauseError::build)?;
            u.add(name, block, &rw).map_err(CauseError::build)?;
        }
        Ok(())
    }

    /// Moves the ports of `[rewire]` onto their new signals: an instance the unit lacks, or one
    /// without the port (a constant mechanical power reads no speed), is not applicable.
    fn rewire(&self, u: &mut Unit) -> Result<(), CauseError> {
        for (inst, ports) in &self.rewire {
            let Some(block) = u.block(inst) else {
                return Err(NotApplicable::NoInstance { name: inst.clone() }.into());
            };
            let has = |p: &str| block.ports().iter().any(|q| q.name == p);
            if let Some((port, _)) = ports.iter().find(|(p, _)| !has(p)) {
                return Err(NotApplicable::NoPort {
                    instance: inst.clone(),
                    model: block.model().to_string(),
                    port: port.clone(),
                }
                .into());
            }
            u.rewire(inst, ports)
                .map_err(|e| CauseError::build(format!("rewire.{inst}: {e}")))?;
        }
        Ok(())
    }

    /// A required input of one of the file's blocks that reads a signal no block of `u`
    /// writes, where the blocks of some role write it (a PSS's `vs`): the unit lacks that part.
    fn unwritten(&self, u: &Unit) -> Option<NotApplicable> {
        use itaipu_dynamics::block::{Dir, PortInit};
        let written = |s: &str| {
            u.instances().iter().any(|i| {
                i.block
                    .ports()
                    .iter()
                    .zip(&i.wiring)
                    .any(|(p, w)| w == s && (p.dir == Dir::Out || p.init == PortInit::Gives))
            })
        };
        let added = u
            .instances()
            .iter()
            .filter(|i| self.blocks.iter().any(|(n, _, _)| *n == i.name));
        for inst in added {
            let reads = inst.block.ports().iter().zip(&inst.wiring);
            for (_, signal) in reads.filter(|(p, _)| p.dir == Dir::In && !p.optional) {
                if !written(signal) {
                    if let Some(role) = writer_of(signal) {
                        return Some(NotApplicable::Unwritten {
                            block: inst.name.clone(),
                            signal: signal.clone(),
                            writer: Some(role),
                        });
                    }
                }
            }
        }
        None
    }

    /// The re-fit's bound of entry `s` in the extended unit `u`.
    fn bound(s: &UserFree, u: &Unit) -> Result<FreeBound, NotApplicable> {
        let param = &s.bound.param;
        let v = u
            .params()
            .into_iter()
            .find(|(p, _, _)| p == param)
            .map(|(_, _, v)| v)
            .ok_or_else(|| NotApplicable::NoParam {
                param: param.clone(),
                in_tie: false,
            })?;
        let (min, max) = match s.factor {
            None => (s.bound.min, s.bound.max),
            // The band around the value within the declared range, as for a catalog cause.
            Some(f) => around(u, param, f).map(|b| (b.min, b.max)).ok_or_else(|| {
                NotApplicable::NotPositive {
                    param: param.clone(),
                    value: v,
                }
            })?,
        };
        Ok(FreeBound {
            min,
            max,
            ..s.bound.clone()
        }
        .starting_at(s.bound.start.unwrap_or(v)))
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
        let known = hideable_params(unit, &ext);
        if let Some((p, _)) = values.iter().find(|(p, _)| !known.iter().any(|k| k == p)) {
            return Err(HideError::Request(format!(
                "{}: unknown parameter '{p}' (its parameters: {})",
                self.id,
                known.join(", ")
            )));
        }
        hidden_unit(&ext, values.iter().copied())
    }
}

impl Cause for UserCause {
    fn info(&self) -> CauseInfo<'_> {
        CauseInfo {
            id: &self.id,
            title: &self.title,
            signature: &self.signature,
            extension: &self.extension,
            key_params: &[],
        }
    }

    fn acts(&self) -> Acts {
        Acts::Unstated
    }

    fn band_top_hz(&self, _ctx: &Context) -> Option<f64> {
        self.band_top_hz
    }

    /// Adds the file's blocks, rewires the unit's ports onto their signals, and frees the
    /// `[[free]]` parameters (the extension's), the `[[interacting]]` ones the unit has (an
    /// interacting parameter the unit lacks, another exciter model's say, is left out) and the
    /// ties.
    fn extend(&self, x: &mut Extension, _roles: &Roles, _ctx: &Context) -> Result<(), CauseError> {
        self.add_blocks(&mut x.unit)?;
        self.rewire(&mut x.unit)?;
        if let Err(e) = x.unit.ensure_finished() {
            return Err(match self.unwritten(&x.unit) {
                Some(why) => why.into(),
                None => {
                    CauseError::build(format!("{}: the extended unit: {e}", self.path.display()))
                }
            });
        }
        let u = &x.unit;
        let extension_free = self
            .free
            .iter()
            .map(|s| Self::bound(s, u))
            .collect::<Result<Vec<_>, _>>()?;
        let interacting_free: Vec<FreeBound> = self
            .interacting
            .iter()
            .filter_map(|s| Self::bound(s, u).ok())
            .collect();
        for (leader, follower) in &self.ties {
            if let Some(p) = [leader, follower].into_iter().find(|p| u.param(p).is_err()) {
                return Err(NotApplicable::NoParam {
                    param: p.clone(),
                    in_tie: true,
                }
                .into());
            }
        }
        x.extension_free = extension_free;
        x.interacting_free = interacting_free;
        x.ties = self.ties.clone();
        x.search_factor = self.search_factor;
        x.from_datasheet = self.from_datasheet;
        Ok(())
    }
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

/// The cause `id` among the catalog's and `users` (a user's file of a catalog id cannot be
/// read, [`UserCause::parse`]).
pub fn lookup<'a>(id: &str, users: &'a [UserCause]) -> Option<&'a dyn Cause> {
    catalog::cause(id).or_else(|| {
        users
            .iter()
            .find(|u| u.id == id)
            .map(|u| u as &'a dyn Cause)
    })
}

/// Is `id` a catalog cause or one of `users`?
pub fn known(id: &str, users: &[UserCause]) -> bool {
    lookup(id, users).is_some()
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
