//! Governor roles: which parameter of a turbine-governor model plays each part that code above
//! the model reasons about (the droop, the servo and turbine time constants, the output and
//! rate limits, …), declared by the model itself ([`Block::governor_roles`]) so that the
//! calibrator's default spec and the diagnosis need no model's parameter names. The same idea
//! and the same [`ParamRole`]/[`LeadLagRole`] as the exciter roles
//! ([`crate::models::exciter::roles`]).
//!
//! | role | meaning |
//! |---|---|
//! | `droop` | permanent droop R [pu speed / pu power]: HYGOV `R`, TGOV1 `R`, GAST `R`, TG2 `R` |
//! | `speed_gain` | the same expressed as a gain K = 1/R: IEEEG1 `K` |
//! | `transient_droop`, `reset_time_constant` | a dashpot (temporary droop r, reset T_r): HYGOV |
//! | `governor_lead_lag` | a lead-lag on the speed signal: IEEEG1 `(1 + sT2)/(1 + sT1)`, TG2 `(1 + sT1)/(1 + sT2)` |
//! | `servo_time_constant` | the gate or valve servo: HYGOV `T_g`, TGOV1 `T1`, IEEEG1 `T3`, GAST `T1` (fuel valve) |
//! | `turbine_time_constant` | the prime mover's main lag: HYGOV `T_w`, IEEEG1 `T4` (steam chest), GAST `T2` |
//! | `reheat_time_constant` | the reheater's lag: TGOV1 `T3`, IEEEG1 `T5` |
//! | `reheat_lead` | the lead of a reheater lead-lag (the high-pressure fraction times T_RH): TGOV1 `T2` |
//! | `output_max`, `output_min` | the gate, valve or power limits |
//! | `rate_max`, `rate_min` | the opening and closing rate limits (a symmetric limit plays both) |
//! | `damping` | turbine damping on Δω |
//! | `reference_offset` | the set-point offset nuisance parameter added after initialisation |
//!
//! [`Block::governor_roles`]: crate::block::Block::governor_roles

use crate::models::exciter::roles::{check_roles, LeadLagRole, ParamRole};
use crate::params::ParamSet;

/// Which parameter of a governor plays each role (see the module documentation).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct GovernorRoles {
    pub droop: ParamRole,
    pub speed_gain: ParamRole,
    pub transient_droop: ParamRole,
    pub reset_time_constant: ParamRole,
    pub governor_lead_lag: LeadLagRole,
    pub servo_time_constant: ParamRole,
    pub turbine_time_constant: ParamRole,
    pub reheat_time_constant: ParamRole,
    pub reheat_lead: ParamRole,
    pub output_max: ParamRole,
    pub output_min: ParamRole,
    pub rate_max: ParamRole,
    pub rate_min: ParamRole,
    pub damping: ParamRole,
    pub reference_offset: ParamRole,
}

impl GovernorRoles {
    /// Every role not applicable, each with `reason`; set the fields that apply.
    pub fn none(reason: &str) -> Self {
        let n = || ParamRole::none(reason);
        let ll = || LeadLagRole::NotApplicable(reason.to_string());
        Self {
            droop: n(),
            speed_gain: n(),
            transient_droop: n(),
            reset_time_constant: n(),
            governor_lead_lag: ll(),
            servo_time_constant: n(),
            turbine_time_constant: n(),
            reheat_time_constant: n(),
            reheat_lead: n(),
            output_max: n(),
            output_min: n(),
            rate_max: n(),
            rate_min: n(),
            damping: n(),
            reference_offset: n(),
        }
    }

    /// The single-parameter roles as `(role name, role)`.
    pub fn params(&self) -> [(&'static str, &ParamRole); 14] {
        [
            ("droop", &self.droop),
            ("speed_gain", &self.speed_gain),
            ("transient_droop", &self.transient_droop),
            ("reset_time_constant", &self.reset_time_constant),
            ("servo_time_constant", &self.servo_time_constant),
            ("turbine_time_constant", &self.turbine_time_constant),
            ("reheat_time_constant", &self.reheat_time_constant),
            ("reheat_lead", &self.reheat_lead),
            ("output_max", &self.output_max),
            ("output_min", &self.output_min),
            ("rate_max", &self.rate_max),
            ("rate_min", &self.rate_min),
            ("damping", &self.damping),
            ("reference_offset", &self.reference_offset),
        ]
    }

    /// The lead-lag roles as `(role name, role)`.
    pub fn lead_lags(&self) -> [(&'static str, &LeadLagRole); 1] {
        [("governor_lead_lag", &self.governor_lead_lag)]
    }

    /// The parameters a playback of P identifies on a frequency excursion, the ones a default
    /// calibration frees: the droop (or its gain), the dashpot, the servo, turbine and reheat
    /// time constants and the governor lead-lag. The limits and rate limits act only when
    /// reached, and the damping and offset are nuisances: not freed by default.
    pub fn identifiable(&self) -> Vec<String> {
        let mut out: Vec<String> = [
            &self.droop,
            &self.speed_gain,
            &self.transient_droop,
            &self.reset_time_constant,
            &self.servo_time_constant,
            &self.turbine_time_constant,
            &self.reheat_time_constant,
            &self.reheat_lead,
        ]
        .iter()
        .filter_map(|r| r.name().map(String::from))
        .collect();
        if let Some((a, b)) = self.governor_lead_lag.names() {
            out.extend([a.to_string(), b.to_string()]);
        }
        out
    }

    /// Every parameter named by a role is a parameter of `ps` (the error names the role).
    pub fn check(&self, ps: &dyn ParamSet) -> Result<(), String> {
        check_roles(ps, &self.params(), &self.lead_lags())
    }
}
