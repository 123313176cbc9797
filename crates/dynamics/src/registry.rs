//! The catalogue of block models by name, as written in unit files (`model = "GENSAE"`) and
//! `.dyr` records.
//!
//! **One model, one file.** Each model file declares, beside its equations, one [`ModelInfo`]
//! (`pub const MODEL`): its name, role, summary, the standard it follows and its PSS/E `.dyr`
//! record ([`DyrRecord`]: field order, flags, input codes). The file is registered by one line,
//! its module name in the `crate::library!` list of its folder's `mod.rs`
//! (`models/exciter/mod.rs` for an exciter). Everything else reads the entry: unit files, the
//! `.dyr` reader and writer, `itaipu-calib models`, Python's `models()`, the calibrator's
//! default spec (through the roles the block declares) and docs/model-library.md's table.
//! How to add a model: docs/model-library.md.

use crate::block::Block;
use crate::dyr::DyrRecord;

/// What a model is for; the unit file section it normally goes in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Role {
    Machine,
    Exciter,
    Pss,
    Governor,
    Other,
}

impl Role {
    pub fn section(self) -> &'static str {
        match self {
            Role::Machine => "machine",
            Role::Exciter => "exciter",
            Role::Pss => "pss",
            Role::Governor => "governor",
            Role::Other => "block",
        }
    }

    /// What a unit without a block of this role does instead (for the warning about a model
    /// the unit lacks).
    pub fn absence(self) -> &'static str {
        match self {
            Role::Machine => "nothing to simulate",
            Role::Exciter => {
                "E_fd held at its initial value E_fd0: no voltage regulation in P and Q"
            }
            Role::Pss => "V_S held at 0: no damping from the stabiliser in P and Q",
            Role::Governor => "P_m held at its initial value P_m0: no frequency response in P",
            Role::Other => "its action missing",
        }
    }
}

/// One catalogue entry: what the rest of the tool knows of a model. Declared once, in the
/// model's own file, as `pub const MODEL: ModelInfo`.
pub struct ModelInfo {
    /// Name in unit files and `.dyr` records (e.g. `ESST4B`).
    pub name: &'static str,
    pub role: Role,
    /// One line: what the model is.
    pub summary: &'static str,
    /// The standard or manual the equations follow, and the limiter convention (one line).
    pub reference: &'static str,
    /// A new block with typical parameter values.
    pub make: fn() -> Box<dyn Block>,
    /// Its PSS/E `.dyr` record (`None`: no PSS/E record, e.g. a model extension).
    pub dyr: Option<DyrRecord>,
}

impl ModelInfo {
    /// A new block with typical parameter values.
    pub fn create(&self) -> Box<dyn Block> {
        (self.make)()
    }
}

/// Declares the model files of a folder and the list the registry reads: one module name per
/// model, each module defining `pub const MODEL: ModelInfo`. The registration line of a new
/// model is its name in this list.
///
/// ```text
/// crate::library! {
///     sexs,
///     esst4b,
/// }
/// ```
#[macro_export]
macro_rules! library {
    ($($model:ident),* $(,)?) => {
        $(pub mod $model;)*
        /// The models of this folder, in the order `itaipu-calib models` lists them.
        pub const MODELS: &[&$crate::registry::ModelInfo] = &[$(&$model::MODEL),*];
    };
}

/// Every model: machines, exciters, stabilisers, governors, then the other blocks.
pub fn all() -> impl Iterator<Item = &'static ModelInfo> + Clone {
    use crate::models::{exciter, extensions, governor, grid, machine, pss};
    machine::MODELS
        .iter()
        .chain(exciter::MODELS)
        .chain(pss::MODELS)
        .chain(governor::MODELS)
        .chain(extensions::MODELS)
        .copied()
        .chain(std::iter::once(&grid::MODEL))
}

/// Every model, as [`all`] lists them.
pub static MODELS: std::sync::LazyLock<Vec<&'static ModelInfo>> =
    std::sync::LazyLock::new(|| all().collect());

/// Looks a model up by name (case-insensitive).
pub fn find(name: &str) -> Option<&'static ModelInfo> {
    all().find(|m| m.name.eq_ignore_ascii_case(name))
}

/// Names of all models, for error messages.
pub fn names() -> String {
    all().map(|m| m.name).collect::<Vec<_>>().join(", ")
}

/// The models with a PSS/E record, for messages.
pub fn dyr_names() -> Vec<&'static str> {
    all().filter(|m| m.dyr.is_some()).map(|m| m.name).collect()
}

/// The roles a block declares, `role = parameter` for each that applies (`None` for a block
/// without roles): one line for `itaipu-calib models` and the library table.
pub fn roles_line(b: &dyn Block) -> Option<String> {
    use crate::models::exciter::roles::{LeadLagRole, ParamRole};
    fn join(params: &[(&str, &ParamRole)], lls: &[(&str, &LeadLagRole)]) -> String {
        let mut v: Vec<String> = params
            .iter()
            .filter_map(|(role, r)| r.name().map(|n| format!("{role} = {n}")))
            .collect();
        v.extend(lls.iter().filter_map(|(role, r)| match r {
            LeadLagRole::LeadLag { lead, lag } => Some(format!("{role} = ({lead}, {lag})")),
            LeadLagRole::RatioLag { ratio, lag } => {
                Some(format!("{role} = ({ratio}·{lag}, {lag})"))
            }
            LeadLagRole::NotApplicable(_) => None,
        }));
        v.join(", ")
    }
    if let Some(r) = b.exciter_roles() {
        let tgr = crate::models::exciter::roles::TGR_ROLE_NAME;
        return Some(join(&r.params(), &[(tgr, &r.transient_gain_reduction)]));
    }
    if let Some(r) = b.governor_roles() {
        return Some(join(&r.params(), &r.lead_lags()));
    }
    b.pss_roles().map(|r| join(&r.params(), &r.lead_lags()))
}

/// The library as a Markdown table (docs/model-library.md's, which a test keeps equal to this):
/// one row per model with its role, the standard it follows, its `.dyr` record and its roles.
pub fn library_table() -> String {
    let mut s = String::from(
        "| model | role | follows | `.dyr` record after `IBUS 'MODEL' ID` | roles (role = parameter) |\n|---|---|---|---|---|\n",
    );
    for m in all() {
        let b = m.create();
        let record = match &m.dyr {
            Some(r) if r.is_empty() => "(none)".to_string(),
            Some(r) => r.field_names(b.as_ref()).join(" "),
            None => "no PSS/E record".to_string(),
        };
        let roles = roles_line(b.as_ref()).unwrap_or_else(|| "—".into());
        s.push_str(&format!(
            "| {} | {} | {} | {} | {} |\n",
            m.name,
            m.role.section(),
            m.reference.replace('|', "\\|"),
            record,
            if roles.is_empty() {
                "—".into()
            } else {
                roles
            }
        ));
    }
    s
}

/// What `models NAME` shows: a model of the library, or the diagram primitives
/// (`NAME = "diagram"`, any case).
pub enum Listing {
    Model(&'static ModelInfo),
    DiagramPrimitives,
}

/// The listing of `models NAME` (the command line's and Python's `models(name)`), or the
/// message naming every name it takes.
pub fn listing(name: &str) -> Result<Listing, String> {
    if name.eq_ignore_ascii_case("diagram") {
        return Ok(Listing::DiagramPrimitives);
    }
    find(name)
        .map(Listing::Model)
        .ok_or_else(|| format!("unknown model '{name}' (known: {}, diagram)", names()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_unique_and_every_entry_builds_its_own_model() {
        let mut seen = std::collections::HashSet::new();
        for m in all() {
            assert!(seen.insert(m.name.to_ascii_uppercase()), "{} twice", m.name);
            let b = m.create();
            assert_eq!(b.model(), m.name, "{}'s MODEL builds another model", m.name);
            assert!(
                !m.summary.is_empty() && !m.reference.is_empty(),
                "{}",
                m.name
            );
        }
    }

    #[test]
    fn every_dyr_record_names_parameters_and_ports_of_its_model() {
        for m in all() {
            let Some(r) = &m.dyr else { continue };
            let b = m.create();
            if let Err(e) = r.check(b.as_ref()) {
                panic!("{}: {e}", m.name);
            }
        }
    }
}
