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
    pub fn derivative(&self, f: f64) -> f64 {
        match self.mode {
            LimitMode::Free => f,
            _ => 0.0,
        }
    }

    /// The two event functions (positive while the mode holds).
    #[inline]
    pub fn events(&self, x: f64, f: f64, lo: f64, hi: f64, g: &mut [f64]) {
        match self.mode {
            LimitMode::Free => {
                g[0] = hi - x;
                g[1] = x - lo;
            }
            LimitMode::AtMax => {
                g[0] = f;
                g[1] = 1.0;
            }
            LimitMode::AtMin => {
                g[0] = -f;
                g[1] = 1.0;
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
            LimitMode::Free => *x = x.clamp(lo, hi),
        }
        (self.mode, *x) != old
    }
}

/// Clamp that tolerates `lo > hi` by returning `lo` (never panics).
#[inline(always)]
pub fn clamp(v: f64, lo: f64, hi: f64) -> f64 {
    if v > hi {
        hi
    } else if v < lo {
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
}
