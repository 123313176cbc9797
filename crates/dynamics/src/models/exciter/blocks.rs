//! Small linear blocks shared by the models (lag, lead-lag, washout, limited lead-lag), with PSS/E's and OpenIPSL's handling of
//! zero time constants (`models.md` §8).
//!
//! A time constant counts as zero when it is below [`ZERO_T`] (OpenIPSL compares with the
//! machine epsilon): a lag with `T = 0` passes its input, a lead-lag with `T_B = 0` is bypassed
//! (PSS/E's convention: the lead `T_C` is then ignored). A tiny positive time constant is
//! integrated as given (and makes the system stiff).

use crate::models::limiter::{clamp, NonWindup};
use crate::sens::Scalar;

/// Below this a time constant is zero [s].
pub const ZERO_T: f64 = f64::EPSILON;

/// `1/(1 + sT)` with state `x`: `T dx/dt = u − x`, `y = x`; `T = 0`: `y = u`, state held.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Lag<S = f64> {
    inv_t: S,
    bypass: bool,
}

impl<S: Scalar> Lag<S> {
    pub fn new(t: S) -> Self {
        let bypass = t.val() < ZERO_T;
        Self {
            inv_t: if bypass { S::cst(0.0) } else { t.recip() },
            bypass,
        }
    }
    #[inline(always)]
    pub fn output(&self, x: S, u: S) -> S {
        if self.bypass {
            u
        } else {
            x
        }
    }
    #[inline(always)]
    pub fn derivative(&self, x: S, u: S) -> S {
        (u - x) * self.inv_t
    }
}

/// `(1 + sT_C)/(1 + sT_B)` with state `x`: `T_B dx/dt = u − x`, `y = x + (T_C/T_B)(u − x)`;
/// `T_B = 0`: bypassed, `y = u`, state held. Steady state: `x = u`.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct LeadLag<S = f64> {
    ratio: S,
    inv_tb: S,
    bypass: bool,
}

impl<S: Scalar> LeadLag<S> {
    pub fn new(tc: S, tb: S) -> Self {
        let bypass = tb.val() < ZERO_T;
        Self {
            ratio: if bypass { S::cst(1.0) } else { tc / tb },
            inv_tb: if bypass { S::cst(0.0) } else { tb.recip() },
            bypass,
        }
    }
    #[inline(always)]
    pub fn output(&self, x: S, u: S) -> S {
        if self.bypass {
            u
        } else {
            x + self.ratio * (u - x)
        }
    }
    #[inline(always)]
    pub fn derivative(&self, x: S, u: S) -> S {
        (u - x) * self.inv_tb
    }
}

/// `sT/(1 + sT)` with state `x`: `T dx/dt = u − x`, `y = u − x`; `T = 0`: bypassed, `y = u`
/// (PSS/E's convention for a washout set to zero), state held. Steady state: `x = u`, `y = 0`
/// (`y = u` bypassed).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Washout<S = f64> {
    inv_t: S,
    bypass: bool,
}

impl<S: Scalar> Washout<S> {
    pub fn new(t: S) -> Self {
        let bypass = t.val() < ZERO_T;
        Self {
            inv_t: if bypass { S::cst(0.0) } else { t.recip() },
            bypass,
        }
    }
    #[inline(always)]
    pub fn output(&self, x: S, u: S) -> S {
        if self.bypass {
            u
        } else {
            u - x
        }
    }
    #[inline(always)]
    pub fn derivative(&self, x: S, u: S) -> S {
        (u - x) * self.inv_t
    }
}

/// A lead-lag with a non-windup limit on its output, as OpenIPSL's `LeadLagLim`:
///
/// ```text
/// w = x + (T_C/T_B)(u − x),   y = clamp(w, lo, hi)
/// T_C dx/dt = y − x            (= (u − x)/T_B while w is inside the limits)
/// ```
///
/// While the output is limited the state is driven toward the limit with time constant `T_C`
/// (it evolves as if the input were reduced to just hold the output on the limit), so it never
/// winds up beyond it; the right-hand side is continuous, the output has a kink at the limit.
/// `T_C = 0` (a pure lag): the non-windup lag of [`NonWindup`], the state frozen on the limit
/// while pushing outwards, with event-located modes. `T_B = 0`: bypassed, `y = clamp(u)`.
///
/// On the number type `S` (`f64`, or a dual for forward sensitivities). The `T_C = 0` form's mode
/// is the caller's (`*_in` methods): a block keeps its modes apart from its numbers, so that its
/// dual equations follow the plain simulation's modes, and the mode has one home.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct LeadLagLim<S = f64> {
    ll: LeadLag<S>,
    inv_tc: S,
    lo: S,
    hi: S,
    pure_lag: bool,
}

impl<S: Scalar> LeadLagLim<S> {
    pub fn new(tc: S, tb: S, lo: S, hi: S) -> Self {
        let ll = LeadLag::new(tc, tb);
        let pure_lag = !ll.bypass && tc.val() < ZERO_T;
        Self {
            ll,
            inv_tc: if tc.val() < ZERO_T {
                S::cst(0.0)
            } else {
                tc.recip()
            },
            lo,
            hi,
            pure_lag,
        }
    }
    /// The output `y` in the mode `limit` (of the `T_C = 0` form). While free, that form's
    /// output is the state's (its value clamped: see [`NonWindup::output`]).
    #[inline(always)]
    pub fn output_in(&self, limit: &NonWindup, x: S, u: S) -> S {
        if self.pure_lag {
            match limit.mode {
                crate::models::limiter::LimitMode::AtMax => self.hi,
                crate::models::limiter::LimitMode::AtMin => self.lo,
                crate::models::limiter::LimitMode::Free => {
                    x.with_value(clamp(x.val(), self.lo.val(), self.hi.val()))
                }
            }
        } else {
            clamp(self.ll.output(x, u), self.lo, self.hi)
        }
    }
    /// The state's derivative in the mode `limit`.
    #[inline(always)]
    pub fn derivative_in(&self, limit: &NonWindup, x: S, u: S) -> S {
        if self.ll.bypass {
            S::cst(0.0)
        } else if self.pure_lag {
            limit.derivative(self.ll.derivative(x, u))
        } else {
            (clamp(self.ll.output(x, u), self.lo, self.hi) - x) * self.inv_tc
        }
    }
    /// Two event functions in the mode `limit` (constant 1 unless `T_C = 0`).
    #[inline]
    pub fn events_in(&self, limit: &NonWindup, x: S, u: S, g: &mut [S]) {
        if self.pure_lag {
            limit.events(x, self.ll.derivative(x, u), self.lo, self.hi, g);
        } else {
            g[0] = S::cst(1.0);
            g[1] = S::cst(1.0);
        }
    }
    /// A state the mode `limit` pins (`T_C = 0` form) takes the limit's value and derivatives
    /// ([`NonWindup::pin`]).
    #[inline]
    pub fn pin_in(&self, limit: &NonWindup, x: &mut S) {
        if self.pure_lag {
            limit.pin(x, self.lo, self.hi);
        }
    }
}

impl LeadLagLim {
    /// Update of the `T_C = 0` form's mode `limit` (may pin `x` on a limit).
    pub fn update_in(&self, limit: &mut NonWindup, x: &mut f64, u: f64) -> bool {
        if self.pure_lag {
            let f = self.ll.derivative(*x, u);
            limit.update(x, f, self.lo, self.hi)
        } else {
            false
        }
    }
}

/// PSS/E's quadratic exciter saturation (`SE` in OpenIPSL, `ExcQuadSat` in ANDES): the
/// saturation factor `S_E(E) = B (E − A)²/E` for `E > A`, else 0, through the two points
/// `S_E(E_1) = SE_1`, `S_E(E_2) = SE_2`:
///
/// ```text
/// a = sqrt(SE_1 E_1 / (SE_2 E_2)),   A = E_2 − (E_1 − E_2)/(a − 1),   B = SE_2 E_2 (a − 1)²/(E_1 − E_2)²
/// ```
///
/// `SE_1 = 0` or `SE_2 = 0` (or `E_1 = E_2`) switches saturation off, as in OpenIPSL.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct QuadraticExciterSaturation<S = f64> {
    a: S,
    b: S,
}

impl<S: Scalar> QuadraticExciterSaturation<S> {
    /// Fits the curve; an error (the offending pair of parameter names and a message) when the
    /// two points admit no such curve (`SE_1 E_1 = SE_2 E_2 ≠ 0`, or negative data).
    pub fn new(e1: S, se1: S, e2: S, se2: S) -> Result<Self, (&'static str, String)> {
        for (n, v) in [("e1", e1), ("se1", se1), ("e2", e2), ("se2", se2)] {
            let v = v.val();
            if !(v.is_finite() && v >= 0.0) {
                return Err((n, format!("must be finite and >= 0 (got {v})")));
            }
        }
        if se1.val() == 0.0 || se2.val() == 0.0 || e1.val() == e2.val() {
            return Ok(Self {
                a: S::cst(0.0),
                b: S::cst(0.0),
            });
        }
        let r = (se1 * e1 / (se2 * e2)).sqrt();
        if (r.val() - 1.0).abs() < 1e-12 {
            return Err((
                "se2",
                format!(
                    "SE(E1)·E1 = SE(E2)·E2 = {:.6}: no quadratic saturation curve passes through both points",
                    se1.val() * e1.val()
                ),
            ));
        }
        let a = e2 - (e1 - e2) / (r - 1.0);
        let b = se2 * e2 * (r - 1.0).powi(2) / (e1 - e2).powi(2);
        Ok(Self { a, b })
    }
    /// `S_E(E)·E = B (E − A)²` for `E > max(A, 0)`, else 0: the saturation term the exciter
    /// subtracts.
    #[inline(always)]
    pub fn times_e(&self, e: S) -> S {
        if self.b.val() == 0.0 || e.val() <= 0.0 || e.val() <= self.a.val() {
            S::cst(0.0)
        } else {
            self.b * (e - self.a) * (e - self.a)
        }
    }
    /// The saturation factor `S_E(E)`.
    pub fn factor(&self, e: S) -> S {
        if e.val() <= 0.0 {
            S::cst(0.0)
        } else {
            self.times_e(e) / e
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn zero_time_constants_pass_the_input() {
        let lag = Lag::new(0.0);
        assert_eq!(lag.output(0.3, 0.7), 0.7);
        let ll = LeadLag::new(2.0, 0.0);
        assert_eq!((ll.output(0.3, 0.7), ll.derivative(0.3, 0.7)), (0.7, 0.0));
        let lim = LeadLagLim::new(2.0, 0.0, -1.0, 0.5);
        assert_eq!(lim.output_in(&NonWindup::default(), 0.3, 0.7), 0.5);
        // T_C = 0: a lag, y = x.
        let ll = LeadLag::new(0.0, 2.0);
        assert_eq!(ll.output(0.3, 0.7), 0.3);
        assert!((ll.derivative(0.3, 0.7) - 0.2).abs() < 1e-15);
    }

    #[test]
    fn the_quadratic_saturation_passes_through_its_two_points() {
        let s = QuadraticExciterSaturation::new(2.85, 0.3, 3.8, 0.6).unwrap();
        assert!((s.factor(2.85) - 0.3).abs() < 1e-12);
        assert!((s.factor(3.8) - 0.6).abs() < 1e-12);
        assert_eq!(s.factor(0.5), 0.0);
        let off = QuadraticExciterSaturation::new(2.85, 0.0, 3.8, 0.6).unwrap();
        assert_eq!(off.times_e(5.0), 0.0);
        assert!(QuadraticExciterSaturation::new(2.0, 0.5, 1.0, 1.0).is_err());
    }

    #[test]
    fn a_limited_lead_lag_drives_its_state_to_the_limit_with_t_c() {
        let b = LeadLagLim::new(1.0, 4.0, -1.0, 1.0);
        let free = NonWindup::default();
        // Free: (u − x)/T_B.
        assert!((b.derivative_in(&free, 0.0, 0.8) - 0.2).abs() < 1e-15);
        assert!((b.output_in(&free, 0.0, 0.8) - 0.2).abs() < 1e-15);
        // w = 0.5 + 0.25·(9.5) = 2.875 > 1: y = 1, dx/dt = (1 − 0.5)/T_C.
        assert_eq!(b.output_in(&free, 0.5, 10.0), 1.0);
        assert!((b.derivative_in(&free, 0.5, 10.0) - 0.5).abs() < 1e-15);
        // On the limit with x = hi the state stays (no windup).
        assert_eq!(b.derivative_in(&free, 1.0, 10.0), 0.0);
    }
}
