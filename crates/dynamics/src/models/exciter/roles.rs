//! Exciter roles: which parameter of an exciter model plays each part a diagnosis reasons about
//! (the regulator gain, the field time constant, the ceiling, …), declared by the model itself
//! so that code working on "the exciter" never has to know one model's parameter names.
//!
//! Every built-in exciter answers [`Block::exciter_roles`](crate::block::Block::exciter_roles);
//! a user-defined diagram declares its roles in an `[exciter_roles]` table of its definition
//! ([`ExciterRoles::from_toml`]). A role no parameter plays is [`ParamRole::NotApplicable`] with
//! a short reason meant to be printed as is ("not applicable: …").
//!
//! | role | meaning |
//! |---|---|
//! | `gain` | steady-state (regulator) gain from the voltage error to E_fd: SEXS `K`, ST5B `K_R`, IEEET1 `KA`, ESST1A `KA`; a PI regulator's proportional gain (ESST4B `KPR`) |
//! | `integral_gain` | a PI regulator's integral gain (ESST4B `KIR`) |
//! | `field_time_constant` | dominant exciter / bridge time constant: SEXS `T_E`, ST5B `T_1`, IEEET1 `TE`, ESST1A `TA` |
//! | `ceiling`, `floor` | a constant limit on E_fd in pu of E_fd (moving it moves E_fd's limit one for one) |
//! | `v_ref_offset` | the set-point offset nuisance parameter added after initialisation |
//! | `transient_gain_reduction` | the lead-lag that reduces the transient gain, `(1 + sT_C)/(1 + sT_B)` |
//! | `supply_ceiling`, `supply_floor` | `X` in an E_fd limit `V_t·X (− K_C·X_adI_fd)` of a bus-fed bridge |
//! | `commutation` | `K_C`, the rectifier commutation factor on X_adI_fd |
//! | `regulator_ceiling`, `regulator_floor` | a limit on the regulator output upstream of the exciter stage |

use crate::params::ParamSet;

/// The part one parameter plays, or why no parameter plays it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ParamRole {
    /// Canonical name of the parameter in the block's parameter set (e.g. `k_r`).
    Param(String),
    /// No parameter of the model plays the role; a short reason ("ST5B's ceiling is …").
    NotApplicable(String),
}

impl ParamRole {
    /// The parameter that plays the role.
    pub fn param(name: &str) -> Self {
        ParamRole::Param(name.to_string())
    }
    /// No parameter plays the role, because `reason`.
    pub fn none(reason: impl Into<String>) -> Self {
        ParamRole::NotApplicable(reason.into())
    }
    /// The parameter's canonical name, if one plays the role.
    pub fn name(&self) -> Option<&str> {
        match self {
            ParamRole::Param(p) => Some(p),
            ParamRole::NotApplicable(_) => None,
        }
    }
    /// Why no parameter plays the role (`None` when one does).
    pub fn reason(&self) -> Option<&str> {
        match self {
            ParamRole::Param(_) => None,
            ParamRole::NotApplicable(r) => Some(r),
        }
    }
}

/// The transient-gain-reduction lead-lag of the regulator.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum LeadLagRole {
    /// `(1 + sT_C)/(1 + sT_B)` with lead `T_C` and lag `T_B` given as time constants.
    LeadLag { lead: String, lag: String },
    /// `(1 + s·r·T_B)/(1 + sT_B)`: the lead given as the ratio `r = T_C/T_B` (SEXS's `T_A/T_B`)
    /// and the lag `T_B`.
    RatioLag { ratio: String, lag: String },
    /// The model has no such lead-lag; why.
    NotApplicable(String),
}

impl LeadLagRole {
    /// The parameters involved, in the order (lead or ratio, lag).
    pub fn names(&self) -> Option<(&str, &str)> {
        match self {
            LeadLagRole::LeadLag { lead, lag } => Some((lead, lag)),
            LeadLagRole::RatioLag { ratio, lag } => Some((ratio, lag)),
            LeadLagRole::NotApplicable(_) => None,
        }
    }
    /// Why the model has none (`None` when it has one).
    pub fn reason(&self) -> Option<&str> {
        match self {
            LeadLagRole::NotApplicable(r) => Some(r),
            _ => None,
        }
    }
}

/// Which parameter of an exciter plays each role (see the module documentation).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ExciterRoles {
    pub gain: ParamRole,
    pub integral_gain: ParamRole,
    pub field_time_constant: ParamRole,
    pub ceiling: ParamRole,
    pub floor: ParamRole,
    pub v_ref_offset: ParamRole,
    pub transient_gain_reduction: LeadLagRole,
    pub supply_ceiling: ParamRole,
    pub supply_floor: ParamRole,
    pub commutation: ParamRole,
    pub regulator_ceiling: ParamRole,
    pub regulator_floor: ParamRole,
}

/// Names of the single-parameter roles, in the order of [`ExciterRoles::params`] (the keys of a
/// diagram's `[exciter_roles]` table, with `transient_gain_reduction`).
pub const PARAM_ROLE_NAMES: &[&str] = &[
    "gain",
    "integral_gain",
    "field_time_constant",
    "ceiling",
    "floor",
    "v_ref_offset",
    "supply_ceiling",
    "supply_floor",
    "commutation",
    "regulator_ceiling",
    "regulator_floor",
];

/// Key of the lead-lag role.
pub const TGR_ROLE_NAME: &str = "transient_gain_reduction";

impl ExciterRoles {
    /// Every role not applicable, each with `reason`; set the fields that apply.
    pub fn none(reason: &str) -> Self {
        let n = || ParamRole::none(reason);
        Self {
            gain: n(),
            integral_gain: n(),
            field_time_constant: n(),
            ceiling: n(),
            floor: n(),
            v_ref_offset: n(),
            transient_gain_reduction: LeadLagRole::NotApplicable(reason.to_string()),
            supply_ceiling: n(),
            supply_floor: n(),
            commutation: n(),
            regulator_ceiling: n(),
            regulator_floor: n(),
        }
    }

    /// The single-parameter roles as `(role name, role)`, in [`PARAM_ROLE_NAMES`] order.
    pub fn params(&self) -> [(&'static str, &ParamRole); 11] {
        [
            ("gain", &self.gain),
            ("integral_gain", &self.integral_gain),
            ("field_time_constant", &self.field_time_constant),
            ("ceiling", &self.ceiling),
            ("floor", &self.floor),
            ("v_ref_offset", &self.v_ref_offset),
            ("supply_ceiling", &self.supply_ceiling),
            ("supply_floor", &self.supply_floor),
            ("commutation", &self.commutation),
            ("regulator_ceiling", &self.regulator_ceiling),
            ("regulator_floor", &self.regulator_floor),
        ]
    }

    fn param_mut(&mut self, role: &str) -> Option<&mut ParamRole> {
        Some(match role {
            "gain" => &mut self.gain,
            "integral_gain" => &mut self.integral_gain,
            "field_time_constant" => &mut self.field_time_constant,
            "ceiling" => &mut self.ceiling,
            "floor" => &mut self.floor,
            "v_ref_offset" => &mut self.v_ref_offset,
            "supply_ceiling" => &mut self.supply_ceiling,
            "supply_floor" => &mut self.supply_floor,
            "commutation" => &mut self.commutation,
            "regulator_ceiling" => &mut self.regulator_ceiling,
            "regulator_floor" => &mut self.regulator_floor,
            _ => return None,
        })
    }

    /// Every parameter named by a role is a parameter of `ps` (the check a model's unit test and
    /// a diagram's loader make). The error names the role and the parameter.
    pub fn check(&self, ps: &dyn ParamSet) -> Result<(), String> {
        check_roles(
            ps,
            &self.params(),
            &[(TGR_ROLE_NAME, &self.transient_gain_reduction)],
        )
    }

    /// The parameters a playback of Q identifies, the ones a default calibration frees: the
    /// gain (and a PI's integral gain), the field time constant and the transient gain
    /// reduction's lead-lag. The limits act only when reached and the offset is a nuisance: not
    /// freed by default.
    pub fn identifiable(&self) -> Vec<String> {
        let mut out: Vec<String> = [&self.gain, &self.integral_gain, &self.field_time_constant]
            .iter()
            .filter_map(|r| r.name().map(String::from))
            .collect();
        if let Some((a, b)) = self.transient_gain_reduction.names() {
            out.extend([a.to_string(), b.to_string()]);
        }
        out
    }

    /// Reads the `[exciter_roles]` table of a diagram definition: each key a role, its value the
    /// name of a declared parameter or `{ none = "reason" }`; `transient_gain_reduction` is
    /// `{ lead = "t_c", lag = "t_b" }` or `{ ratio = "ta_tb", lag = "t_b" }`. A role left out
    /// is not applicable ("not declared by the diagram"). `params` are the declared parameter
    /// names. The error is `(key, message)`.
    ///
    /// ```toml
    /// [exciter_roles]
    /// gain = "k"
    /// field_time_constant = "te"
    /// ceiling = "e_max"
    /// floor = "e_min"
    /// v_ref_offset = "v_ref_offset"
    /// transient_gain_reduction = { ratio = "ta_tb", lag = "tb" }
    /// supply_ceiling = { none = "constant limits" }
    /// ```
    pub fn from_toml(t: &toml::Table, params: &[String]) -> Result<Self, (String, String)> {
        let mut roles = ExciterRoles::none("not declared by the diagram");
        let known = |key: &str, v: &toml::Value| -> Result<String, (String, String)> {
            let s = v.as_str().ok_or_else(|| {
                (
                    key.to_string(),
                    "must be a parameter name (a string)".to_string(),
                )
            })?;
            if params.iter().any(|p| p == s) {
                Ok(s.to_string())
            } else {
                Err((
                    key.to_string(),
                    format!("'{s}' is not a declared parameter"),
                ))
            }
        };
        let none_reason =
            |key: &str, tab: &toml::Table| -> Result<Option<String>, (String, String)> {
                match tab.get("none") {
                    None => Ok(None),
                    Some(toml::Value::String(r)) if tab.len() == 1 => Ok(Some(r.clone())),
                    Some(_) => Err((
                        key.to_string(),
                        "{ none = \"reason\" } takes one string and nothing else".to_string(),
                    )),
                }
            };
        for (key, v) in t {
            let field = format!("exciter_roles.{key}");
            if key == TGR_ROLE_NAME {
                let tab = v.as_table().ok_or_else(|| {
                    (
                        field.clone(),
                        "must be { lead = .., lag = .. }, { ratio = .., lag = .. } or { none = \"reason\" }"
                            .to_string(),
                    )
                })?;
                if let Some(r) = none_reason(&field, tab)? {
                    roles.transient_gain_reduction = LeadLagRole::NotApplicable(r);
                    continue;
                }
                let get = |k: &str| tab.get(k).map(|v| known(&format!("{field}.{k}"), v));
                for k in tab.keys() {
                    if !["lead", "ratio", "lag"].contains(&k.as_str()) {
                        return Err((
                            format!("{field}.{k}"),
                            "unknown key (expected lead or ratio, and lag)".to_string(),
                        ));
                    }
                }
                let lag =
                    get("lag").ok_or_else(|| (field.clone(), "lag is missing".to_string()))??;
                roles.transient_gain_reduction = match (get("lead"), get("ratio")) {
                    (Some(lead), None) => LeadLagRole::LeadLag { lead: lead?, lag },
                    (None, Some(ratio)) => LeadLagRole::RatioLag { ratio: ratio?, lag },
                    _ => {
                        return Err((
                            field,
                            "give exactly one of lead (a time constant) and ratio (T_C/T_B)"
                                .to_string(),
                        ))
                    }
                };
                continue;
            }
            let role = match v {
                toml::Value::Table(tab) => match none_reason(&field, tab)? {
                    Some(r) => ParamRole::NotApplicable(r),
                    None => {
                        return Err((
                            field,
                            "must be a parameter name or { none = \"reason\" }".to_string(),
                        ))
                    }
                },
                v => ParamRole::Param(known(&field, v)?),
            };
            let slot = roles.param_mut(key).ok_or_else(|| {
                (
                    field.clone(),
                    format!(
                        "unknown role (expected {}, {TGR_ROLE_NAME})",
                        PARAM_ROLE_NAMES.join(", ")
                    ),
                )
            })?;
            *slot = role;
        }
        Ok(roles)
    }
}

/// Every parameter a role names is a parameter of `ps`; the error names the role (shared by
/// the exciter, governor and stabiliser roles).
pub fn check_roles(
    ps: &dyn ParamSet,
    params: &[(&str, &ParamRole)],
    lead_lags: &[(&str, &LeadLagRole)],
) -> Result<(), String> {
    let has = |n: &str| ps.specs().iter().any(|s| s.name == n);
    for (role, r) in params {
        if let Some(n) = r.name() {
            if !has(n) {
                return Err(format!("{role}: '{n}' is not a parameter"));
            }
        }
    }
    for (role, r) in lead_lags {
        if let Some((a, b)) = r.names() {
            for n in [a, b] {
                if !has(n) {
                    return Err(format!("{role}: '{n}' is not a parameter"));
                }
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(v: &[&str]) -> Vec<String> {
        v.iter().map(|s| s.to_string()).collect()
    }

    #[test]
    fn a_diagram_table_declares_roles_and_leaves_the_rest_not_applicable() {
        let t: toml::Table = toml::from_str(
            "gain = \"k\"\nceiling = \"e_max\"\nfloor = { none = \"no floor\" }\n\
             transient_gain_reduction = { ratio = \"ta_tb\", lag = \"tb\" }\n",
        )
        .unwrap();
        let r = ExciterRoles::from_toml(&t, &names(&["k", "e_max", "ta_tb", "tb"])).unwrap();
        assert_eq!(r.gain, ParamRole::param("k"));
        assert_eq!(r.ceiling.name(), Some("e_max"));
        assert_eq!(r.floor.reason(), Some("no floor"));
        assert_eq!(
            r.field_time_constant.reason(),
            Some("not declared by the diagram")
        );
        assert_eq!(r.transient_gain_reduction.names(), Some(("ta_tb", "tb")));
    }

    #[test]
    fn a_diagram_table_naming_an_unknown_parameter_or_role_is_refused() {
        let bad = |text: &str| {
            let t: toml::Table = toml::from_str(text).unwrap();
            ExciterRoles::from_toml(&t, &names(&["k", "tb"])).unwrap_err()
        };
        assert_eq!(bad("gain = \"ka\"").0, "exciter_roles.gain");
        assert!(bad("speed = \"k\"").1.contains("unknown role"));
        assert!(bad("transient_gain_reduction = { lead = \"k\" }")
            .1
            .contains("lag is missing"));
        assert!(
            bad("transient_gain_reduction = { lead = \"k\", ratio = \"k\", lag = \"tb\" }")
                .1
                .contains("exactly one")
        );
        assert!(bad("gain = { none = 3 }").1.contains("none"));
    }
}
