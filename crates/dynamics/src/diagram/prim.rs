//! The primitive library of user-defined diagrams: what each primitive computes, its fields,
//! states and steady state.
//!
//! Notation: `u` the (first) input, `u_i` the i-th input, `y` the output, `x` the state,
//! `clamp(v) = min(max(v, min), max)`. Every field is a number or an expression of the
//! diagram's parameters (see [`super::expr`]); limits default to ±∞ (no limit).
//!
//! | primitive | equations | steady state (initialisation) |
//! |---|---|---|
//! | `constant` | `y = value` | |
//! | `reference` | `y = r + offset`, `r` solved at initialisation so that the target outputs (E_fd, P_m) take the machine's values; `offset` is a nuisance added afterwards | `r` unknown |
//! | `initial` | `y = u(0)` (the input's value at initialisation, then held) | `y = u` |
//! | `time` | `y = t` [s] | |
//! | `gain` | `y = k u` | |
//! | `sum` | `y = Σ g_i u_i`, `g_i` from `signs = "+-+"` or `gains = [..]` | |
//! | `product` | `y = Π u_i^{±1}`, `ops = "*/"` (`*` multiplies, `/` divides) | |
//! | `abs` | `y = \|u\|` | |
//! | `lag` | `T dx/dt = k u − x`, `y = clamp(x)`; with `min`/`max` the state is non-windup (frozen at a limit while pushing outwards) | `x = k u` |
//! | `lead_lag` | `k (1 + s T_a)/(1 + s T_b)`: `T_b dx/dt = u − x`, `y = k ((T_a/T_b) u + (1 − T_a/T_b) x)` | `x = u`, `y = k u` |
//! | `washout` | `k s T/(1 + s T)`: `T dx/dt = u − x`, `y = k (u − x)` | `x = u`, `y = 0` |
//! | `derivative` | `k s/(1 + s T)`: `T dx/dt = u − x`, `y = k (u − x)/T` | `x = u`, `y = 0` |
//! | `integrator` | `dx/dt = k u`, `y = clamp(x)`; `limit = "non_windup"` (default: x frozen at a limit while pushing outwards) or `"windup"` (x free, only y clamped) | `u = 0`, `x` unknown (or `x0` when given) |
//! | `pi` | `dx/dt = k_i u`, `y = clamp(k_p u + x)`; limits on x as for `integrator` | `u = 0`, `x` unknown |
//! | `pid` | `dx_i/dt = k_i u`, `T_d dx_d/dt = u − x_d`, `y = clamp(k_p u + x_i + k_d (u − x_d)/T_d)` | `u = 0`, `x_d = u`, `x_i` unknown |
//! | `limiter` | `y = clamp(u)` | |
//! | `rate_limiter` | `dx/dt = clamp((u − x)/T, −fall, rise)`, `y = x` (a tracking state whose speed is limited) | `x = u` |
//! | `deadband` | `y = 0` for `\|u\| ≤ width`, `u ∓ width` outside (no jump) | |
//! | `min`, `max` | `y = min_i u_i`, `max_i u_i` | |
//! | `switch` | inputs `[c, a, b]`: `y = a` when `c ≥ threshold`, else `b` | |
//! | `pwl` | piecewise-linear through `x = [..]`, `y = [..]` (x increasing), constant outside | |
//! | `pulso` | paper 000's step: `y = 0` for `u < p1`, `p2` for `p1 < u < p3`, `p4` otherwise; without `in` the input is the time `t` | |
//!
//! The clamps of `lag`, `integrator`, `pi`, `pid` and `limiter` are not applied during the
//! initialisation's solve; a steady state outside the limits is an error naming the block.
//! Static discontinuities (`switch`, `pulso`, `deadband` corners, `limiter`, `min`/`max`) are
//! not located by the integrator's event logic; the adaptive step handles them by rejection.
//!
//! The evaluation is written once for any [`Scalar`] ([`Node::output_in`],
//! [`Node::free_rate_in`], [`Node::derivatives_in`]): on `f64` with the node's own values (the
//! simulation), on dual numbers with values that carry their derivatives with respect to the
//! diagram's parameters (the forward sensitivities, [`crate::sens`]; the derivative of a
//! piecewise primitive is that of its active piece, a `pwl`'s breakpoints included).

use crate::models::limiter::{clamp, NonWindup};
use crate::sens::Scalar;

/// Domain a field's value must lie in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Dom {
    Positive,
    NonNegative,
    Finite,
    /// Any value, ±∞ included (limits).
    Any,
}

impl Dom {
    pub fn check(self, v: f64) -> Result<(), &'static str> {
        let ok = match self {
            Dom::Positive => v.is_finite() && v > 0.0,
            Dom::NonNegative => v.is_finite() && v >= 0.0,
            Dom::Finite => v.is_finite(),
            Dom::Any => !v.is_nan(),
        };
        if ok {
            Ok(())
        } else {
            Err(match self {
                Dom::Positive => "must be > 0",
                Dom::NonNegative => "must be >= 0",
                Dom::Finite => "must be finite",
                Dom::Any => "must be a number",
            })
        }
    }
    pub fn describe(self) -> &'static str {
        match self {
            Dom::Positive => "> 0",
            Dom::NonNegative => ">= 0",
            Dom::Finite => "finite",
            Dom::Any => "any, ±inf allowed",
        }
    }
}

/// A numeric field of a primitive.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Field {
    pub name: &'static str,
    /// Value when the field is omitted (`None`: required).
    pub default: Option<f64>,
    pub dom: Dom,
    pub doc: &'static str,
}

const fn req(name: &'static str, dom: Dom, doc: &'static str) -> Field {
    Field {
        name,
        default: None,
        dom,
        doc,
    }
}
const fn opt(name: &'static str, default: f64, dom: Dom, doc: &'static str) -> Field {
    Field {
        name,
        default: Some(default),
        dom,
        doc,
    }
}

/// How many inputs a primitive takes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Arity {
    None,
    One,
    /// One, or none (then the input is the time).
    OneOrTime,
    Exactly(usize),
    AtLeast(usize),
}

impl Arity {
    /// Whether a block of this arity may take `n` inputs.
    pub fn accepts(self, n: usize) -> bool {
        match self {
            Arity::None => n == 0,
            Arity::One => n == 1,
            Arity::OneOrTime => n <= 1,
            Arity::Exactly(k) => n == k,
            Arity::AtLeast(k) => n >= k,
        }
    }

    /// The inputs taken, in words for messages (`"one input"`) and as the `in` field is
    /// written, for the library listing (`in = "u"`).
    pub fn describe(self) -> (String, String) {
        let (words, field) = match self {
            Arity::None => ("no input".to_string(), "none".to_string()),
            Arity::One => ("one input".to_string(), "in = \"u\"".to_string()),
            Arity::OneOrTime => (
                "one input or none (the time)".to_string(),
                "in = \"u\" or none (time)".to_string(),
            ),
            Arity::Exactly(n) => (format!("exactly {n} inputs"), format!("in = [{n} signals]")),
            Arity::AtLeast(n) => (
                format!("at least {n} input(s)"),
                format!("in = [{n} or more signals]"),
            ),
        };
        (words, field)
    }
}

/// Primitive kind.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    Constant,
    Reference,
    Initial,
    Time,
    Gain,
    Sum,
    Product,
    Abs,
    Lag,
    LeadLag,
    Washout,
    Derivative,
    Integrator,
    Pi,
    Pid,
    Limiter,
    RateLimiter,
    Deadband,
    Min,
    Max,
    Switch,
    Pwl,
    Pulso,
}

/// Library entry of one primitive.
#[derive(Debug, Clone, Copy)]
pub struct PrimInfo {
    pub name: &'static str,
    pub kind: Kind,
    pub arity: Arity,
    pub fields: &'static [Field],
    /// Word or list options (not numbers), with their meaning.
    pub options: &'static [(&'static str, &'static str)],
    pub states: &'static [&'static str],
    pub equation: &'static str,
}

const LIM: [Field; 2] = [
    opt("min", f64::NEG_INFINITY, Dom::Any, "lower limit"),
    opt("max", f64::INFINITY, Dom::Any, "upper limit"),
];
const GUESS: Field = opt(
    "guess",
    f64::NAN,
    Dom::Any,
    "starting value of the state for the initialisation's solve (default: mid-limits, else 1)",
);
const X0: Field = opt(
    "x0",
    f64::NAN,
    Dom::Any,
    "fixed initial state: not solved for (its input must then be 0 at t = 0 by itself)",
);
const LIMIT_OPT: (&str, &str) = (
    "limit",
    "\"non_windup\" (default: the state freezes at a limit) or \"windup\" (only the output is clamped)",
);

/// The library, in the order `itaipu-calib models` prints it.
pub static PRIMITIVES: &[PrimInfo] = &[
    PrimInfo {
        name: "constant",
        kind: Kind::Constant,
        arity: Arity::None,
        fields: &[req("value", Dom::Finite, "output value")],
        options: &[],
        states: &[],
        equation: "y = value",
    },
    PrimInfo {
        name: "reference",
        kind: Kind::Reference,
        arity: Arity::None,
        fields: &[
            opt(
                "offset",
                0.0,
                Dom::Finite,
                "nuisance offset added after initialisation",
            ),
            opt(
                "guess",
                1.0,
                Dom::Finite,
                "starting value for the initialisation's solve",
            ),
        ],
        options: &[],
        states: &[],
        equation: "y = r + offset, r solved at initialisation (one reference per target output)",
    },
    PrimInfo {
        name: "initial",
        kind: Kind::Initial,
        arity: Arity::One,
        fields: &[],
        options: &[],
        states: &[],
        equation: "y = u(0), held",
    },
    PrimInfo {
        name: "time",
        kind: Kind::Time,
        arity: Arity::None,
        fields: &[],
        options: &[],
        states: &[],
        equation: "y = t [s]",
    },
    PrimInfo {
        name: "gain",
        kind: Kind::Gain,
        arity: Arity::One,
        fields: &[req("k", Dom::Finite, "gain")],
        options: &[],
        states: &[],
        equation: "y = k u",
    },
    PrimInfo {
        name: "sum",
        kind: Kind::Sum,
        arity: Arity::AtLeast(1),
        fields: &[],
        options: &[
            (
                "signs",
                "one + or - per input, e.g. \"+-+\" (default all +)",
            ),
            (
                "gains",
                "a number or expression per input, instead of signs",
            ),
        ],
        states: &[],
        equation: "y = Σ g_i u_i",
    },
    PrimInfo {
        name: "product",
        kind: Kind::Product,
        arity: Arity::AtLeast(1),
        fields: &[],
        options: &[("ops", "one * or / per input, e.g. \"*/\" (default all *)")],
        states: &[],
        equation: "y = Π u_i^(±1)",
    },
    PrimInfo {
        name: "abs",
        kind: Kind::Abs,
        arity: Arity::One,
        fields: &[],
        options: &[],
        states: &[],
        equation: "y = |u|",
    },
    PrimInfo {
        name: "lag",
        kind: Kind::Lag,
        arity: Arity::One,
        fields: &[
            opt("k", 1.0, Dom::Finite, "gain"),
            req("t", Dom::Positive, "time constant [s]"),
            LIM[0],
            LIM[1],
        ],
        options: &[],
        states: &["x"],
        equation: "T dx/dt = k u − x (non-windup in [min, max]), y = clamp(x)",
    },
    PrimInfo {
        name: "lead_lag",
        kind: Kind::LeadLag,
        arity: Arity::One,
        fields: &[
            opt("k", 1.0, Dom::Finite, "gain"),
            req("t_a", Dom::NonNegative, "lead time constant [s]"),
            req("t_b", Dom::Positive, "lag time constant [s]"),
        ],
        options: &[],
        states: &["x"],
        equation:
            "k (1 + s T_a)/(1 + s T_b): T_b dx/dt = u − x, y = k ((T_a/T_b) u + (1 − T_a/T_b) x)",
    },
    PrimInfo {
        name: "washout",
        kind: Kind::Washout,
        arity: Arity::One,
        fields: &[
            opt("k", 1.0, Dom::Finite, "gain"),
            req("t", Dom::Positive, "time constant [s]"),
        ],
        options: &[],
        states: &["x"],
        equation: "k sT/(1 + sT): T dx/dt = u − x, y = k (u − x)",
    },
    PrimInfo {
        name: "derivative",
        kind: Kind::Derivative,
        arity: Arity::One,
        fields: &[
            opt("k", 1.0, Dom::Finite, "gain [s]"),
            req("t", Dom::Positive, "filter time constant [s]"),
        ],
        options: &[],
        states: &["x"],
        equation: "k s/(1 + sT): T dx/dt = u − x, y = k (u − x)/T",
    },
    PrimInfo {
        name: "integrator",
        kind: Kind::Integrator,
        arity: Arity::One,
        fields: &[
            opt("k", 1.0, Dom::Finite, "gain [1/s]"),
            LIM[0],
            LIM[1],
            GUESS,
            X0,
        ],
        options: &[LIMIT_OPT],
        states: &["x"],
        equation: "dx/dt = k u, y = clamp(x)",
    },
    PrimInfo {
        name: "pi",
        kind: Kind::Pi,
        arity: Arity::One,
        fields: &[
            req("k_p", Dom::Finite, "proportional gain"),
            req("k_i", Dom::Finite, "integral gain [1/s]"),
            LIM[0],
            LIM[1],
            GUESS,
            X0,
        ],
        options: &[LIMIT_OPT],
        states: &["x"],
        equation: "dx/dt = k_i u, y = clamp(k_p u + x)",
    },
    PrimInfo {
        name: "pid",
        kind: Kind::Pid,
        arity: Arity::One,
        fields: &[
            req("k_p", Dom::Finite, "proportional gain"),
            req("k_i", Dom::Finite, "integral gain [1/s]"),
            req("k_d", Dom::Finite, "derivative gain [s]"),
            req("t_d", Dom::Positive, "derivative filter time constant [s]"),
            LIM[0],
            LIM[1],
            GUESS,
            X0,
        ],
        options: &[LIMIT_OPT],
        states: &["i", "d"],
        equation:
            "dx_i/dt = k_i u, T_d dx_d/dt = u − x_d, y = clamp(k_p u + x_i + k_d (u − x_d)/T_d)",
    },
    PrimInfo {
        name: "limiter",
        kind: Kind::Limiter,
        arity: Arity::One,
        fields: &[LIM[0], LIM[1]],
        options: &[],
        states: &[],
        equation: "y = clamp(u)",
    },
    PrimInfo {
        name: "rate_limiter",
        kind: Kind::RateLimiter,
        arity: Arity::One,
        fields: &[
            req("t", Dom::Positive, "tracking time constant [s]"),
            req("rise", Dom::Positive, "largest rate up [1/s]"),
            req("fall", Dom::Positive, "largest rate down [1/s]"),
        ],
        options: &[],
        states: &["x"],
        equation: "dx/dt = clamp((u − x)/T, −fall, rise), y = x",
    },
    PrimInfo {
        name: "deadband",
        kind: Kind::Deadband,
        arity: Arity::One,
        fields: &[req("width", Dom::NonNegative, "half-width of the band")],
        options: &[],
        states: &[],
        equation: "y = 0 for |u| ≤ width, u − width·sign(u) outside",
    },
    PrimInfo {
        name: "min",
        kind: Kind::Min,
        arity: Arity::AtLeast(1),
        fields: &[],
        options: &[],
        states: &[],
        equation: "y = min_i u_i",
    },
    PrimInfo {
        name: "max",
        kind: Kind::Max,
        arity: Arity::AtLeast(1),
        fields: &[],
        options: &[],
        states: &[],
        equation: "y = max_i u_i",
    },
    PrimInfo {
        name: "switch",
        kind: Kind::Switch,
        arity: Arity::Exactly(3),
        fields: &[opt(
            "threshold",
            0.0,
            Dom::Finite,
            "switching threshold on the first input",
        )],
        options: &[],
        states: &[],
        equation: "in = [c, a, b]: y = a if c ≥ threshold, else b",
    },
    PrimInfo {
        name: "pwl",
        kind: Kind::Pwl,
        arity: Arity::One,
        fields: &[],
        options: &[
            ("x", "breakpoints, increasing (numbers or expressions)"),
            ("y", "values at the breakpoints"),
        ],
        states: &[],
        equation: "linear between breakpoints, constant outside",
    },
    PrimInfo {
        name: "pulso",
        kind: Kind::Pulso,
        arity: Arity::OneOrTime,
        fields: &[
            opt("p1", 0.0, Dom::Finite, "lower threshold"),
            opt("p2", 1.0, Dom::Finite, "value between p1 and p3"),
            opt("p3", 1e10, Dom::Finite, "upper threshold"),
            opt("p4", 1.0, Dom::Finite, "value above p3"),
        ],
        options: &[],
        states: &[],
        equation: "y = 0 for u < p1, p2 for p1 < u < p3, p4 otherwise (u = t without an input)",
    },
];

/// Looks a primitive up by name (case-insensitive).
pub fn find(name: &str) -> Option<&'static PrimInfo> {
    PRIMITIVES
        .iter()
        .find(|p| p.name.eq_ignore_ascii_case(name))
}

/// Names of all primitives, for messages.
pub fn names() -> String {
    PRIMITIVES
        .iter()
        .map(|p| p.name)
        .collect::<Vec<_>>()
        .join(", ")
}

impl Kind {
    /// Does the output depend on the inputs in the same instant (algebraic path)?
    pub fn feedthrough(self) -> bool {
        !matches!(
            self,
            Kind::Lag | Kind::Integrator | Kind::RateLimiter | Kind::Initial
        )
    }
    /// In steady state, does the output depend on the inputs?
    pub fn steady_feedthrough(self) -> bool {
        !matches!(self, Kind::Integrator | Kind::Washout | Kind::Derivative)
    }
    /// Does the steady state leave the state free (the input must be zero instead)?
    pub fn integrating(self) -> bool {
        matches!(self, Kind::Integrator | Kind::Pi | Kind::Pid)
    }
    /// Can the initialisation's solve tear a steady-state loop here (no algebraic path, state
    /// or held value determined by the input)?
    pub fn tearable(self) -> bool {
        matches!(self, Kind::Lag | Kind::RateLimiter | Kind::Initial)
    }
    /// Number of states.
    pub fn n_states(self) -> usize {
        match self {
            Kind::Pid => 2,
            Kind::Lag
            | Kind::LeadLag
            | Kind::Washout
            | Kind::Derivative
            | Kind::Integrator
            | Kind::Pi
            | Kind::RateLimiter => 1,
            _ => 0,
        }
    }
}

/// Slots of compiled values `v` per kind (fields in [`PrimInfo::fields`] order, then derived).
pub mod slot {
    pub const K: usize = 0;
    // lag: k, t, min, max, 1/t
    pub const LAG_T: usize = 1;
    pub const LAG_MIN: usize = 2;
    pub const LAG_MAX: usize = 3;
    pub const LAG_INV_T: usize = 4;
    // lead_lag: k, t_a, t_b, t_a/t_b, 1/t_b
    pub const LL_RATIO: usize = 3;
    pub const LL_INV_TB: usize = 4;
    // washout, derivative: k, t, 1/t
    pub const W_INV_T: usize = 2;
    // integrator: k, min, max, guess
    pub const I_MIN: usize = 1;
    pub const I_MAX: usize = 2;
    pub const I_GUESS: usize = 3;
    pub const I_X0: usize = 4;
    // pi: k_p, k_i, min, max, guess
    pub const PI_KI: usize = 1;
    pub const PI_MIN: usize = 2;
    pub const PI_MAX: usize = 3;
    pub const PI_GUESS: usize = 4;
    pub const PI_X0: usize = 5;
    // pid: k_p, k_i, k_d, t_d, min, max, guess, 1/t_d
    pub const PID_KI: usize = 1;
    pub const PID_KD: usize = 2;
    pub const PID_MIN: usize = 4;
    pub const PID_MAX: usize = 5;
    pub const PID_GUESS: usize = 6;
    pub const PID_X0: usize = 7;
    pub const PID_INV_TD: usize = 8;
    // limiter: min, max
    // rate_limiter: t, rise, fall, 1/t
    pub const RL_RISE: usize = 1;
    pub const RL_FALL: usize = 2;
    pub const RL_INV_T: usize = 3;
    // reference: offset, guess, r (solved), initial: held value in 0
    pub const REF_R: usize = 2;
}

/// Number of value slots per node.
pub const NV: usize = 9;

/// A compiled node: kind, wiring into the scratch slots, and its values.
#[derive(Debug, Clone, PartialEq)]
pub struct Node {
    pub kind: Kind,
    /// Scratch slots of the inputs.
    pub ins: Vec<u32>,
    /// Scratch slot of the output.
    pub out: u32,
    /// Offset of the node's states in the diagram's state slice.
    pub x: u32,
    /// Index of the node's non-windup limit (`u32::MAX` when it has none).
    pub lim: u32,
    /// `windup` option of integrator, pi and pid.
    pub windup: bool,
    /// Numeric values (see [`slot`]).
    pub v: [f64; NV],
    /// List values: sum gains, product exponents (±1), pwl breakpoints then values.
    pub list: Vec<f64>,
}

/// Read access to the scratch signals: `f64` in the simulation, dual numbers in a sensitivity
/// pass ([`crate::sens`]).
pub trait Sig<S = f64> {
    fn s(&self, i: u32) -> S;
}

/// A slice of signal values (the sensitivity pass's scratch).
impl<S: Copy> Sig<S> for [S] {
    #[inline(always)]
    fn s(&self, i: u32) -> S {
        self[i as usize]
    }
}

/// The non-windup limits of a kind from its values `v` (±∞ for a kind without limits).
#[inline(always)]
pub fn limits_of<S: Scalar>(kind: Kind, v: &[S]) -> (S, S) {
    use slot::*;
    match kind {
        Kind::Lag => (v[LAG_MIN], v[LAG_MAX]),
        Kind::Integrator => (v[I_MIN], v[I_MAX]),
        Kind::Pi => (v[PI_MIN], v[PI_MAX]),
        Kind::Pid => (v[PID_MIN], v[PID_MAX]),
        Kind::Limiter => (v[0], v[1]),
        _ => (S::cst(f64::NEG_INFINITY), S::cst(f64::INFINITY)),
    }
}

impl Node {
    /// The limits of the node's limited state (or of a `limiter`), ±∞ for other nodes.
    #[inline(always)]
    pub fn limits(&self) -> (f64, f64) {
        limits_of(self.kind, &self.v)
    }

    /// The output at time `t` from the states `x` (the node's slice) and the inputs.
    /// `clamp_states = false` (initialisation's solve) leaves the state clamps out.
    #[inline(always)]
    pub fn output<G: Sig + ?Sized>(&self, t: f64, x: &[f64], s: &G, clamp_states: bool) -> f64 {
        self.output_in(&self.v, &self.list, None, t, x, s, clamp_states)
    }

    /// [`Node::output`] on any [`Scalar`], with the node's values `v` and list values `list`
    /// given (dual numbers in a sensitivity pass). `lim`: the node's non-windup limit, whose
    /// mode gives a `lag`'s or an `integrator`'s clamped output the derivatives of the limit it
    /// is pinned to ([`NonWindup::output`]); `None`: the clamp's active branch (the same value).
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    pub fn output_in<S: Scalar, G: Sig<S> + ?Sized>(
        &self,
        v: &[S],
        list: &[S],
        lim: Option<&NonWindup>,
        t: f64,
        x: &[S],
        s: &G,
        clamp_states: bool,
    ) -> S {
        use slot::*;
        let u = || s.s(self.ins[0]);
        let c = |y: S, lo: S, hi: S| {
            if clamp_states {
                clamp(y, lo, hi)
            } else {
                y
            }
        };
        // A state that is the output itself: under a non-windup limit, the mode's branch.
        let c_state = |y: S, lo: S, hi: S| match (lim, clamp_states) {
            (Some(l), true) => l.output(y, lo, hi),
            _ => c(y, lo, hi),
        };
        match self.kind {
            Kind::Constant => v[0],
            Kind::Reference => v[REF_R] + v[0],
            Kind::Initial => v[0],
            Kind::Time => S::cst(t),
            Kind::Gain => v[K] * u(),
            Kind::Sum => {
                let mut y = S::cst(0.0);
                for (i, &g) in self.ins.iter().zip(list) {
                    y += g * s.s(*i);
                }
                y
            }
            Kind::Product => {
                let mut y = S::cst(1.0);
                for (i, e) in self.ins.iter().zip(list) {
                    if e.val() > 0.0 {
                        y *= s.s(*i);
                    } else {
                        y = y / s.s(*i);
                    }
                }
                y
            }
            Kind::Abs => u().abs(),
            Kind::Lag => c_state(x[0], v[LAG_MIN], v[LAG_MAX]),
            Kind::LeadLag => {
                let r = v[LL_RATIO];
                v[K] * (r * u() + r.rsub(1.0) * x[0])
            }
            Kind::Washout => v[K] * (u() - x[0]),
            Kind::Derivative => v[K] * (u() - x[0]) * v[W_INV_T],
            Kind::Integrator => c_state(x[0], v[I_MIN], v[I_MAX]),
            Kind::Pi => c(v[K] * u() + x[0], v[PI_MIN], v[PI_MAX]),
            Kind::Pid => {
                let u = u();
                c(
                    v[K] * u + x[0] + v[PID_KD] * (u - x[1]) * v[PID_INV_TD],
                    v[PID_MIN],
                    v[PID_MAX],
                )
            }
            Kind::Limiter => c(u(), v[0], v[1]),
            Kind::RateLimiter => x[0],
            Kind::Deadband => {
                let (u, w) = (u(), v[0]);
                if u.val() > w.val() {
                    u - w
                } else if u.val() < -w.val() {
                    u + w
                } else {
                    S::cst(0.0)
                }
            }
            Kind::Min => self
                .ins
                .iter()
                .fold(S::cst(f64::INFINITY), |m, i| m.min_s(s.s(*i))),
            Kind::Max => self
                .ins
                .iter()
                .fold(S::cst(f64::NEG_INFINITY), |m, i| m.max_s(s.s(*i))),
            Kind::Switch => {
                if s.s(self.ins[0]).val() >= v[0].val() {
                    s.s(self.ins[1])
                } else {
                    s.s(self.ins[2])
                }
            }
            Kind::Pwl => {
                let n = list.len() / 2;
                let (xs, ys) = list.split_at(n);
                pwl(xs, ys, u())
            }
            Kind::Pulso => {
                let u = if self.ins.is_empty() { t } else { u().val() };
                let (p1, p2, p3, p4) = (v[0].val(), v[1], v[2].val(), v[3]);
                if u < p1 {
                    S::cst(0.0)
                } else if u > p1 && u < p3 {
                    p2
                } else {
                    p4
                }
            }
        }
    }

    /// The unconstrained derivative of the limited state (the one a non-windup limit freezes).
    #[inline(always)]
    pub fn free_rate<G: Sig + ?Sized>(&self, x: &[f64], s: &G) -> f64 {
        self.free_rate_in(&self.v, x, s)
    }

    /// [`Node::free_rate`] on any [`Scalar`] with the values `v`.
    #[inline(always)]
    pub fn free_rate_in<S: Scalar, G: Sig<S> + ?Sized>(&self, v: &[S], x: &[S], s: &G) -> S {
        use slot::*;
        let u = || s.s(self.ins[0]);
        match self.kind {
            Kind::Lag => (v[K] * u() - x[0]) * v[LAG_INV_T],
            Kind::Integrator => v[K] * u(),
            Kind::Pi => v[PI_KI] * u(),
            Kind::Pid => v[PID_KI] * u(),
            _ => S::cst(0.0),
        }
    }

    /// Writes the derivatives of the node's states; `lim` is its non-windup limit, if any.
    #[inline(always)]
    pub fn derivatives<G: Sig + ?Sized>(
        &self,
        x: &[f64],
        s: &G,
        lim: Option<&NonWindup>,
        dx: &mut [f64],
    ) {
        self.derivatives_in(&self.v, x, s, lim, dx)
    }

    /// [`Node::derivatives`] on any [`Scalar`] with the values `v`.
    #[inline(always)]
    pub fn derivatives_in<S: Scalar, G: Sig<S> + ?Sized>(
        &self,
        v: &[S],
        x: &[S],
        s: &G,
        lim: Option<&NonWindup>,
        dx: &mut [S],
    ) {
        use slot::*;
        let u = || s.s(self.ins[0]);
        match self.kind {
            Kind::Lag | Kind::Integrator | Kind::Pi | Kind::Pid => {
                let f = self.free_rate_in(v, x, s);
                dx[0] = match lim {
                    Some(l) => l.derivative(f),
                    None => f,
                };
                if self.kind == Kind::Pid {
                    dx[1] = (u() - x[1]) * v[PID_INV_TD];
                }
            }
            Kind::LeadLag => dx[0] = (u() - x[0]) * v[LL_INV_TB],
            Kind::Washout | Kind::Derivative => dx[0] = (u() - x[0]) * v[W_INV_T],
            Kind::RateLimiter => dx[0] = clamp((u() - x[0]) * v[RL_INV_T], -v[RL_FALL], v[RL_RISE]),
            _ => {}
        }
    }
}

/// Piecewise-linear interpolation, constant outside `[xs[0], xs[n-1]]` (on dual numbers: the
/// derivatives of the active segment, its breakpoints' included).
#[inline]
pub fn pwl<S: Scalar>(xs: &[S], ys: &[S], u: S) -> S {
    let n = xs.len();
    if n == 0 {
        return S::cst(0.0);
    }
    if u.val() <= xs[0].val() {
        return ys[0];
    }
    if u.val() >= xs[n - 1].val() {
        return ys[n - 1];
    }
    let k = xs.partition_point(|b| b.val() <= u.val()).max(1) - 1;
    let w = (u - xs[k]) / (xs[k + 1] - xs[k]);
    ys[k] + w * (ys[k + 1] - ys[k])
}
