//! Saturation functions of the PSS/E machines (reference `models.md` §2).
//!
//! Both return the saturation **factor** `Se(ψ)`; the extra field current is `Se·ψ`-like (see
//! each machine). Saturation points are E1 = 1.0 pu and E2 = 1.2 pu, with `Se(1.0) = S10` and
//! `Se(1.2) = S12`.

use crate::block::ModelError;
use crate::sens::Scalar;

/// Quadratic saturation (GENSAL, GENROU; OpenIPSL `SE.mo`):
///
/// ```text
/// a = sqrt(S10 / (1.2 S12)),  A = 1.2 + 0.2/(a − 1),  B = 1.2 S12 (a − 1)² / 0.04
/// Se(ψ) = B (ψ − A)² / ψ  for ψ > A,   0 otherwise (and 0 when S10 = 0 or S12 = 0)
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct QuadraticSaturation<S = f64> {
    knee: S,
    b: S,
    active: bool,
}

impl<S: Scalar> QuadraticSaturation<S> {
    pub fn new(s10: S, s12: S) -> Result<Self, ModelError> {
        let (s10v, s12v) = (s10.val(), s12.val());
        if s10v < 0.0 || s12v < 0.0 || !s10v.is_finite() || !s12v.is_finite() {
            return Err(ModelError::param(
                "s10",
                format!("S10 = {s10v} and S12 = {s12v} must be finite and >= 0"),
            ));
        }
        if s10v == 0.0 || s12v == 0.0 {
            return Ok(Self {
                knee: S::cst(0.0),
                b: S::cst(0.0),
                active: false,
            });
        }
        // A sensible curve needs S12 > S10/1.2 (then a < 1 and the knee lies below 1 pu).
        if 1.2 * s12v <= s10v {
            return Err(ModelError::param(
                "s12",
                format!("quadratic saturation needs S12 > S10/1.2 (S10 = {s10v}, S12 = {s12v})"),
            ));
        }
        let a = (s10 / (s12 * 1.2)).sqrt();
        let knee = (a - 1.0).rdiv(0.2) + 1.2;
        let b = s12 * 1.2 * (a - 1.0).powi(2) / 0.04;
        Ok(Self {
            knee,
            b,
            active: true,
        })
    }

    #[inline]
    pub fn eval(&self, psi: S) -> S {
        if !self.active || psi.val() <= 0.0 || psi.val() <= self.knee.val() {
            S::cst(0.0)
        } else {
            self.b * (psi - self.knee).powi(2) / psi
        }
    }
}

/// Exponential saturation (GENSAE, GENROE; OpenIPSL `SE_exp.mo`):
///
/// ```text
/// n = ln(S12/S10) / ln(1.2),   Se(ψ) = S10 · ψⁿ      (0 when ψ <= 0 or S10 = 0)
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ExponentialSaturation<S = f64> {
    s10: S,
    n: S,
}

impl<S: Scalar> ExponentialSaturation<S> {
    pub fn new(s10: S, s12: S) -> Result<Self, ModelError> {
        let (s10v, s12v) = (s10.val(), s12.val());
        if s10v < 0.0 || s12v < 0.0 || !s10v.is_finite() || !s12v.is_finite() {
            return Err(ModelError::param(
                "s10",
                format!("S10 = {s10v} and S12 = {s12v} must be finite and >= 0"),
            ));
        }
        if s10v == 0.0 {
            return Ok(Self {
                s10: S::cst(0.0),
                n: S::cst(0.0),
            });
        }
        if s12v == 0.0 {
            return Err(ModelError::param(
                "s12",
                "exponential saturation needs S12 > 0 when S10 > 0",
            ));
        }
        Ok(Self {
            s10,
            n: (s12 / s10).ln() / 1.2f64.ln(),
        })
    }

    #[inline]
    pub fn eval(&self, psi: S) -> S {
        if self.s10.val() == 0.0 || psi.val() <= 0.0 {
            S::cst(0.0)
        } else {
            // S10·ψⁿ as exp(n ln ψ): same value to rounding, cheaper than powf.
            self.s10 * (self.n * psi.ln()).exp()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quadratic_hits_both_points() {
        let s = QuadraticSaturation::new(0.1, 0.3).unwrap();
        assert!((s.eval(1.0) - 0.1).abs() < 1e-12);
        assert!((s.eval(1.2) - 0.3).abs() < 1e-12);
        assert_eq!(s.eval(0.5), 0.0);
        assert!(QuadraticSaturation::new(0.36, 0.3).is_err());
        assert_eq!(QuadraticSaturation::new(0.0, 1.0).unwrap().eval(1.3), 0.0);
    }

    #[test]
    fn exponential_hits_both_points() {
        let s = ExponentialSaturation::new(0.1, 0.3).unwrap();
        assert!((s.eval(1.0) - 0.1).abs() < 1e-12);
        assert!((s.eval(1.2) - 0.3).abs() < 1e-12);
        assert_eq!(s.eval(0.0), 0.0);
        assert!(ExponentialSaturation::new(0.1, 0.0).is_err());
    }
}
