//! `measurement_skew`: the PMU's P and Q channels skewed in time against its voltage channel,
//! modelled by a fractional delay of P and Q.

use itaipu_dynamics::synthetic::EventKind;

use super::super::cause::{
    Cause, CauseError, CauseInfo, Extension, NotApplicable, Roles, Scenario, Tolerance,
};
use super::super::cause_kit::{add_block, fb, new_block, scanned};
use super::super::context::{Acts, Context};
use super::super::report::EventEvidence;
use super::signature;

pub struct MeasurementSkew;

static INFO: CauseInfo<'static> = CauseInfo {
    id: "measurement_skew",
    title: "power channels skewed against the voltage channel",
    signature:
        "P and Q residuals shaped like the time derivative of the response (largest where P and Q \
                change fastest), cross-correlated with the input at a lag",
    extension: "pmu_measurement block: a fractional delay of the P and Q channels",
    key_params: &["measurement.pq_delay_s"],
};

/// Smallest P/Q skew a diagnosis names, in sample intervals: the resolution a delay is scored
/// to. Between samples the playback only knows the voltage by interpolation, and the unit's
/// fastest responses (subtransient flux, the exciter) follow it within the sample interval, so a
/// delay of a fraction of a sample trades against those.
pub const SKEW_RESOLUTION_SAMPLES: f64 = 0.5;

impl Cause for MeasurementSkew {
    fn info(&self) -> CauseInfo<'_> {
        INFO
    }

    fn acts(&self) -> Acts {
        Acts::PowerMeasurement
    }

    fn extend(&self, x: &mut Extension, _roles: &Roles, ctx: &Context) -> Result<(), CauseError> {
        if x.unit.block("measurement").is_some() {
            return Err(NotApplicable::NameTaken {
                name: "measurement".into(),
            }
            .into());
        }
        add_block(
            &mut x.unit,
            "measurement",
            new_block("pmu_measurement", &[])?,
        )?;
        // The delay's range comes from the PMU rate (up to 3 samples; computed here).
        let rate = ctx.rate_hz.max(1.0);
        x.extension_free = vec![scanned(
            fb("measurement.pq_delay_s", 0.0, 3.0 / rate, 0.5 / rate)?,
            13,
        )];
        x.from_datasheet = true;
        Ok(())
    }

    fn signature(&self, ev: &[EventEvidence], _ctx: &Context) -> Vec<String> {
        signature::correlates_with(ev, "|V|", None)
    }

    fn below_resolution(&self, fitted: &[(String, f64)], ctx: &Context) -> Option<String> {
        let tau = fitted
            .iter()
            .find(|(p, _)| p == "measurement.pq_delay_s")?
            .1;
        let samples = tau * ctx.rate_hz;
        (samples < SKEW_RESOLUTION_SAMPLES).then(|| {
            format!(
                "the fitted delay ({:.1} ms, {samples:.2} sample intervals) is below half a sample \
                 interval, which the playback's own timing between samples can account for",
                1e3 * tau
            )
        })
    }

    fn scenario(&self, spread: &dyn Fn(u64) -> f64) -> Option<Scenario> {
        Some(Scenario {
            values: vec![("measurement.pq_delay_s", 0.012 + 0.006 * spread(1))],
            key: Some(("measurement.pq_delay_s", Tolerance::Abs(0.5 / 60.0))),
            kind: EventKind::FaultDip,
        })
    }
}
