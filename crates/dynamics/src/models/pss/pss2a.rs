//! PSS2A: IEEE 421.5-2005 dual-input stabiliser (IEEE 1992 PSS2A), as PSS/E's `PSS2A`
//! (`models.md` §9.2.4). ANDES has no PSS2A; the independent check is the same model written
//! from diagram primitives (`data/diagrams/pss2a.toml`, `tests/pss2a_diagram.rs`).
//!
//! States: washouts `x_w1`, `x_w2` (input 1), `x_w3`, `x_w4` (input 2), lags `x_t6`, `x_t7`, the
//! phase-compensation lead-lags `x_ll1`, `x_ll2`, then the ramp-tracking filter's M·N states.
//!
//! ```text
//! y1 = [sT_W1/(1 + sT_W1)] [sT_W2/(1 + sT_W2)] [1/(1 + sT6)] V_S1                 (V_S1: input u1, default speed)
//! y2 = [sT_W3/(1 + sT_W3)] [sT_W4/(1 + sT_W4)] [K_S2/(1 + sT7)] V_S2              (V_S2: input u2, default P_e)
//! r  = RTF(s) (y1 + K_S3 y2) − y2,        RTF(s) = [(1 + sT8)/(1 + sT9)^M]^N     (ramp-tracking filter)
//! V_S = clamp(K_S1 (1 + sT1)/(1 + sT2) · (1 + sT3)/(1 + sT4) · r, V_STMIN, V_STMAX)
//! ```
//!
//! All signals in pu (speed deviation, power on the machine base), times in s. A washout with
//! T_W = 0 is bypassed (passes its input), a lag or lead-lag with a zero lag time constant is
//! bypassed (PSS/E's conventions); T9 = 0, M = 0 or N = 0 bypass the ramp-tracking filter. The
//! options `m` and `n` are PSS/E's ICONs M and N (1 ≤ M·N ≤ 8), the inputs' signals its input
//! codes ICS1 and ICS2 (read from and written to `.dyr` as the ports' wiring).
//!
//! **Limits.** The output limit is a clamp on V_S (no state is limited).
//!
//! **Departure.** The ramp-tracking filter is IEEE 421.5's `[(1 + sT8)/(1 + sT9)^M]^N` as PSS/E
//! documents it: N sections of one lead-lag and M − 1 lags. OpenIPSL's `RampTrackingFilter`
//! chains N lead-lags and M extra lags (`(1 + sT8)^N/(1 + sT9)^(N+M)`), one lag more for N = 1,
//! on purpose (to reproduce PSS/E v33 responses, `models.md` §11.10).
//!
//! **Initialisation** (exact): every state equals its block's input in steady state (washouts
//! then output 0, unless bypassed); `V_S0` follows from the inputs (0 when each path has a
//! washout) and the exciter's reference absorbs it.

use crate::block::{guard, Block, InitPoint, Io, ModelError, Port, PortInit};
use crate::dyr::{DyrRecord, Icon, STABILISER_INPUTS};
use crate::models::exciter::blocks::{Lag, LeadLag, Washout};
use crate::models::exciter::roles::{LeadLagRole, ParamRole};
use crate::models::limiter::clamp;
use crate::models::pss::roles::PssRoles;
use crate::registry::{ModelInfo, Role};
use crate::sens::{Scalar, D};
use crate::{block_common, param_set};

/// The registry entry ([`crate::registry`]): name, role, `.dyr` record (PSS/E's ICON and CON
/// order: the input codes and remote buses, then M and N).
pub const MODEL: ModelInfo = ModelInfo {
    name: "PSS2A",
    role: Role::Pss,
    summary: "IEEE dual-input stabiliser (speed and power): washouts, ramp-tracking filter, two lead-lags",
    reference: "IEEE 421.5-2005 PSS2A as PSS/E's PSS2A (models.md §9.2.4); output clamped",
    make: || Box::new(Pss2a::default()),
    dyr: Some(DyrRecord {
        icons: &[
            Icon::Input {
                name: "ICS1",
                port: "u1",
                codes: STABILISER_INPUTS,
            },
            Icon::Zero {
                name: "REMBUS1",
                meaning: "remote bus",
            },
            Icon::Input {
                name: "ICS2",
                port: "u2",
                codes: STABILISER_INPUTS,
            },
            Icon::Zero {
                name: "REMBUS2",
                meaning: "remote bus",
            },
            Icon::Option {
                name: "M",
                key: "m",
                default: "5",
            },
            Icon::Option {
                name: "N",
                key: "n",
                default: "1",
            },
        ],
        cons: &[
            "tw1", "tw2", "t6", "tw3", "tw4", "t7", "ks2", "ks3", "t8", "t9", "ks1", "t1", "t2",
            "t3", "t4", "vst_max", "vst_min",
        ],
        machine: None,
    }),
};

param_set! {
    /// PSS2A parameters (PSS/E CON order). Typical values: IEEE 421.5-2005 sample data
    /// (Annex H, PSS2A; K_S2 = T7/(2H)).
    pub struct Pss2aParams {
        tw1: ("TW1", "s", 10.0, (1.0, 20.0), "first washout time constant of input 1 T_W1"),
        tw2: ("TW2", "s", 10.0, (0.0, 20.0), "second washout time constant of input 1 T_W2 (0: bypassed)"),
        t6: ("T6", "s", 0.0, (0.0, 2.0), "input 1 transducer time constant T6"),
        tw3: ("TW3", "s", 10.0, (1.0, 20.0), "first washout time constant of input 2 T_W3"),
        tw4: ("TW4", "s", 0.0, (0.0, 20.0), "second washout time constant of input 2 T_W4 (0: bypassed)"),
        t7: ("T7", "s", 10.0, (1.0, 20.0), "input 2 integrator time constant T7"),
        ks2: ("KS2", "pu", 1.13, (0.1, 5.0), "input 2 gain K_S2 (T7/2H)"),
        ks3: ("KS3", "pu", 1.0, (0.5, 2.0), "input 2 gain into the ramp-tracking filter K_S3"),
        t8: ("T8", "s", 0.3, (0.0, 1.0), "ramp-tracking filter lead time constant T8"),
        t9: ("T9", "s", 0.15, (0.02, 1.0), "ramp-tracking filter lag time constant T9"),
        ks1: ("KS1", "pu", 20.0, (1.0, 50.0), "stabiliser gain K_S1"),
        t1: ("T1", "s", 0.16, (0.0, 1.0), "first lead time constant T1"),
        t2: ("T2", "s", 0.02, (0.01, 1.0), "first lag time constant T2"),
        t3: ("T3", "s", 0.16, (0.0, 1.0), "second lead time constant T3"),
        t4: ("T4", "s", 0.02, (0.01, 1.0), "second lag time constant T4"),
        vst_max: ("VSTMAX", "pu", 0.2, (0.05, 0.3), "maximum output V_STMAX"),
        vst_min: ("VSTMIN", "pu", -0.066, (-0.3, -0.02), "minimum output V_STMIN"),
    }
}

mod port {
    pub const U1: usize = 0;
    pub const U2: usize = 1;
    pub const VS: usize = 2;
}

const PORTS: &[Port] = &[
    Port::input_ft(
        "u1",
        PortInit::Needs,
        "first input V_S1 (default: speed deviation Δω) [pu]",
    )
    .wired("speed"),
    Port::input_ft(
        "u2",
        PortInit::Needs,
        "second input V_S2 (default: electrical power P_e on the machine base) [pu]",
    )
    .wired("pe"),
    Port::output("vs", PortInit::Gives, "stabiliser output V_S [pu]"),
];

/// Largest M·N (PSS/E's limit on the ramp-tracking filter's order).
pub const MAX_RTF_ORDER: usize = 8;

/// State names: the eight fixed states, then the ramp-tracking filter's (the first M·N used).
static STATE_NAMES: [&str; 8 + MAX_RTF_ORDER] = [
    "x_w1", "x_w2", "x_t6", "x_w3", "x_w4", "x_t7", "x_ll1", "x_ll2", "x_rtf1", "x_rtf2",
    "x_rtf3", "x_rtf4", "x_rtf5", "x_rtf6", "x_rtf7", "x_rtf8",
];
const RTF: usize = 8;

/// The linear blocks, from the parameters (on the number type `S`).
#[derive(Debug, Clone, Copy, Default)]
struct Blocks<S = f64> {
    w: [Washout<S>; 4],
    t6: Lag<S>,
    t7: Lag<S>,
    ll1: LeadLag<S>,
    ll2: LeadLag<S>,
    rtf_lead: LeadLag<S>,
    rtf_lag: Lag<S>,
}

impl<S: Scalar> Blocks<S> {
    fn new(p: &Pss2aParams<S>) -> Self {
        Self {
            w: [
                Washout::new(p.tw1),
                Washout::new(p.tw2),
                Washout::new(p.tw3),
                Washout::new(p.tw4),
            ],
            t6: Lag::new(p.t6),
            t7: Lag::new(p.t7),
            ll1: LeadLag::new(p.t1, p.t2),
            ll2: LeadLag::new(p.t3, p.t4),
            rtf_lead: LeadLag::new(p.t8, p.t9),
            rtf_lag: Lag::new(p.t9),
        }
    }
}

/// A PSS2A block. See the module documentation.
#[derive(Debug, Clone)]
pub struct Pss2a {
    pub p: Pss2aParams,
    /// PSS/E's ICONs M and N (ramp-tracking filter order).
    m: usize,
    n: usize,
    b: Blocks,
    /// The parameters and blocks on dual numbers, after [`Block::seed_dual`].
    dual: Option<(Pss2aParams<D>, Blocks<D>)>,
}

impl Default for Pss2a {
    fn default() -> Self {
        Self::new(Pss2aParams::default())
    }
}

impl Pss2a {
    pub fn new(p: Pss2aParams) -> Self {
        Self {
            p,
            m: 5,
            n: 1,
            b: Blocks::default(),
            dual: None,
        }
    }

    /// The ramp-tracking filter's order M·N (0 when bypassed by M or N).
    fn rtf_order(&self) -> usize {
        self.m * self.n
    }
}

/// One pass through the diagram: the output V_S, and each state's input into `u` (its
/// derivative is `(u − x)/T`, or its steady state `x = u`).
#[inline(always)]
fn chain<S: Scalar>(
    p: &Pss2aParams<S>,
    b: &Blocks<S>,
    (m, n): (usize, usize),
    x: &[S],
    (u1, u2): (S, S),
    u: &mut [S],
) -> S {
    u[0] = u1;
    let w1 = b.w[0].output(x[0], u1);
    u[1] = w1;
    let w2 = b.w[1].output(x[1], w1);
    u[2] = w2;
    let y1 = b.t6.output(x[2], w2);
    u[3] = u2;
    let w3 = b.w[2].output(x[3], u2);
    u[4] = w3;
    let w4 = b.w[3].output(x[4], w3);
    u[5] = w4;
    let y2 = b.t7.output(x[5], w4) * p.ks2;
    let mut r = y1 + p.ks3 * y2;
    for section in 0..n {
        for stage in 0..m {
            let k = RTF + section * m + stage;
            u[k] = r;
            r = if stage == 0 {
                b.rtf_lead.output(x[k], r)
            } else {
                b.rtf_lag.output(x[k], r)
            };
        }
    }
    let v = (r - y2) * p.ks1;
    u[6] = v;
    let z1 = b.ll1.output(x[6], v);
    u[7] = z1;
    let z2 = b.ll2.output(x[7], z1);
    clamp(z2, p.vst_min, p.vst_max)
}

/// The state derivatives from the states and their inputs.
#[inline(always)]
fn derivatives<S: Scalar>(
    p: &Pss2aParams<S>,
    b: &Blocks<S>,
    mn: (usize, usize),
    x: &[S],
    io: &Io<S>,
    dx: &mut [S],
) {
    let mut u = [S::cst(0.0); 8 + MAX_RTF_ORDER];
    chain(p, b, mn, x, (io.get(port::U1), io.get(port::U2)), &mut u);
    dx[0] = b.w[0].derivative(x[0], u[0]);
    dx[1] = b.w[1].derivative(x[1], u[1]);
    dx[2] = b.t6.derivative(x[2], u[2]);
    dx[3] = b.w[2].derivative(x[3], u[3]);
    dx[4] = b.w[3].derivative(x[4], u[4]);
    dx[5] = b.t7.derivative(x[5], u[5]);
    dx[6] = b.ll1.derivative(x[6], u[6]);
    dx[7] = b.ll2.derivative(x[7], u[7]);
    let (m, n) = mn;
    for k in RTF..RTF + m * n {
        dx[k] = if (k - RTF).is_multiple_of(m) {
            b.rtf_lead.derivative(x[k], u[k])
        } else {
            b.rtf_lag.derivative(x[k], u[k])
        };
    }
}

impl Block for Pss2a {
    block_common!();

    fn model(&self) -> &'static str {
        MODEL.name
    }
    fn ports(&self) -> &'static [Port] {
        PORTS
    }
    fn state_names(&self) -> &'static [&'static str] {
        &STATE_NAMES[..RTF + self.rtf_order()]
    }
    fn validate(&self) -> Result<(), ModelError> {
        let p = &self.p;
        for (n, v) in [
            ("tw1", p.tw1),
            ("tw2", p.tw2),
            ("t6", p.t6),
            ("tw3", p.tw3),
            ("tw4", p.tw4),
            ("t7", p.t7),
            ("t8", p.t8),
            ("t9", p.t9),
            ("t1", p.t1),
            ("t2", p.t2),
            ("t3", p.t3),
            ("t4", p.t4),
        ] {
            guard::non_negative(n, v)?;
        }
        for (n, v) in [("ks1", p.ks1), ("ks2", p.ks2), ("ks3", p.ks3)] {
            guard::finite(n, v)?;
        }
        guard::greater("vst_max", p.vst_max, "vst_min", p.vst_min)
    }

    fn init(&mut self, _op: &InitPoint, x: &mut [f64], io: &mut Io) -> Result<(), ModelError> {
        self.validate()?;
        self.b = Blocks::new(&self.p);
        let mn = (self.m, self.n);
        let (u1, u2) = (io.get(port::U1), io.get(port::U2));
        // States equal their inputs in steady state: one pass per block, in the chain's order,
        // each pass fixing the next state (at most 8 + M·N passes; the chain is acyclic).
        let nx = x.len();
        x.fill(0.0);
        let mut u = [0.0; 8 + MAX_RTF_ORDER];
        for _ in 0..nx {
            chain(&self.p, &self.b, mn, x, (u1, u2), &mut u);
            if x.iter().zip(&u).all(|(a, b)| a == b) {
                break;
            }
            x.copy_from_slice(&u[..nx]);
        }
        let vs0 = chain(&self.p, &self.b, mn, x, (u1, u2), &mut u);
        io.set(port::VS, vs0);
        Ok(())
    }

    #[inline]
    fn outputs(&self, _t: f64, x: &[f64], io: &mut Io) {
        let mut u = [0.0; 8 + MAX_RTF_ORDER];
        let vs = chain(
            &self.p,
            &self.b,
            (self.m, self.n),
            x,
            (io.get(port::U1), io.get(port::U2)),
            &mut u,
        );
        io.set(port::VS, vs);
    }

    #[inline]
    fn derivatives(&self, _t: f64, x: &[f64], io: &Io, dx: &mut [f64]) {
        derivatives(&self.p, &self.b, (self.m, self.n), x, io, dx);
    }

    fn seed_dual(&mut self, lanes: &[Option<usize>], _consts: &[D]) -> bool {
        let p = self.p.lift_dual(lanes);
        let b = Blocks::new(&p);
        self.dual = Some((p, b));
        true
    }

    fn outputs_dual(&self, _t: f64, x: &[D], io: &mut Io<D>) {
        if let Some((p, b)) = &self.dual {
            let mut u = [D::cst(0.0); 8 + MAX_RTF_ORDER];
            let inputs = (io.get(port::U1), io.get(port::U2));
            let vs = chain(p, b, (self.m, self.n), x, inputs, &mut u);
            io.set(port::VS, vs);
        }
    }

    fn derivatives_dual(&self, _t: f64, x: &[D], io: &Io<D>, dx: &mut [D]) {
        if let Some((p, b)) = &self.dual {
            derivatives(p, b, (self.m, self.n), x, io, dx);
        }
    }

    fn set_option(&mut self, key: &str, value: &str) -> Result<(), ModelError> {
        let order = |v: &str| -> Result<usize, ModelError> {
            v.parse::<usize>().map_err(|_| {
                ModelError::param(
                    key,
                    format!("'{v}': PSS/E's {} is a whole number 0 to 8", key.to_uppercase()),
                )
            })
        };
        let (m, n) = match key {
            "m" => (order(value)?, self.n),
            "n" => (self.m, order(value)?),
            _ => {
                return Err(ModelError::param(
                    key,
                    "unknown option (PSS2A options: m, n, the ramp-tracking filter's orders)",
                ))
            }
        };
        if m * n > MAX_RTF_ORDER {
            return Err(ModelError::param(
                key,
                format!("M·N = {m}·{n} = {} exceeds {MAX_RTF_ORDER} (PSS/E's limit on the ramp-tracking filter)", m * n),
            ));
        }
        self.m = m;
        self.n = n;
        Ok(())
    }
    fn options(&self) -> Vec<(&'static str, String)> {
        vec![("m", self.m.to_string()), ("n", self.n.to_string())]
    }

    fn pss_roles(&self) -> Option<PssRoles> {
        let mut r = PssRoles::none("not applicable to PSS2A");
        r.gain = ParamRole::param("ks1");
        r.washout = ParamRole::param("tw1");
        r.lead_lag_1 = LeadLagRole::LeadLag {
            lead: "t1".into(),
            lag: "t2".into(),
        };
        r.lead_lag_2 = LeadLagRole::LeadLag {
            lead: "t3".into(),
            lag: "t4".into(),
        };
        r.input_filter = ParamRole::none("PSS2A's input transducers (T6, T7) are usually fixed by design");
        r.output_max = ParamRole::param("vst_max");
        r.output_min = ParamRole::param("vst_min");
        Some(r)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn init_at(b: &mut Pss2a, u1: f64, u2: f64) -> (Vec<f64>, [f64; 3]) {
        let mut bus = [u1, u2, f64::NAN];
        let map = [0, 1, 2];
        let mut x = vec![0.0; b.state_names().len()];
        let op = InitPoint {
            v_mag: 1.0,
            v_ang: 0.0,
            p: u2,
            q: 0.0,
            speed_dev: u1,
        };
        b.init(&op, &mut x, &mut Io::new(&mut bus, &map)).unwrap();
        (x, bus)
    }

    #[test]
    fn starts_in_steady_state_with_zero_output_and_with_bypassed_washouts() {
        let mut b = Pss2a::default();
        let (x, mut bus) = init_at(&mut b, 0.001, 0.8);
        assert_eq!(bus[2], 0.0);
        let mut dx = vec![1.0; x.len()];
        b.derivatives(0.0, &x, &Io::new(&mut bus, &[0, 1, 2]), &mut dx);
        assert!(dx.iter().all(|d| d.abs() < 1e-15), "{dx:?}");
        // Both washouts of input 2 bypassed and K_S3 ≠ 1: P_e's level passes to V_S (the
        // filter's path and the direct one no longer cancel), still steady.
        let mut b = Pss2a::new(Pss2aParams {
            tw3: 0.0,
            tw4: 0.0,
            ks3: 0.9,
            ..Default::default()
        });
        b.set_option("m", "4").unwrap();
        b.set_option("n", "2").unwrap();
        let (x, mut bus) = init_at(&mut b, 0.0, 0.8);
        assert_eq!(x.len(), 16);
        assert!(bus[2] != 0.0);
        let mut dx = vec![1.0; x.len()];
        b.derivatives(0.0, &x, &Io::new(&mut bus, &[0, 1, 2]), &mut dx);
        assert!(dx.iter().all(|d| d.abs() < 1e-14), "{dx:?}");
    }

    #[test]
    fn the_filter_orders_are_pss_e_s_icons() {
        let mut b = Pss2a::default();
        assert_eq!(
            b.options(),
            vec![("m", "5".to_string()), ("n", "1".to_string())]
        );
        assert_eq!(b.state_names().len(), 13);
        assert!(b.set_option("m", "5").is_ok());
        assert!(b.set_option("n", "2").unwrap_err().to_string().contains("exceeds 8"));
        assert!(b.set_option("m", "x").is_err());
        b.set_option("n", "0").unwrap();
        assert_eq!(b.state_names().len(), 8);
    }

    #[test]
    fn roles_name_pss2a_parameters() {
        let b = Pss2a::default();
        let r = b.pss_roles().unwrap();
        r.check(b.params()).unwrap();
        assert_eq!(r.identifiable(), vec!["ks1", "tw1", "t1", "t2", "t3", "t4"]);
    }
}
