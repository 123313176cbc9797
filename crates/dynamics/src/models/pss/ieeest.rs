//! IEEEST: IEEE 1981 stabiliser (`models.md` §9.2.3; OpenIPSL `PSS/IEEEST.mo`, ANDES `ieeest.py`).
//!
//! ```text
//! F(s) = (1 + A5 s + A6 s²) / [(1 + A1 s + A2 s²)(1 + A3 s + A4 s²)]          (notch / torsional filter)
//! V_S = clamp( KS · T5 s/(1 + s T6) · (1 + s T1)/(1 + s T2) · (1 + s T3)/(1 + s T4) · F(s) · u , LSMIN, LSMAX )
//! V_S → 0 unless VCL < V_CT < VCU   (a limit equal to 0 disables that side)
//! ```
//!
//! The input `u` is whatever signal the port is wired to (PSS/E selects it by a code: speed
//! deviation, frequency, P_e, accelerating power, voltage…); the default wiring is `speed`.
//! `F(s)` is realised in controllable canonical form of its actual degree (0 to 4; all A's zero
//! bypasses it). States: four filter states (unused ones stay 0), two lead-lags, the washout.
//! Everything starts in steady state with output 0.

use crate::block::{guard, Block, InitPoint, Io, ModelError, Port, PortInit};
use crate::models::limiter::clamp;
use crate::models::exciter::roles::{LeadLagRole, ParamRole};
use crate::models::pss::roles::PssRoles;
use crate::sens::{Scalar, D};
use crate::{block_common, param_set};
use crate::dyr::{DyrRecord, Icon, STABILISER_INPUTS};
use crate::registry::{ModelInfo, Role};

/// The registry entry ([`crate::registry`]): name, role, `.dyr` record.
pub const MODEL: ModelInfo = ModelInfo {
    name: "IEEEST",
    role: Role::Pss,
    summary: "IEEE 1981 stabiliser",
    reference: "IEEE 421.5-1981 PSS as PSS/E IEEEST, OpenIPSL and ANDES (models.md §9.2.3)",
    make: || Box::new(Ieeest::default()),
    dyr: Some(DyrRecord {
        icons: &[
            Icon::Input {
                name: "IC",
                port: "u",
                codes: STABILISER_INPUTS,
            },
            Icon::Zero {
                name: "IB",
                meaning: "remote bus",
            },
        ],
        cons: &[
            "a1", "a2", "a3", "a4", "a5", "a6", "t1", "t2", "t3", "t4", "t5", "t6", "ks", "ls_max",
            "ls_min", "vcu", "vcl",
        ],
        machine: None,
    }),
};

param_set! {
    /// IEEEST parameters.
    pub struct IeeestParams {
        a1: ("A1", "s", 0.0, (0.0, 1.0), "filter denominator, first section, s coefficient"),
        a2: ("A2", "s2", 0.0, (0.0, 1.0), "filter denominator, first section, s² coefficient"),
        a3: ("A3", "s", 0.0, (0.0, 1.0), "filter denominator, second section, s coefficient"),
        a4: ("A4", "s2", 0.0, (0.0, 1.0), "filter denominator, second section, s² coefficient"),
        a5: ("A5", "s", 0.0, (0.0, 1.0), "filter numerator, s coefficient"),
        a6: ("A6", "s2", 0.0, (0.0, 1.0), "filter numerator, s² coefficient"),
        t1: ("T1", "s", 0.15, (0.0, 1.0), "first lead time constant"),
        t2: ("T2", "s", 0.03, (0.0, 1.0), "first lag time constant"),
        t3: ("T3", "s", 0.15, (0.0, 1.0), "second lead time constant"),
        t4: ("T4", "s", 0.03, (0.0, 1.0), "second lag time constant"),
        t5: ("T5", "s", 1.65, (1.0, 10.0), "washout numerator time constant"),
        t6: ("T6", "s", 1.65, (1.0, 10.0), "washout denominator time constant"),
        ks: ("KS", "pu", 6.2, (1.0, 40.0), "stabiliser gain"),
        ls_max: ("LSMAX", "pu", 0.26, (0.05, 0.3), "maximum output"),
        ls_min: ("LSMIN", "pu", -0.1, (-0.3, -0.05), "minimum output"),
        vcu: ("VCU", "pu", 0.0, (0.0, 1.3), "output cut-off above this terminal voltage (0 = off)"),
        vcl: ("VCL", "pu", 0.0, (0.0, 0.9), "output cut-off below this terminal voltage (0 = off)"),
    }
}

mod port {
    pub const U: usize = 0;
    pub const V_TERM: usize = 1;
    pub const VS: usize = 2;
}

const PORTS: &[Port] = &[
    Port::input_ft(
        "u",
        PortInit::Needs,
        "stabiliser input (default: speed deviation Δω) [pu]",
    )
    .wired("speed"),
    Port::input_ft(
        "v_term",
        PortInit::Needs,
        "terminal voltage V_CT for the output cut-off [pu]",
    ),
    Port::output("vs", PortInit::Gives, "stabiliser output V_S [pu]"),
];

/// Controllable-canonical realisation of F(s) (derived constants).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct Filter<S = f64> {
    order: usize,
    dff: S,
    a: [S; 4],
    c: [S; 4],
}

impl<S: Scalar> Filter<S> {
    fn new(p: &IeeestParams<S>) -> Result<Self, ModelError> {
        let one = S::cst(1.0);
        let d = [
            one,
            p.a1 + p.a3,
            p.a2 + p.a4 + p.a1 * p.a3,
            p.a1 * p.a4 + p.a2 * p.a3,
            p.a2 * p.a4,
        ];
        let num = [one, p.a5, p.a6, S::cst(0.0), S::cst(0.0)];
        let order = (0..5).rev().find(|&i| d[i].val() != 0.0).unwrap_or(0);
        let num_order = (0..5).rev().find(|&i| num[i].val() != 0.0).unwrap_or(0);
        if num_order > order {
            return Err(ModelError::param(
                "a5",
                "the notch filter F(s) is improper (numerator degree > denominator degree)",
            ));
        }
        let mut f = Filter {
            order,
            dff: one,
            a: [S::cst(0.0); 4],
            c: [S::cst(0.0); 4],
        };
        if order == 0 {
            return Ok(f);
        }
        let dn = d[order];
        f.dff = num[order] / dn;
        for i in 0..order {
            f.a[i] = d[i] / dn;
            f.c[i] = num[i] / dn - f.dff * f.a[i];
        }
        Ok(f)
    }
    #[inline(always)]
    fn output(&self, z: &[S], u: S) -> S {
        // Summed from −0 as `f64`'s `Sum` does.
        let sum = self.c[..self.order]
            .iter()
            .zip(z)
            .fold(S::cst(-0.0), |acc, (c, z)| acc + *c * *z);
        self.dff * u + sum
    }
    #[inline(always)]
    fn derivatives(&self, z: &[S], u: S, dz: &mut [S]) {
        dz[..4].fill(S::cst(0.0));
        let n = self.order;
        if n == 0 {
            return;
        }
        dz[..n - 1].copy_from_slice(&z[1..n]);
        let sum = self.a[..n]
            .iter()
            .zip(z)
            .fold(S::cst(-0.0), |acc, (a, z)| acc + *a * *z);
        dz[n - 1] = u - sum;
    }
}

/// Lead-lag `(1 + s t_lead)/(1 + s t_lag)` output with state `x` (`t_lag = 0` means a gain of 1).
#[inline(always)]
fn lead_lag<S: Scalar>(u: S, x: S, t_lead: S, t_lag: S) -> S {
    if t_lag.val() > 0.0 {
        let r = t_lead / t_lag;
        r * u + r.rsub(1.0) * x
    } else {
        u
    }
}

#[inline(always)]
fn lag_rate<S: Scalar>(u: S, x: S, t: S) -> S {
    if t.val() > 0.0 {
        (u - x) / t
    } else {
        S::cst(0.0)
    }
}

/// Signals along the chain: (filter out, lead-lag 1 out, lead-lag 2 out, washout out).
#[inline(always)]
fn chain<S: Scalar>(p: &IeeestParams<S>, filter: &Filter<S>, x: &[S], u: S) -> (S, S, S, S) {
    let yf = filter.output(&x[0..4], u);
    let y1 = lead_lag(yf, x[4], p.t1, p.t2);
    let y2 = lead_lag(y1, x[5], p.t3, p.t4);
    let yw = (p.t5 / p.t6) * (y2 - x[6]);
    (yf, y1, y2, yw)
}

#[inline(always)]
fn outputs<S: Scalar>(p: &IeeestParams<S>, filter: &Filter<S>, x: &[S], io: &mut Io<S>) {
    let (_, _, _, yw) = chain(p, filter, x, io.get(port::U));
    let mut vs = clamp(p.ks * yw, p.ls_min, p.ls_max);
    let vct = io.get(port::V_TERM).val();
    let (vcu, vcl) = (p.vcu.val(), p.vcl.val());
    if (vcu != 0.0 && vct > vcu) || (vcl != 0.0 && vct < vcl) {
        vs = S::cst(0.0);
    }
    io.set(port::VS, vs);
}

#[inline(always)]
fn derivatives<S: Scalar>(
    p: &IeeestParams<S>,
    filter: &Filter<S>,
    x: &[S],
    io: &Io<S>,
    dx: &mut [S],
) {
    let u = io.get(port::U);
    let (yf, y1, y2, _) = chain(p, filter, x, u);
    filter.derivatives(&x[0..4], u, &mut dx[0..4]);
    dx[4] = lag_rate(yf, x[4], p.t2);
    dx[5] = lag_rate(y1, x[5], p.t4);
    dx[6] = (y2 - x[6]) / p.t6;
}

/// IEEEST block.
#[derive(Debug, Clone, Default)]
pub struct Ieeest {
    pub p: IeeestParams,
    filter: Filter,
    /// The parameters and the filter on dual numbers, after [`Block::seed_dual`].
    dual: Option<(IeeestParams<D>, Filter<D>)>,
}

impl Ieeest {
    pub fn new(p: IeeestParams) -> Self {
        Self {
            p,
            filter: Filter::default(),
            dual: None,
        }
    }
}

impl Block for Ieeest {
    block_common!();

    fn pss_roles(&self) -> Option<PssRoles> {
        let mut r = PssRoles::none("not applicable to IEEEST");
        r.gain = ParamRole::param("ks");
        r.washout = ParamRole::param("t6");
        r.lead_lag_1 = LeadLagRole::LeadLag {
            lead: "t1".into(),
            lag: "t2".into(),
        };
        r.lead_lag_2 = LeadLagRole::LeadLag {
            lead: "t3".into(),
            lag: "t4".into(),
        };
        r.output_max = ParamRole::param("ls_max");
        r.output_min = ParamRole::param("ls_min");
        Some(r)
    }

    fn model(&self) -> &'static str {
        "IEEEST"
    }
    fn ports(&self) -> &'static [Port] {
        PORTS
    }
    fn state_names(&self) -> &'static [&'static str] {
        &[
            "filter_1",
            "filter_2",
            "filter_3",
            "filter_4",
            "lead_lag_1",
            "lead_lag_2",
            "washout",
        ]
    }
    fn validate(&self) -> Result<(), ModelError> {
        let p = &self.p;
        for (name, v) in [
            ("a1", p.a1),
            ("a2", p.a2),
            ("a3", p.a3),
            ("a4", p.a4),
            ("a5", p.a5),
            ("a6", p.a6),
        ] {
            guard::non_negative(name, v)?;
        }
        for (lead, lag, ln, gn) in [(p.t1, p.t2, "t1", "t2"), (p.t3, p.t4, "t3", "t4")] {
            guard::non_negative(ln, lead)?;
            guard::non_negative(gn, lag)?;
            if lag == 0.0 && lead != 0.0 {
                return Err(ModelError::param(
                    gn,
                    format!("a lead ({ln} = {lead}) needs a lag > 0"),
                ));
            }
        }
        guard::non_negative("t5", p.t5)?;
        guard::positive("t6", p.t6)?;
        guard::finite("ks", p.ks)?;
        guard::greater("ls_max", p.ls_max, "ls_min", p.ls_min)?;
        Filter::new(p).map(|_| ())
    }
    fn init(&mut self, _op: &InitPoint, x: &mut [f64], io: &mut Io) -> Result<(), ModelError> {
        self.validate()?;
        self.filter = Filter::new(&self.p)?;
        let u0 = io.get(port::U);
        x.fill(0.0);
        if self.filter.order > 0 {
            x[0] = u0 / self.filter.a[0];
        }
        x[4] = u0;
        x[5] = u0;
        x[6] = u0;
        io.set(port::VS, 0.0);
        Ok(())
    }
    #[inline]
    fn outputs(&self, _t: f64, x: &[f64], io: &mut Io) {
        outputs(&self.p, &self.filter, x, io);
    }
    #[inline]
    fn derivatives(&self, _t: f64, x: &[f64], io: &Io, dx: &mut [f64]) {
        derivatives(&self.p, &self.filter, x, io, dx);
    }
    fn seed_dual(&mut self, lanes: &[Option<usize>], _consts: &[D]) -> bool {
        let p = self.p.lift_dual(lanes);
        let Ok(filter) = Filter::new(&p) else {
            return false;
        };
        self.dual = Some((p, filter));
        true
    }
    fn outputs_dual(&self, _t: f64, x: &[D], io: &mut Io<D>) {
        if let Some((p, f)) = &self.dual {
            outputs(p, f, x, io);
        }
    }
    fn derivatives_dual(&self, _t: f64, x: &[D], io: &Io<D>, dx: &mut [D]) {
        if let Some((p, f)) = &self.dual {
            derivatives(p, f, x, io, dx);
        }
    }
}
