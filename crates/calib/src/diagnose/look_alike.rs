//! Look-alikes: effects outside the catalog that every full diagnosis also tries, so that a
//! residual one of them explains better is not given the nearest catalog name.
//!
//! A catalog cause can mimic an effect the catalog does not list: a reactive-current droop in
//! the AVR bends the Q response in the dip much as a stronger saturation does, and a
//! saturation extension with a strong curve then passes every test against its own baseline.
//! Its test asks "does this cause explain the residual?", not "does it explain it better than
//! what else a real unit carries?". The look-alikes answer the second question for the common
//! settings a generic model leaves out (the ones `data/causes/` ships as user-defined
//! diagrams): a reactive droop, a voltage transducer lag, a governor speed filter, a PSS
//! lead-lag stage and an under-excitation limiter.
//!
//! They are the bundled cause files themselves, built into the library (the CLI, the Python
//! module and the practice runner see the same five, with no data folder). They are scored
//! like user causes, after the catalog's and the user's, and only when something was
//! significant (without a significant candidate there is no name to guard). They are never
//! named: when one is the best significant candidate the verdict is `unexplained`, saying
//! which effect it looks like and how to name it (`--user-cause` with its file); when one is
//! within the BIC threshold of the best, the verdict is `inconclusive` like for any two causes
//! that explain the residual about equally. A cause file the user passes with the same id
//! replaces its look-alike (it is then a candidate that can be named).

use std::path::Path;

use super::user_cause::{UserCause, UserCauseError};

/// `(cause file, its text, diagram file, its text)`, from `data/causes/`.
const BUNDLED: [(&str, &str, &str, &str); 5] = [
    (
        "reactive_droop.toml",
        include_str!("../../../../data/causes/reactive_droop.toml"),
        "reactive_droop.diagram.toml",
        include_str!("../../../../data/causes/reactive_droop.diagram.toml"),
    ),
    (
        "avr_transducer.toml",
        include_str!("../../../../data/causes/avr_transducer.toml"),
        "avr_transducer.diagram.toml",
        include_str!("../../../../data/causes/avr_transducer.diagram.toml"),
    ),
    (
        "governor_speed_filter.toml",
        include_str!("../../../../data/causes/governor_speed_filter.toml"),
        "governor_speed_filter.diagram.toml",
        include_str!("../../../../data/causes/governor_speed_filter.diagram.toml"),
    ),
    (
        "pss_lead_lag.toml",
        include_str!("../../../../data/causes/pss_lead_lag.toml"),
        "pss_lead_lag.diagram.toml",
        include_str!("../../../../data/causes/pss_lead_lag.diagram.toml"),
    ),
    (
        "uel.toml",
        include_str!("../../../../data/causes/uel.toml"),
        "uel.diagram.toml",
        include_str!("../../../../data/causes/uel.diagram.toml"),
    ),
];

/// Where a look-alike's file lives in the repository (messages, and the `--user-cause` hint).
pub fn file_of(id: &str) -> String {
    format!("data/causes/{id}.toml")
}

/// One bundled cause file with its diagram put inline (the `diagram = "file"` entry replaced by
/// the definition's table), parsed as a user cause.
fn parse_bundled(
    file: &str,
    text: &str,
    diagram_file: &str,
    diagram_text: &str,
) -> Result<UserCause, UserCauseError> {
    let path = Path::new("data/causes").join(file);
    let err = |field: &str, msg: String| UserCauseError {
        path: path.clone(),
        field: field.into(),
        msg,
    };
    let mut t: toml::Table = text
        .parse()
        .map_err(|e: toml::de::Error| err("(syntax)", e.to_string()))?;
    let diagram: toml::Table = diagram_text
        .parse()
        .map_err(|e: toml::de::Error| err(diagram_file, e.to_string()))?;
    if let Some(toml::Value::Array(blocks)) = t.get_mut("block") {
        for b in blocks.iter_mut().filter_map(|b| b.as_table_mut()) {
            if b.get("diagram").and_then(|d| d.as_str()) == Some(diagram_file) {
                b.insert("diagram".into(), toml::Value::Table(diagram.clone()));
            }
        }
    }
    UserCause::parse(&t.to_string(), &path)
}

/// The bundled look-alikes, parsed once.
pub fn bundled() -> &'static [UserCause] {
    static ALL: std::sync::OnceLock<Vec<UserCause>> = std::sync::OnceLock::new();
    ALL.get_or_init(|| {
        BUNDLED
            .iter()
            .map(|(f, t, df, dt)| {
                // The files are the repository's own, checked by the test below: a failure
                // here is a build of broken data, not a user's input.
                parse_bundled(f, t, df, dt).unwrap_or_else(|e| panic!("bundled look-alike: {e}"))
            })
            .collect()
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every bundled file parses with its diagram inline, under the id its file is named after
    /// and no catalog id, and extends the synthetic unit (GENSAE, SEXS, STAB3, HYGOV).
    #[test]
    fn the_bundled_look_alikes_parse_and_extend() {
        let all = bundled();
        assert_eq!(all.len(), BUNDLED.len());
        for (u, (f, ..)) in all.iter().zip(BUNDLED) {
            assert_eq!(format!("{}.toml", u.id), f);
            assert_eq!(file_of(&u.id), format!("data/causes/{f}"));
            assert!(
                super::super::catalog::find(&u.id).is_none(),
                "{} shadows a catalog cause",
                u.id
            );
        }
        let unit = super::super::trial::base_unit();
        let ctx = super::super::catalog::Context::default();
        for u in all {
            let ext = u
                .extend(&unit, &ctx)
                .unwrap_or_else(|e| panic!("{}: {e}", u.id));
            assert!(!ext.extension_free.is_empty(), "{}", u.id);
        }
    }
}
