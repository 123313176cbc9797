//! Stabiliser roles: which parameter of a PSS model plays each part that code above the model
//! reasons about (the gain, the washout, the phase-compensation lead-lags, the output limits),
//! declared by the model ([`Block::pss_roles`]). The same [`ParamRole`]/[`LeadLagRole`] as the
//! exciter roles ([`crate::models::exciter::roles`]).
//!
//! | role | meaning |
//! |---|---|
//! | `gain` | the stabiliser gain: IEEEST `KS`, PSS2A `KS1`, STAB3 `K_X` |
//! | `washout` | the (first) washout time constant: IEEEST `T6`, PSS2A `TW1`, STAB3 `T_X2` |
//! | `lead_lag_1`, `lead_lag_2` | the phase-compensation lead-lags `(1 + sT1)/(1 + sT2)`, `(1 + sT3)/(1 + sT4)` |
//! | `input_filter` | the input transducer or low-pass time constant: STAB3 `T_X1`, PSS2A `T6` |
//! | `output_max`, `output_min` | the output limits (a symmetric limit plays both) |
//!
//! [`Block::pss_roles`]: crate::block::Block::pss_roles

use crate::models::exciter::roles::{check_roles, LeadLagRole, ParamRole};
use crate::params::ParamSet;

/// Which parameter of a stabiliser plays each role (see the module documentation).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PssRoles {
    pub gain: ParamRole,
    pub washout: ParamRole,
    pub lead_lag_1: LeadLagRole,
    pub lead_lag_2: LeadLagRole,
    pub input_filter: ParamRole,
    pub output_max: ParamRole,
    pub output_min: ParamRole,
}

impl PssRoles {
    /// Every role not applicable, each with `reason`; set the fields that apply.
    pub fn none(reason: &str) -> Self {
        let n = || ParamRole::none(reason);
        let ll = || LeadLagRole::NotApplicable(reason.to_string());
        Self {
            gain: n(),
            washout: n(),
            lead_lag_1: ll(),
            lead_lag_2: ll(),
            input_filter: n(),
            output_max: n(),
            output_min: n(),
        }
    }

    /// The single-parameter roles as `(role name, role)`.
    pub fn params(&self) -> [(&'static str, &ParamRole); 5] {
        [
            ("gain", &self.gain),
            ("washout", &self.washout),
            ("input_filter", &self.input_filter),
            ("output_max", &self.output_max),
            ("output_min", &self.output_min),
        ]
    }

    /// The lead-lag roles as `(role name, role)`.
    pub fn lead_lags(&self) -> [(&'static str, &LeadLagRole); 2] {
        [
            ("lead_lag_1", &self.lead_lag_1),
            ("lead_lag_2", &self.lead_lag_2),
        ]
    }

    /// The parameters a playback of Q identifies, the ones a default calibration frees: the
    /// gain, the washout and the lead-lags' time constants (the phase compensation). The output
    /// limits act only when reached: not freed by default.
    pub fn identifiable(&self) -> Vec<String> {
        let mut out: Vec<String> = [&self.gain, &self.washout, &self.input_filter]
            .iter()
            .filter_map(|r| r.name().map(String::from))
            .collect();
        for ll in [&self.lead_lag_1, &self.lead_lag_2] {
            if let Some((a, b)) = ll.names() {
                out.extend([a.to_string(), b.to_string()]);
            }
        }
        out
    }

    /// Every parameter named by a role is a parameter of `ps` (the error names the role).
    pub fn check(&self, ps: &dyn ParamSet) -> Result<(), String> {
        check_roles(ps, &self.params(), &self.lead_lags())
    }
}
