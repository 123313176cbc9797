//! Non-windup (anti-windup) limits on an integrating state, with discrete modes.
//!
//! A state `x` with unconstrained derivative `f` and limits `[lo, hi]` behaves as
//! (reference `models.md` §8, "freeze the derivative" logic):
//!
//! ```text
//! Free:   dx/dt = f            leaves when x reaches hi (→ AtMax) or lo (→ AtMin)
//! AtMax:  dx/dt = 0, x = hi    leaves when f < 0
//! AtMin:  dx/dt = 0, x = lo    leaves when f > 0
//! ```
//!
//! The mode is frozen during an integration step; the integrator locates the sign change of the
//! event function (positive while the mode holds) and calls [`NonWindup::update`] there, which
//! pins the state exactly on the limit. No overshoot, no chattering.

use crate::sens::Scalar;

/// Relative distance from a limit within which a state counts as on it at an event.
pub const AT_LIMIT_TOL: f64 = 1e-7;

/// Mode of a non-windup limit.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum LimitMode {
    #[default]
    Free,
    AtMax,
    AtMin,
}

/// A non-windup limit on one state.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct NonWindup {
    pub mode: LimitMode,
}

impl NonWindup {
    /// Derivative under the current mode, given the unconstrained derivative `f`.
    #[inline(always)]
    pub fn derivative<S: Scalar>(&self, f: S) -> S {
        match self.mode {
            LimitMode::Free => f,
            _ => S::cst(0.0),
        }
    }

    /// The output of a state under a constant non-windup limit: `clamp(x, lo, hi)` in value,
    /// with the derivatives of the mode's branch. While free the state is inside its limits by
    /// construction (the mode pins it at a crossing), so the clamp only guards the value against
    /// an integrator stage a hair beyond the limit; the derivative stays that of `x`. (Taking
    /// the clamp's branch there would drop `∂x/∂p` for that stage alone, an O(1) error in the
    /// stage times the step: 1 % of the sensitivities after a ceiling is reached, measured.)
    #[inline(always)]
    pub fn output<S: Scalar>(&self, x: S, lo: S, hi: S) -> S {
        match self.mode {
            LimitMode::Free => x.with_value(clamp(x.val(), lo.val(), hi.val())),
            LimitMode::AtMax => hi.with_value(clamp(x.val(), lo.val(), hi.val())),
            LimitMode::AtMin => lo.with_value(clamp(x.val(), lo.val(), hi.val())),
        }
    }

    /// A state pinned by the current mode takes the limit's value and derivatives (a
    /// sensitivity pass, after [`NonWindup::update`] pinned its value).
    #[inline]
    pub fn pin<S: Scalar>(&self, x: &mut S, lo: S, hi: S) {
        match self.mode {
            LimitMode::Free => {}
            LimitMode::AtMax => *x = hi,
            LimitMode::AtMin => *x = lo,
        }
    }

    /// The two event functions (positive while the mode holds); on dual numbers, their
    /// derivatives too (the crossing time's, [`crate::sens`]).
    #[inline]
    pub fn events<S: Scalar>(&self, x: S, f: S, lo: S, hi: S, g: &mut [S]) {
        match self.mode {
            LimitMode::Free => {
                g[0] = hi - x;
                g[1] = x - lo;
            }
            LimitMode::AtMax => {
                g[0] = f;
                g[1] = S::cst(1.0);
            }
            LimitMode::AtMin => {
                g[0] = -f;
                g[1] = S::cst(1.0);
            }
        }
    }

    /// Re-evaluates the mode at the current point and pins `x` when a limit is active.
    /// Returns `true` when the mode or `x` changed.
    ///
    /// The integrator locates a crossing to within ~1e-12 s, so at an event `x` may sit a hair
    /// short of the limit: within [`AT_LIMIT_TOL`] (relative) it counts as on the limit.
    pub fn update(&mut self, x: &mut f64, f: f64, lo: f64, hi: f64) -> bool {
        let old = (self.mode, *x);
        let tol_hi = AT_LIMIT_TOL * hi.abs().max(1.0);
        let tol_lo = AT_LIMIT_TOL * lo.abs().max(1.0);
        self.mode = if *x >= hi - tol_hi && f > 0.0 {
            LimitMode::AtMax
        } else if *x <= lo + tol_lo && f < 0.0 {
            LimitMode::AtMin
        } else {
            LimitMode::Free
        };
        match self.mode {
            LimitMode::AtMax => *x = hi,
            LimitMode::AtMin => *x = lo,
            // `clamp` below, not `f64::clamp`: a trial stage of the integrator may hand in
            // limits computed from non-finite signals (NaN), which must not panic.
            LimitMode::Free => *x = clamp(*x, lo, hi),
        }
        (self.mode, *x) != old
    }
}

/// Non-windup limits that move with time (`lo(t)`, `hi(t)` computed from signals, e.g. a
/// bus-fed exciter ceiling `V_t·V_RMAX − K_C·X_adI_fd`, `models.md` §12.3).
///
/// The same three modes as [`NonWindup`], with these changes, because a pinned state must follow
/// a limit that moves and the derivative of the limit is not available:
///
/// ```text
/// effective state  x_eff = hi (AtMax), lo (AtMin), x (Free)   → used for the output and for f
/// Free:   dx/dt = f                 event g0 = max(hi − x, −f), g1 = max(x − lo, f)
/// AtMax:  dx/dt = (hi − x)/T_track  event g0 = f(x_eff = hi)   (leave when it pulls back inside)
/// AtMin:  dx/dt = (lo − x)/T_track  event g0 = −f(x_eff = lo)
/// ```
///
/// While pinned, the block uses `x_eff = hi(t)` exactly; the stored state only tracks it (with
/// the block's own time constant `T_track`, so that traces of the state stay meaningful) and is
/// projected onto the limit at every mode change. With constant limits the stored state sits
/// exactly on the limit and `dx/dt = 0`, as for [`NonWindup`]. In Free mode the guard
/// `max(hi − x, −f)` only fires when the state is at or above the ceiling *and* pushing
/// outwards: when the ceiling drops faster than the state decays (`x > hi`, `f < 0`), the output
/// is clamped to `hi` and the state is pinned as soon as it pushes outwards again (no upward
/// windup, and no event that starts at a zero guard and could never be detected).
impl NonWindup {
    /// The state the block must use (`hi`/`lo` while pinned).
    #[inline(always)]
    pub fn effective<S: Scalar>(&self, x: S, lo: S, hi: S) -> S {
        match self.mode {
            LimitMode::Free => x,
            LimitMode::AtMax => hi,
            LimitMode::AtMin => lo,
        }
    }

    /// The limit the current mode pins the state to (`None` while free): with moving limits,
    /// the value a mode change projects the stored state onto ([`Block::moving_pins`]).
    ///
    /// [`Block::moving_pins`]: crate::block::Block::moving_pins
    #[inline]
    pub fn pinned_to<S: Scalar>(&self, lo: S, hi: S) -> Option<S> {
        match self.mode {
            LimitMode::Free => None,
            LimitMode::AtMax => Some(hi),
            LimitMode::AtMin => Some(lo),
        }
    }

    /// Derivative of the stored state with moving limits (`inv_t_track` = 1/T_track).
    #[inline(always)]
    pub fn derivative_moving<S: Scalar>(&self, f: S, x: S, lo: S, hi: S, inv_t_track: S) -> S {
        match self.mode {
            LimitMode::Free => f,
            LimitMode::AtMax => (hi - x) * inv_t_track,
            LimitMode::AtMin => (lo - x) * inv_t_track,
        }
    }

    /// Event functions with moving limits; `f` is the unconstrained derivative at the effective
    /// state.
    #[inline]
    pub fn events_moving<S: Scalar>(&self, x: S, f: S, lo: S, hi: S, g: &mut [S]) {
        match self.mode {
            LimitMode::Free => {
                g[0] = (hi - x).max_s(-f);
                g[1] = (x - lo).max_s(f);
            }
            _ => self.events(x, f, lo, hi, g),
        }
    }

    /// Mode update with moving limits: projects a pinned state onto its (moved) limit, then
    /// re-evaluates as [`NonWindup::update`] with `f = rate(x)`. Returns `true` on any change.
    pub fn update_moving(
        &mut self,
        x: &mut f64,
        rate: impl Fn(f64) -> f64,
        lo: f64,
        hi: f64,
    ) -> bool {
        let old = (self.mode, *x);
        *x = self.effective(*x, lo, hi);
        let f = rate(*x);
        self.update(x, f, lo, hi);
        (self.mode, *x) != old
    }
}

/// Clamp that never panics: `lo > hi` gives `hi` for `v > hi`, else `lo` for `v < lo`; a NaN
/// limit is ignored (comparisons with NaN are false) and a NaN `v` stays NaN.
#[inline(always)]
pub fn clamp<S: Scalar>(v: S, lo: S, hi: S) -> S {
    if v.val() > hi.val() {
        hi
    } else if v.val() < lo.val() {
        lo
    } else {
        v
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pins_and_releases() {
        let mut l = NonWindup::default();
        let mut x = 5.2;
        assert!(l.update(&mut x, 1.0, 0.0, 5.0));
        assert_eq!((l.mode, x), (LimitMode::AtMax, 5.0));
        assert_eq!(l.derivative(3.0), 0.0);
        let mut g = [0.0; 2];
        l.events(x, -0.1, 0.0, 5.0, &mut g);
        assert!(g[0] < 0.0, "pulling back inside must trigger the event");
        assert!(l.update(&mut x, -0.1, 0.0, 5.0));
        assert_eq!(l.mode, LimitMode::Free);
        assert_eq!(l.derivative(-0.1), -0.1);
    }

    #[test]
    fn an_event_located_a_hair_before_the_limit_still_pins() {
        let mut l = NonWindup::default();
        let mut x = 5.0 - 1e-10;
        assert!(l.update(&mut x, 2.0, 0.0, 5.0));
        assert_eq!((l.mode, x), (LimitMode::AtMax, 5.0));
        let mut y = 4.99;
        assert!(!l.clone().update(&mut y, 2.0, 0.0, 5.0) || y == 4.99);
    }

    #[test]
    fn moving_limit_pins_to_the_current_ceiling_and_releases_there() {
        let mut l = NonWindup::default();
        let mut x = 4.0;
        // Reaching a ceiling of 4 while pushing up: pinned.
        assert!(l.update_moving(&mut x, |_| 1.0, 0.0, 4.0));
        assert_eq!(l.mode, LimitMode::AtMax);
        // The ceiling drops to 3: the block uses 3 at once; the stored state tracks it.
        assert_eq!(l.effective(x, 0.0, 3.0), 3.0);
        assert_eq!(l.derivative_moving(1.0, x, 0.0, 3.0, 20.0), -20.0);
        // Pulling back inside releases from the moved ceiling, not from the stale state.
        assert!(l.update_moving(&mut x, |xe| 2.5 - xe, 0.0, 3.0));
        assert_eq!((l.mode, x), (LimitMode::Free, 3.0));
        // Free above a ceiling that fell faster than the state: guard positive while f < 0,
        // crosses when the state pushes outwards again.
        let mut g = [0.0; 2];
        l.events_moving(3.2, -0.5, 0.0, 3.0, &mut g);
        assert!(g[0] > 0.0 && g[1] > 0.0);
        l.events_moving(3.2, 0.5, 0.0, 3.0, &mut g);
        assert!(g[0] <= 0.0);
        // Constant limits: the pinned state sits on the limit and does not move.
        let mut c = NonWindup::default();
        let mut y = 5.0;
        c.update_moving(&mut y, |_| 1.0, 0.0, 5.0);
        assert_eq!(c.derivative_moving(1.0, y, 0.0, 5.0, 20.0), 0.0);
    }
}
