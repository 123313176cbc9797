//! ST5B: IEEE 421.5-2005 type ST5B static (bus-fed thyristor) excitation system, as PSS/E's
//! `ST5B` and OpenIPSL's `Electrical.Controls.PSSE.ES.ST5B` implement it.
//!
//! States: transducer `v_m`; main regulator lead-lags `x_ll1`, `x_ll2`; the alternate UEL and
//! OEL lead-lag pairs `x_ul1`, `x_ul2`, `x_ol1`, `x_ol2`; bridge output `e_fd`.
//!
//! ```text
//! T_R dV_m/dt = E_comp − V_m                                  (T_R = 0: V_m = E_comp)
//! V_e  = V_ref + ΔV_ref − V_m
//! V_h  = V_e + V_UEL        or, UEL gate:  V_h = max(V_e, V_UEL)        (HV gate)
//! V_l  = V_h + V_OEL        or, OEL gate:  V_l = min(V_h, V_OEL)        (LV gate)
//! u    = V_l + V_S
//! main path:  y = LL(T_C2, T_B2)[ LL(T_C1, T_B1)[u] ]   each lead-lag limited to [V_RMIN/K_R, V_RMAX/K_R]
//! UEL path (UEL gate selects V_UEL):  LL(T_UC2, T_UB2)[ LL(T_UC1, T_UB1)[u] ]
//! OEL path (OEL gate selects V_OEL):  LL(T_OC2, T_OB2)[ LL(T_OC1, T_OB1)[u] ]
//! V_R  = clamp(K_R · y, V_RMIN, V_RMAX)
//! T_1 dE_fd/dt = V_R − K_C·X_adI_fd − E_fd     non-windup in [V_T·V_RMIN, V_T·V_RMAX]
//!                                             (T_1 = 0: E_fd = clamp(V_R − K_C·X_adI_fd))
//! ```
//!
//! All voltages in pu (E_fd on the machine's field base, X_adI_fd in non-reciprocal pu), times in
//! s; nothing depends on the nominal frequency. `V_T` is the supply voltage on port `v_supply`
//! (default: the played-back `|V_t|`, as OpenIPSL feeds `ECOMP` to the limits); the regulated
//! voltage `E_comp` is port `v_term`. In steady state E_fd cannot exceed
//! `min(V_T·V_RMAX, V_RMAX − K_C·X_adI_fd)`: the K_C-reduced ceiling acts through `V_R ≤ V_RMAX`
//! upstream of the bridge, the supply-scaled one on the bridge output.
//!
//! **Limited lead-lags** are OpenIPSL's `LeadLagLim` (`blocks::LeadLagLim`: while the output is
//! on a limit the state is driven toward it with time constant `T_C`; `T_C = 0`: a non-windup
//! lag). A lead-lag with `T_B = 0` is bypassed (its output is its input, limited); `T_R = 0`
//! drops the transducer and `T_1 = 0` makes the bridge algebraic, as in PSS/E and OpenIPSL.
//!
//! **Moving bridge limits**, as OpenIPSL's `SimpleLagLimVar`: E_fd stays on `V_T·V_RMAX` while
//! the bridge input `V_R − K_C·X_adI_fd` is above it (following V_T as it moves) and leaves it
//! when the input falls below; the decision is taken at the output, the state clamped into the
//! limits ([`NonWindup`]'s moving-limit modes). One case differs: when the ceiling falls onto an
//! E_fd that is already decaying (bridge input below the ceiling), E_fd is held on the ceiling
//! until the free state has decayed below it, where OpenIPSL restarts the state from the
//! ceiling at once.
//!
//! **UEL/OEL inputs.** By default (`uel = "summing"`, `oel = "summing"`) `vuel` and `voel` are
//! added to the voltage error as in SEXS (0 when not wired), which is what PSS/E's gates do when
//! no limiter model drives them, and what the summing-point `oel` extension of this library
//! expects. With the option `uel = "gate"` (`oel = "gate"`) the signal enters through PSS/E's
//! HV (LV) gate and, while the gate selects it, the regulator output comes from the alternate
//! UEL (OEL) lead-lag pair (whose states integrate all along, fed by the same `u`). A gate whose
//! input no block drives stays inactive, as in PSS/E without a limiter model
//! ([`Block::set_undriven_inputs`]).
//!
//! **Initialisation** (exact, from E_fd0 and X_adI_fd0): `V_R0 = E_fd0 + K_C·X_adI_fd0`, every
//! lead-lag state `= V_R0/K_R`, `V_m0 = E_comp0`, `e_fd = E_fd0`, and
//! `V_ref = E_comp0 + V_R0/K_R − V_S0 − V_OEL0 − V_UEL0` (a gate input instead must not be
//! selecting). It is an error, not a clip, when `E_fd0 ∉ [V_T0·V_RMIN, V_T0·V_RMAX]` or
//! `V_R0 ∉ [V_RMIN, V_RMAX]` (E_fd0 above the K_C-reduced ceiling), or a gate selects its
//! limiter at t = 0. `ΔV_ref` (`v_ref_offset`, default 0) is the set-point offset a fit may free.
//!
//! **Forward sensitivities.** The equations are written once, generic over the number type
//! ([`Scalar`]): the plain simulation runs them on `f64`, the sensitivity pass on duals
//! ([`Block::seed_dual`]), with the modes of the plain playback; the lead-lags' `T_C = 0` forms
//! and the bridge pinned on a limit take the limit's derivatives ([`Block::pin_dual`]), and the
//! guards are given on duals ([`Block::events_dual`]); the release from the moving supply
//! ceiling, where the state that only tracked the ceiling with `T_1` is projected onto it, is
//! differentiated by the pass from [`Block::moving_pins`]. Not exact: when the ceiling falls onto
//! a free state (a voltage dip), the output is clamped to it without a located event until the
//! state decays below it, and the sensitivities there are those of the active piece on the
//! replayed steps (on the 0.7 pu dip of `tests/sensitivities.rs`: 3e-4 to 1.6e-2 of each column
//! off the converged derivative, K_R and K_C worst).
//!
//! **Departures from OpenIPSL** (3.x `ST5B.mo`): OpenIPSL builds the UEL and OEL lead-lag pairs
//! but never connects them to the output (and gives the second UEL/OEL blocks the first blocks'
//! time constants); here they are used as the IEEE/PSS/E diagram intends when a gate selects
//! them. OpenIPSL's gates always act (its examples tie VUEL to −∞ and VOEL to +∞); here they are
//! an option (above). Non-windup limits use frozen-derivative modes located by the integrator
//! instead of OpenIPSL's `reinit`.

use crate::block::{guard, Block, InitPoint, Io, ModelError, Port, PortInit};
use crate::models::exciter::blocks::{Lag, LeadLagLim, ZERO_T};
use crate::models::exciter::roles::{ExciterRoles, LeadLagRole, ParamRole};
use crate::models::limiter::{clamp, NonWindup};
use crate::sens::{Scalar, D};
use crate::{block_common, param_set};
use crate::dyr::DyrRecord;
use crate::registry::{ModelInfo, Role};

/// The registry entry ([`crate::registry`]): name, role, `.dyr` record.
pub const MODEL: ModelInfo = ModelInfo {
    name: "ST5B",
    role: Role::Exciter,
    summary: "IEEE 421.5-2005 ST5B static exciter: bus-fed bridge, K_C commutation drop, UEL/OEL gates",
    reference: "IEEE 421.5-2005 ST5B as PSS/E's ST5B and OpenIPSL; limited lead-lags of OpenIPSL's LeadLagLim",
    make: || Box::new(St5b::default()),
    dyr: Some(DyrRecord::cons(&[
        "t_r", "t_c1", "t_b1", "t_c2", "t_b2", "k_r", "vr_max", "vr_min", "t_1", "k_c", "t_uc1",
        "t_ub1", "t_uc2", "t_ub2", "t_oc1", "t_ob1", "t_oc2", "t_ob2",
    ])),
};

param_set! {
    /// ST5B parameters (PSS/E CON order).
    pub struct St5bParams {
        t_r: ("TR", "s", 0.02, (0.0, 0.05), "regulator input filter time constant T_R"),
        t_c1: ("TC1", "s", 0.8, (0.0, 5.0), "lead time constant of the first regulator lead-lag T_C1"),
        t_b1: ("TB1", "s", 6.0, (0.5, 20.0), "lag time constant of the first regulator lead-lag T_B1"),
        t_c2: ("TC2", "s", 0.08, (0.0, 5.0), "lead time constant of the second regulator lead-lag T_C2"),
        t_b2: ("TB2", "s", 0.01, (0.0, 5.0), "lag time constant of the second regulator lead-lag T_B2"),
        k_r: ("KR", "pu", 200.0, (50.0, 500.0), "regulator gain K_R"),
        vr_max: ("VRMAX", "pu", 5.0, (3.0, 8.0), "regulator maximum output V_RMAX (also the E_fd ceiling per pu V_T)"),
        vr_min: ("VRMIN", "pu", -4.0, (-6.0, 0.0), "regulator minimum output V_RMIN (also the E_fd floor per pu V_T)"),
        t_1: ("T1", "s", 0.004, (0.001, 0.05), "thyristor bridge firing equivalent time constant T_1"),
        k_c: ("KC", "pu", 0.05, (0.0, 0.3), "rectifier loading factor proportional to the commutating reactance K_C"),
        t_uc1: ("TUC1", "s", 2.0, (0.0, 10.0), "UEL path: lead time constant of the first lead-lag"),
        t_ub1: ("TUB1", "s", 10.0, (0.0, 20.0), "UEL path: lag time constant of the first lead-lag"),
        t_uc2: ("TUC2", "s", 0.1, (0.0, 5.0), "UEL path: lead time constant of the second lead-lag"),
        t_ub2: ("TUB2", "s", 0.05, (0.0, 5.0), "UEL path: lag time constant of the second lead-lag"),
        t_oc1: ("TOC1", "s", 0.1, (0.0, 10.0), "OEL path: lead time constant of the first lead-lag"),
        t_ob1: ("TOB1", "s", 2.0, (0.0, 20.0), "OEL path: lag time constant of the first lead-lag"),
        t_oc2: ("TOC2", "s", 0.08, (0.0, 5.0), "OEL path: lead time constant of the second lead-lag"),
        t_ob2: ("TOB2", "s", 0.08, (0.0, 5.0), "OEL path: lag time constant of the second lead-lag"),
        v_ref_offset: ("dVref", "pu", 0.0, (-0.01, 0.01), "voltage reference offset added after initialisation (nuisance)"),
    }
}

/// Port indices (the first five as SEXS's).
pub mod port {
    pub const V_TERM: usize = 0;
    pub const VS: usize = 1;
    pub const VOEL: usize = 2;
    pub const VUEL: usize = 3;
    pub const EFD: usize = 4;
    pub const V_SUPPLY: usize = 5;
    pub const XADIFD: usize = 6;
}

const PORTS: &[Port] = &[
    Port::input_ft(
        "v_term",
        PortInit::Needs,
        "compensated terminal voltage E_comp [pu]",
    ),
    Port::input_ft("vs", PortInit::Needs, "stabiliser signal V_S [pu]").optional(),
    Port::input_ft(
        "voel",
        PortInit::Needs,
        "over-excitation limiter signal [pu] (summed, or LV gate with oel = \"gate\")",
    )
    .optional(),
    Port::input_ft(
        "vuel",
        PortInit::Needs,
        "under-excitation limiter signal [pu] (summed, or HV gate with uel = \"gate\")",
    )
    .optional(),
    Port::output("efd", PortInit::Needs, "field voltage E_fd [pu]"),
    Port::input_ft(
        "v_supply",
        PortInit::Needs,
        "supply (terminal) voltage V_T of the bridge [pu]",
    )
    .wired("v_term"),
    Port::input_ft("xadifd", PortInit::Needs, "field current X_ad I_fd [pu]"),
];

/// Index of the six lead-lags in the state vector (after `v_m`).
const LL: usize = 1;
const EFD_STATE: usize = 7;

/// Which lead-lag pair feeds the regulator gain.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Path {
    Main = 0,
    Uel = 1,
    Oel = 2,
}

/// An ST5B block. See the module documentation.
#[derive(Debug, Clone, Default)]
pub struct St5b {
    pub p: St5bParams,
    /// `uel = "gate"`, `oel = "gate"`.
    uel_gate: bool,
    oel_gate: bool,
    /// The unit drives nothing into `vuel` / `voel` (a gate on it stays inactive).
    uel_undriven: bool,
    oel_undriven: bool,
    /// The numbers the initialisation derives (built by [`Block::init`], read with `p`).
    k: Consts,
    /// The discrete modes (no number in them).
    m: Modes,
    /// The parameters and the derived numbers on duals, after [`Block::seed_dual`].
    dual: Option<(St5bParams<D>, Consts<D>)>,
}

/// The numbers the initialisation derives, on the number type `S`.
#[derive(Debug, Clone, Copy, Default)]
struct Consts<S = f64> {
    v_ref: S,
    transducer: Lag<S>,
    /// main (0, 1), UEL (2, 3), OEL (4, 5).
    ll: [LeadLagLim<S>; 6],
    inv_t1: S,
}

/// The modes: the six lead-lags' (`T_C = 0` forms) and the bridge's.
#[derive(Debug, Clone, Copy, Default)]
struct Modes {
    ll: [NonWindup; 6],
    bridge: NonWindup,
}

/// Which gates are in use: the option set and its input driven.
#[derive(Debug, Clone, Copy)]
struct Opts {
    uel_gate: bool,
    oel_gate: bool,
}

impl Opts {
    /// Which pairs integrate: the main one always, an alternate one only with its gate.
    #[inline(always)]
    fn active(&self, pair: usize) -> bool {
        match pair {
            0 => true,
            1 => self.uel_gate,
            _ => self.oel_gate,
        }
    }
}

/// The derived numbers of the parameters `p` with the voltage reference `v_ref`.
fn consts<S: Scalar>(p: &St5bParams<S>, v_ref: S) -> Consts<S> {
    let (lo, hi) = (p.vr_min / p.k_r, p.vr_max / p.k_r);
    Consts {
        v_ref,
        transducer: Lag::new(p.t_r),
        ll: [
            LeadLagLim::new(p.t_c1, p.t_b1, lo, hi),
            LeadLagLim::new(p.t_c2, p.t_b2, lo, hi),
            LeadLagLim::new(p.t_uc1, p.t_ub1, lo, hi),
            LeadLagLim::new(p.t_uc2, p.t_ub2, lo, hi),
            LeadLagLim::new(p.t_oc1, p.t_ob1, lo, hi),
            LeadLagLim::new(p.t_oc2, p.t_ob2, lo, hi),
        ],
        inv_t1: if p.t_1.val() < ZERO_T {
            S::cst(0.0)
        } else {
            p.t_1.recip()
        },
    }
}

/// The lead-lag input `u` and the path the gates select.
#[inline(always)]
fn gated_input<S: Scalar>(
    p: &St5bParams<S>,
    k: &Consts<S>,
    o: Opts,
    x: &[S],
    io: &Io<S>,
) -> (S, Path) {
    let v_m = k.transducer.output(x[0], io.get(port::V_TERM));
    let v_e = k.v_ref + p.v_ref_offset - v_m;
    let (v_uel, v_oel) = (io.get(port::VUEL), io.get(port::VOEL));
    let mut path = Path::Main;
    let v_h = if o.uel_gate {
        if v_uel.val() > v_e.val() {
            path = Path::Uel;
            v_uel
        } else {
            v_e
        }
    } else {
        v_e + v_uel
    };
    let v_l = if o.oel_gate {
        if v_oel.val() < v_h.val() {
            path = Path::Oel;
            v_oel
        } else {
            v_h
        }
    } else {
        v_h + v_oel
    };
    (v_l + io.get(port::VS), path)
}

/// `(u, output of the first block of each pair, path)`.
#[inline(always)]
fn chain<S: Scalar>(
    p: &St5bParams<S>,
    k: &Consts<S>,
    o: Opts,
    m: &Modes,
    x: &[S],
    io: &Io<S>,
) -> (S, [S; 3], Path) {
    let (u, path) = gated_input(p, k, o, x, io);
    let y1 = [0, 1, 2].map(|j| k.ll[2 * j].output_in(&m.ll[2 * j], x[LL + 2 * j], u));
    (u, y1, path)
}

/// Regulator output V_R.
#[inline(always)]
fn v_r<S: Scalar>(
    p: &St5bParams<S>,
    k: &Consts<S>,
    m: &Modes,
    x: &[S],
    y1: &[S; 3],
    path: Path,
) -> S {
    let j = path as usize;
    let y = k.ll[2 * j + 1].output_in(&m.ll[2 * j + 1], x[LL + 2 * j + 1], y1[j]);
    clamp(p.k_r * y, p.vr_min, p.vr_max)
}

/// `(E_fd,min, E_fd,max)` of the bridge.
#[inline(always)]
fn limits<S: Scalar>(p: &St5bParams<S>, io: &Io<S>) -> (S, S) {
    let v = io.get(port::V_SUPPLY);
    (v * p.vr_min, v * p.vr_max)
}

/// Bridge input `V_R − K_C·X_adI_fd`.
#[inline(always)]
fn bridge_input<S: Scalar>(
    p: &St5bParams<S>,
    k: &Consts<S>,
    o: Opts,
    m: &Modes,
    x: &[S],
    io: &Io<S>,
) -> S {
    let (_, y1, path) = chain(p, k, o, m, x, io);
    v_r(p, k, m, x, &y1, path) - p.k_c * io.get(port::XADIFD)
}

/// E_fd at the current point.
#[inline(always)]
fn outputs<S: Scalar>(
    p: &St5bParams<S>,
    k: &Consts<S>,
    o: Opts,
    m: &Modes,
    x: &[S],
    io: &mut Io<S>,
) {
    let (lo, hi) = limits(p, io);
    let efd = if k.inv_t1.val() == 0.0 {
        clamp(bridge_input(p, k, o, m, x, io), lo, hi)
    } else {
        clamp(m.bridge.effective(x[EFD_STATE], lo, hi), lo, hi)
    };
    io.set(port::EFD, efd);
}

/// The state derivatives.
#[inline(always)]
fn derivatives<S: Scalar>(
    p: &St5bParams<S>,
    k: &Consts<S>,
    o: Opts,
    m: &Modes,
    x: &[S],
    io: &Io<S>,
    dx: &mut [S],
) {
    dx[0] = k.transducer.derivative(x[0], io.get(port::V_TERM));
    let (u, y1, path) = chain(p, k, o, m, x, io);
    for (pair, &y1p) in y1.iter().enumerate() {
        let (a, b) = (LL + 2 * pair, LL + 2 * pair + 1);
        if o.active(pair) {
            dx[a] = k.ll[2 * pair].derivative_in(&m.ll[2 * pair], x[a], u);
            dx[b] = k.ll[2 * pair + 1].derivative_in(&m.ll[2 * pair + 1], x[b], y1p);
        } else {
            dx[a] = S::cst(0.0);
            dx[b] = S::cst(0.0);
        }
    }
    dx[EFD_STATE] = if k.inv_t1.val() == 0.0 {
        S::cst(0.0)
    } else {
        let (lo, hi) = limits(p, io);
        let v = v_r(p, k, m, x, &y1, path) - p.k_c * io.get(port::XADIFD);
        let f = (v - m.bridge.effective(x[EFD_STATE], lo, hi)) * k.inv_t1;
        m.bridge
            .derivative_moving(f, x[EFD_STATE], lo, hi, k.inv_t1)
    };
}

/// The guards: the bridge's two, then two for each lead-lag (constant unless `T_C = 0`).
#[inline(always)]
fn guards<S: Scalar>(
    p: &St5bParams<S>,
    k: &Consts<S>,
    o: Opts,
    m: &Modes,
    x: &[S],
    io: &Io<S>,
    g: &mut [S],
) {
    let (u, y1, _) = chain(p, k, o, m, x, io);
    if k.inv_t1.val() == 0.0 {
        g[0] = S::cst(1.0);
        g[1] = S::cst(1.0);
    } else {
        let (lo, hi) = limits(p, io);
        // The rate at the output (the state clamped into the limits): a free state left
        // above a ceiling that fell below it is pinned as soon as the regulator pushes
        // beyond the ceiling, as OpenIPSL's `SimpleLagLimVar` does.
        let xe = clamp(m.bridge.effective(x[EFD_STATE], lo, hi), lo, hi);
        let f = (bridge_input(p, k, o, m, x, io) - xe) * k.inv_t1;
        m.bridge
            .events_moving(x[EFD_STATE], f, lo, hi, &mut g[0..2]);
    }
    for j in 0..6 {
        let input = if j % 2 == 0 { u } else { y1[j / 2] };
        k.ll[j].events_in(&m.ll[j], x[LL + j], input, &mut g[2 + 2 * j..4 + 2 * j]);
    }
}

impl St5b {
    pub fn new(p: St5bParams) -> Self {
        Self {
            p,
            ..Default::default()
        }
    }

    /// Voltage reference found at initialisation [pu].
    pub fn v_ref(&self) -> f64 {
        self.k.v_ref
    }

    /// The gates in use: the option set and its input driven.
    #[inline(always)]
    fn opts(&self) -> Opts {
        Opts {
            uel_gate: self.uel_gate && !self.uel_undriven,
            oel_gate: self.oel_gate && !self.oel_undriven,
        }
    }
}

impl Block for St5b {
    block_common!();

    fn model(&self) -> &'static str {
        "ST5B"
    }
    fn ports(&self) -> &'static [Port] {
        PORTS
    }
    fn state_names(&self) -> &'static [&'static str] {
        &[
            "v_m", "x_ll1", "x_ll2", "x_ul1", "x_ul2", "x_ol1", "x_ol2", "e_fd",
        ]
    }
    fn validate(&self) -> Result<(), ModelError> {
        let p = &self.p;
        for (n, v) in [
            ("t_r", p.t_r),
            ("t_c1", p.t_c1),
            ("t_b1", p.t_b1),
            ("t_c2", p.t_c2),
            ("t_b2", p.t_b2),
            ("t_1", p.t_1),
            ("k_c", p.k_c),
            ("t_uc1", p.t_uc1),
            ("t_ub1", p.t_ub1),
            ("t_uc2", p.t_uc2),
            ("t_ub2", p.t_ub2),
            ("t_oc1", p.t_oc1),
            ("t_ob1", p.t_ob1),
            ("t_oc2", p.t_oc2),
            ("t_ob2", p.t_ob2),
        ] {
            guard::non_negative(n, v)?;
        }
        guard::positive("k_r", p.k_r)?;
        guard::finite("vr_min", p.vr_min)?;
        guard::greater("vr_max", p.vr_max, "vr_min", p.vr_min)?;
        guard::finite("v_ref_offset", p.v_ref_offset)
    }

    fn init(&mut self, _op: &InitPoint, x: &mut [f64], io: &mut Io) -> Result<(), ModelError> {
        self.validate()?;
        self.k = consts(&self.p, 0.0);
        let p = &self.p;
        let efd0 = io.get(port::EFD);
        let ifd0 = io.get(port::XADIFD);
        let vt0 = io.get(port::V_SUPPLY);
        let (lo, hi) = limits(p, io);
        if !(efd0 >= lo && efd0 <= hi) {
            return Err(ModelError::Init(format!(
                "ST5B: initial field voltage E_fd0 = {efd0:.4} pu lies outside [V_T·VRMIN, V_T·VRMAX] = [{lo:.4}, {hi:.4}] (V_T = {vt0:.4})"
            )));
        }
        let vr0 = efd0 + p.k_c * ifd0;
        if !(vr0 >= p.vr_min && vr0 <= p.vr_max) {
            return Err(ModelError::Init(format!(
                "ST5B: E_fd0 + KC·X_adI_fd0 = {efd0:.4} + {}·{ifd0:.4} = {vr0:.4} pu lies outside [VRMIN, VRMAX] = [{}, {}] (E_fd0 above the KC-reduced ceiling)",
                p.k_c, p.vr_min, p.vr_max
            )));
        }
        let u0 = vr0 / p.k_r;
        let ecomp0 = io.get(port::V_TERM);
        // Backwards through the summing points and gates.
        let v_l = u0 - io.get(port::VS);
        let v_oel = io.get(port::VOEL);
        let Opts { uel_gate, oel_gate } = self.opts();
        let v_h = if oel_gate {
            if v_oel < v_l {
                return Err(ModelError::Init(format!(
                    "ST5B: the OEL gate selects V_OEL = {v_oel:.4} at t = 0 (below the regulator error {v_l:.4}): no steady state on the voltage set point"
                )));
            }
            v_l
        } else {
            v_l - v_oel
        };
        let v_uel = io.get(port::VUEL);
        let v_e = if uel_gate {
            if v_uel > v_h {
                return Err(ModelError::Init(format!(
                    "ST5B: the UEL gate selects V_UEL = {v_uel:.4} at t = 0 (above the regulator error {v_h:.4}): no steady state on the voltage set point"
                )));
            }
            v_h
        } else {
            v_h - v_uel
        };
        self.k.v_ref = ecomp0 + v_e;
        x[0] = ecomp0;
        for s in &mut x[LL..LL + 6] {
            *s = u0;
        }
        x[EFD_STATE] = efd0;
        self.m = Modes::default();
        Ok(())
    }

    #[inline]
    fn outputs(&self, _t: f64, x: &[f64], io: &mut Io) {
        outputs(&self.p, &self.k, self.opts(), &self.m, x, io);
    }

    #[inline]
    fn derivatives(&self, _t: f64, x: &[f64], io: &Io, dx: &mut [f64]) {
        derivatives(&self.p, &self.k, self.opts(), &self.m, x, io, dx);
    }

    fn init_constants(&self) -> Vec<f64> {
        vec![self.k.v_ref]
    }

    fn seed_dual(&mut self, lanes: &[Option<usize>], consts_d: &[D]) -> bool {
        let p = self.p.lift_dual(lanes);
        let v_ref = consts_d.first().copied().unwrap_or(D::cst(self.k.v_ref));
        let k = consts(&p, v_ref);
        self.dual = Some((p, k));
        true
    }

    fn outputs_dual(&self, _t: f64, x: &[D], io: &mut Io<D>) {
        if let Some((p, k)) = &self.dual {
            outputs(p, k, self.opts(), &self.m, x, io);
        }
    }

    fn derivatives_dual(&self, _t: f64, x: &[D], io: &Io<D>, dx: &mut [D]) {
        if let Some((p, k)) = &self.dual {
            derivatives(p, k, self.opts(), &self.m, x, io, dx);
        }
    }

    /// The lead-lags' `T_C = 0` forms pinned on `V_RMIN/K_R`, `V_RMAX/K_R`, and the bridge
    /// state pinned on its (moving) limit `V_T·V_RMIN`, `V_T·V_RMAX`.
    fn pin_dual(&self, x: &mut [D], io: &Io<D>) {
        if let Some((p, k)) = &self.dual {
            for j in 0..6 {
                k.ll[j].pin_in(&self.m.ll[j], &mut x[LL + j]);
            }
            if self.k.inv_t1 != 0.0 {
                let (lo, hi) = limits(p, io);
                self.m.bridge.pin(&mut x[EFD_STATE], lo, hi);
            }
        }
    }

    fn moving_pins(&self, _x: &[f64], io: &Io, out: &mut Vec<(usize, f64)>) {
        if self.k.inv_t1 != 0.0 {
            let (lo, hi) = limits(&self.p, io);
            out.extend(self.m.bridge.pinned_to(lo, hi).map(|v| (EFD_STATE, v)));
        }
    }

    fn moving_pins_dual(&self, _x: &[D], io: &Io<D>, out: &mut Vec<(usize, D)>) {
        if let (true, Some((p, _))) = (self.k.inv_t1 != 0.0, &self.dual) {
            let (lo, hi) = limits(p, io);
            out.extend(self.m.bridge.pinned_to(lo, hi).map(|v| (EFD_STATE, v)));
        }
    }

    fn n_events(&self) -> usize {
        2 + 12
    }
    fn events(&self, x: &[f64], io: &Io, g: &mut [f64]) {
        guards(&self.p, &self.k, self.opts(), &self.m, x, io, g);
    }
    fn events_dual(&self, x: &[D], io: &Io<D>, g: &mut [D]) -> bool {
        match &self.dual {
            Some((p, k)) => {
                guards(p, k, self.opts(), &self.m, x, io, g);
                true
            }
            None => false,
        }
    }
    fn update_modes(&mut self, x: &mut [f64], io: &Io) -> bool {
        let o = self.opts();
        let mut changed = false;
        // The lead-lags first (T_C = 0 forms may pin their state), then the bridge.
        for j in 0..6 {
            let (u, y1, _) = chain(&self.p, &self.k, o, &self.m, x, io);
            let input = if j % 2 == 0 { u } else { y1[j / 2] };
            let mut s = x[LL + j];
            let mut mode = self.m.ll[j];
            changed |= self.k.ll[j].update_in(&mut mode, &mut s, input);
            self.m.ll[j] = mode;
            x[LL + j] = s;
        }
        if self.k.inv_t1 != 0.0 {
            let (lo, hi) = limits(&self.p, io);
            let v = bridge_input(&self.p, &self.k, o, &self.m, x, io);
            let mut limit = self.m.bridge;
            // Decide at the output, the state clamped into the limits (see `events`): a free
            // state above a fallen ceiling is clipped to it, and pinned if the regulator pushes.
            let mut xe = clamp(x[EFD_STATE], lo, hi);
            let inv_t1 = self.k.inv_t1;
            changed |= limit.update_moving(&mut xe, |s| (v - s) * inv_t1, lo, hi);
            self.m.bridge = limit;
            x[EFD_STATE] = xe;
        }
        changed
    }

    fn set_undriven_inputs(&mut self, ports: &[usize]) {
        self.uel_undriven = ports.contains(&port::VUEL);
        self.oel_undriven = ports.contains(&port::VOEL);
    }

    fn set_option(&mut self, key: &str, value: &str) -> Result<(), ModelError> {
        let slot = match key {
            "uel" => &mut self.uel_gate,
            "oel" => &mut self.oel_gate,
            _ => {
                return Err(ModelError::param(
                    key,
                    "unknown option (ST5B options: uel, oel)",
                ))
            }
        };
        *slot = match value {
            "summing" => false,
            "gate" => true,
            _ => {
                return Err(ModelError::param(
                    key,
                    format!("'{value}': expected \"summing\" or \"gate\""),
                ))
            }
        };
        Ok(())
    }
    fn options(&self) -> Vec<(&'static str, String)> {
        let mut o = vec![];
        if self.uel_gate {
            o.push(("uel", "gate".to_string()));
        }
        if self.oel_gate {
            o.push(("oel", "gate".to_string()));
        }
        o
    }

    fn exciter_roles(&self) -> Option<ExciterRoles> {
        let mut r = ExciterRoles::none("not applicable to ST5B");
        r.gain = ParamRole::param("k_r");
        r.field_time_constant = ParamRole::param("t_1");
        r.v_ref_offset = ParamRole::param("v_ref_offset");
        r.ceiling = ParamRole::none(
            "ST5B's ceiling is VRMAX scaled by V_T (and VRMAX − KC·X_adI_fd before the bridge), not one parameter (see supply_ceiling)",
        );
        r.floor = ParamRole::none(
            "ST5B's floor is VRMIN scaled by V_T, not one parameter (see supply_floor)",
        );
        r.transient_gain_reduction = LeadLagRole::LeadLag {
            lead: "t_c1".into(),
            lag: "t_b1".into(),
        };
        r.supply_ceiling = ParamRole::param("vr_max");
        r.supply_floor = ParamRole::param("vr_min");
        r.commutation = ParamRole::param("k_c");
        r.regulator_ceiling = ParamRole::param("vr_max");
        r.regulator_floor = ParamRole::param("vr_min");
        Some(r)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn roles_name_st5b_parameters() {
        let b = St5b::default();
        let r = b.exciter_roles().unwrap();
        r.check(b.params()).unwrap();
        assert_eq!(r.gain.name(), Some("k_r"));
        assert_eq!(r.field_time_constant.name(), Some("t_1"));
        assert_eq!(r.v_ref_offset.name(), Some("v_ref_offset"));
        assert_eq!(r.transient_gain_reduction.names(), Some(("t_c1", "t_b1")));
        assert!(r.ceiling.reason().unwrap().contains("scaled by V_T"));
        assert!(r.floor.name().is_none());
        assert_eq!(r.supply_ceiling.name(), Some("vr_max"));
        assert_eq!(r.supply_floor.name(), Some("vr_min"));
        assert_eq!(r.commutation.name(), Some("k_c"));
    }

    #[test]
    fn options_select_the_gates_and_reject_other_words() {
        let mut b = St5b::default();
        assert!(b.options().is_empty());
        b.set_option("oel", "gate").unwrap();
        assert_eq!(b.options(), vec![("oel", "gate".to_string())]);
        b.set_option("oel", "summing").unwrap();
        assert!(b.options().is_empty());
        assert!(b.set_option("uel", "max").is_err());
        assert!(b.set_option("swing", "gate").is_err());
        assert_eq!(b.params().specs().len(), 19);
    }
}
