//! PMU measurement effects (`models.md` §12.5), applied to the simulated terminal P and Q
//! before they are compared with the recording.
//!
//! ```text
//! time skew:        P'(t) = P(t − τ),  Q'(t) = Q(t − τ)            (band-limited interpolation)
//! VT/CT phase error φ:  P'' = P' cos φ + Q' sin φ,   Q'' = Q' cos φ − P' sin φ
//! ratio errors:     P_meas = k_P · P'',   Q_meas = k_Q · Q''
//! ```
//!
//! The fractional part of τ is interpolated by [`crate::synthetic::delayed`]: a windowed sinc
//! that keeps the variance of the noise the simulated P and Q take from the measured voltage
//! (`models.md` §12.5 says "interpolated"; linear interpolation smooths that noise most at half a
//! sample, and a delay fit then rewarded the smoothing, not the skew).
//!
//! τ > 0 means the power channels lag the voltage channel. The block has no states and no
//! ports: it acts on the recorded P and Q series through [`Block::transform_pq`]. With its
//! defaults (τ = 0, φ = 0, k = 1) it changes nothing. Put it in a unit as
//! `[[block]] name = "measurement"  model = "pmu_measurement"`; its parameters are then fitted
//! like any other (`measurement.pq_delay_s`). Ratio errors correlate strongly with H, D and the
//! AVR gains when left free (§12.5).

use crate::block::{guard, Block, InitPoint, Io, ModelError, Port};
use crate::sens::{Scalar, D};
use crate::{block_common, param_set};
use crate::registry::{ModelInfo, Role};

/// The registry entry ([`crate::registry`]): name, role, `.dyr` record.
pub const MODEL: ModelInfo = ModelInfo {
    name: "pmu_measurement",
    role: Role::Other,
    summary: "PMU effects on the recorded P and Q: channel skew, VT/CT phase error, ratio errors",
    reference: "models.md §12.5",
    make: || Box::new(PmuMeasurement::default()),
    dyr: None,
};

param_set! {
    /// PMU measurement-effect parameters.
    pub struct PmuMeasurementParams {
        pq_delay_s: ("tau", "s", 0.0, (0.0, 0.05), "delay of the P and Q channels behind the voltage channel"),
        phase_deg: ("phi", "deg", 0.0, (-1.0, 1.0), "phase error between the current and voltage transformers"),
        p_ratio: ("kP", "-", 1.0, (0.99, 1.01), "ratio (magnitude) factor of the P channel"),
        q_ratio: ("kQ", "-", 1.0, (0.99, 1.01), "ratio (magnitude) factor of the Q channel"),
    }
}

/// PMU measurement-effect block.
#[derive(Debug, Clone, Default)]
pub struct PmuMeasurement {
    pub p: PmuMeasurementParams,
    /// The parameters on dual numbers, after [`Block::seed_dual`].
    dual: Option<PmuMeasurementParams<D>>,
}

/// The phase and ratio errors on a (delayed) series.
fn rotate_scale<S: Scalar>(pp: &PmuMeasurementParams<S>, p: &mut [S], q: &mut [S]) {
    let (s, c) = (pp.phase_deg * (std::f64::consts::PI / 180.0)).sin_cos();
    for (pk, qk) in p.iter_mut().zip(q.iter_mut()) {
        let (p0, q0) = (*pk, *qk);
        *pk = pp.p_ratio * (p0 * c + q0 * s);
        *qk = pp.q_ratio * (q0 * c - p0 * s);
    }
}

impl Block for PmuMeasurement {
    block_common!();

    fn model(&self) -> &'static str {
        "pmu_measurement"
    }
    fn ports(&self) -> &'static [Port] {
        &[]
    }
    fn state_names(&self) -> &'static [&'static str] {
        &[]
    }
    fn validate(&self) -> Result<(), ModelError> {
        guard::non_negative("pq_delay_s", self.p.pq_delay_s)?;
        guard::finite("phase_deg", self.p.phase_deg)?;
        guard::positive("p_ratio", self.p.p_ratio)?;
        guard::positive("q_ratio", self.p.q_ratio)
    }
    fn init(&mut self, _op: &InitPoint, _x: &mut [f64], _io: &mut Io) -> Result<(), ModelError> {
        self.validate()
    }
    fn outputs(&self, _t: f64, _x: &[f64], _io: &mut Io) {}
    fn derivatives(&self, _t: f64, _x: &[f64], _io: &Io, _dx: &mut [f64]) {}

    fn transforms_pq(&self) -> bool {
        true
    }

    fn transform_pq(&self, t: &[f64], p: &mut [f64], q: &mut [f64]) {
        let pp = &self.p;
        if pp.pq_delay_s > 0.0 {
            let dp = crate::synthetic::delayed(t, p, pp.pq_delay_s);
            let dq = crate::synthetic::delayed(t, q, pp.pq_delay_s);
            p.copy_from_slice(&dp);
            q.copy_from_slice(&dq);
        }
        rotate_scale(pp, p, q);
    }
    fn seed_dual(&mut self, lanes: &[Option<usize>], _consts: &[D]) -> bool {
        self.dual = Some(self.p.lift_dual(lanes));
        true
    }
    fn transform_pq_dual(&self, t: &[f64], p: &mut [D], q: &mut [D]) {
        let Some(pp) = &self.dual else { return };
        let tau = pp.pq_delay_s;
        if tau.v > 0.0 || tau.d.iter().any(|&d| d != 0.0) {
            let dp = crate::synthetic::delayed_dual(t, p, tau);
            let dq = crate::synthetic::delayed_dual(t, q, tau);
            p.copy_from_slice(&dp);
            q.copy_from_slice(&dq);
        }
        rotate_scale(pp, p, q);
    }
}
