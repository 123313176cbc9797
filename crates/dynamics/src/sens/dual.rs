//! Forward-mode dual numbers and the [`Scalar`] trait the models are written against.
//!
//! `Dual<N> = v + Σ_k d_k ε_k` with `ε_j ε_k = 0`: every arithmetic operation carries the value
//! `v` and its derivatives `d_k = ∂v/∂p_k` along `N` seeded directions (tangent lanes). A model
//! written once for any `S: Scalar` runs on `f64` (the simulation) and on `Dual<N>` (the
//! simulation and the exact derivatives of everything it computes with respect to the seeded
//! parameters and states, to rounding). The value part of every operation is the same `f64`
//! expression as the plain simulation's, so a dual run's values are the plain run's.

use std::fmt::Debug;
use std::ops::{Add, AddAssign, Div, Mul, MulAssign, Neg, Sub, SubAssign};

/// The number type of a model's right-hand side: `f64`, or a [`Dual`] carrying derivatives.
///
/// Generic model code writes constants on the right (`x * 2.0`, not `2.0 * x`) or lifts them
/// with [`Scalar::cst`]; branches test [`Scalar::val`] (the derivative of a piecewise function is
/// the derivative of the active branch).
pub trait Scalar:
    Copy
    + Debug
    + Default
    + PartialEq
    + Send
    + Sync
    + 'static
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
    + Add<f64, Output = Self>
    + Sub<f64, Output = Self>
    + Mul<f64, Output = Self>
    + Div<f64, Output = Self>
    + AddAssign
    + SubAssign
    + MulAssign
{
    /// A constant (zero derivatives).
    fn cst(v: f64) -> Self;
    /// The value.
    fn val(self) -> f64;
    fn sqrt(self) -> Self;
    fn sin_cos(self) -> (Self, Self);
    fn exp(self) -> Self;
    fn ln(self) -> Self;
    fn powi(self, n: i32) -> Self;
    /// `self^e` for a constant exponent.
    fn powf(self, e: f64) -> Self;
    /// `self.atan2(x)`: the angle of `(x, self)`.
    fn atan2(self, x: Self) -> Self;
    fn abs(self) -> Self;
    fn recip(self) -> Self;
    fn tanh(self) -> Self;
    /// The smaller by value (the derivative of the smaller; a NaN loses, as in `f64::min`).
    #[inline(always)]
    fn min_s(self, o: Self) -> Self {
        if o.val() < self.val() || self.val().is_nan() {
            o
        } else {
            self
        }
    }
    /// The larger by value (the derivative of the larger; a NaN loses, as in `f64::max`).
    #[inline(always)]
    fn max_s(self, o: Self) -> Self {
        if o.val() > self.val() || self.val().is_nan() {
            o
        } else {
            self
        }
    }
    /// `c − self` for a constant `c`.
    #[inline(always)]
    fn rsub(self, c: f64) -> Self {
        -self + c
    }
    /// The value `v` with this number's derivatives (a safety clamp on the value that must
    /// not switch the branch the derivative follows).
    fn with_value(self, v: f64) -> Self;
    /// `c / self` for a constant `c`.
    #[inline(always)]
    fn rdiv(self, c: f64) -> Self {
        self.recip() * c
    }
}

impl Scalar for f64 {
    #[inline(always)]
    fn cst(v: f64) -> Self {
        v
    }
    #[inline(always)]
    fn val(self) -> f64 {
        self
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        f64::sqrt(self)
    }
    #[inline(always)]
    fn sin_cos(self) -> (Self, Self) {
        f64::sin_cos(self)
    }
    #[inline(always)]
    fn exp(self) -> Self {
        f64::exp(self)
    }
    #[inline(always)]
    fn ln(self) -> Self {
        f64::ln(self)
    }
    #[inline(always)]
    fn powi(self, n: i32) -> Self {
        f64::powi(self, n)
    }
    #[inline(always)]
    fn powf(self, e: f64) -> Self {
        f64::powf(self, e)
    }
    #[inline(always)]
    fn atan2(self, x: Self) -> Self {
        f64::atan2(self, x)
    }
    #[inline(always)]
    fn abs(self) -> Self {
        f64::abs(self)
    }
    #[inline(always)]
    fn recip(self) -> Self {
        1.0 / self
    }
    #[inline(always)]
    fn tanh(self) -> Self {
        f64::tanh(self)
    }
    #[inline(always)]
    fn min_s(self, o: Self) -> Self {
        f64::min(self, o)
    }
    #[inline(always)]
    fn max_s(self, o: Self) -> Self {
        f64::max(self, o)
    }
    #[inline(always)]
    fn rsub(self, c: f64) -> Self {
        c - self
    }
    #[inline(always)]
    fn with_value(self, v: f64) -> Self {
        v
    }
    #[inline(always)]
    fn rdiv(self, c: f64) -> Self {
        c / self
    }
}

/// A value with its derivatives along `N` tangent lanes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Dual<const N: usize> {
    /// The value.
    pub v: f64,
    /// `∂v/∂(lane k)`.
    pub d: [f64; N],
}

impl<const N: usize> Default for Dual<N> {
    fn default() -> Self {
        Self::cst(0.0)
    }
}

impl<const N: usize> Dual<N> {
    /// The variable of lane `k` at value `v` (derivative 1 along lane `k`).
    pub fn var(v: f64, k: usize) -> Self {
        let mut d = [0.0; N];
        d[k] = 1.0;
        Self { v, d }
    }
    /// The value `v` with the tangent `d`.
    #[inline(always)]
    pub fn new(v: f64, d: [f64; N]) -> Self {
        Self { v, d }
    }
    /// The chain rule for a scalar function with value `f` and slope `df` at `self.v`.
    #[inline(always)]
    fn chain(self, f: f64, df: f64) -> Self {
        Self {
            v: f,
            d: self.d.map(|x| x * df),
        }
    }
}

impl<const N: usize> Add for Dual<N> {
    type Output = Self;
    #[inline(always)]
    fn add(self, o: Self) -> Self {
        Self {
            v: self.v + o.v,
            d: std::array::from_fn(|k| self.d[k] + o.d[k]),
        }
    }
}
impl<const N: usize> Sub for Dual<N> {
    type Output = Self;
    #[inline(always)]
    fn sub(self, o: Self) -> Self {
        Self {
            v: self.v - o.v,
            d: std::array::from_fn(|k| self.d[k] - o.d[k]),
        }
    }
}
impl<const N: usize> Mul for Dual<N> {
    type Output = Self;
    #[inline(always)]
    #[allow(clippy::suspicious_arithmetic_impl)] // the product rule: d(uv) = u'v + uv'
    fn mul(self, o: Self) -> Self {
        Self {
            v: self.v * o.v,
            d: std::array::from_fn(|k| self.d[k] * o.v + self.v * o.d[k]),
        }
    }
}
impl<const N: usize> Div for Dual<N> {
    type Output = Self;
    #[inline(always)]
    fn div(self, o: Self) -> Self {
        let inv = 1.0 / o.v;
        let v = self.v / o.v;
        Self {
            v,
            d: std::array::from_fn(|k| (self.d[k] - v * o.d[k]) * inv),
        }
    }
}
impl<const N: usize> Neg for Dual<N> {
    type Output = Self;
    #[inline(always)]
    fn neg(self) -> Self {
        Self {
            v: -self.v,
            d: self.d.map(|x| -x),
        }
    }
}
impl<const N: usize> Add<f64> for Dual<N> {
    type Output = Self;
    #[inline(always)]
    fn add(self, c: f64) -> Self {
        Self {
            v: self.v + c,
            d: self.d,
        }
    }
}
impl<const N: usize> Sub<f64> for Dual<N> {
    type Output = Self;
    #[inline(always)]
    fn sub(self, c: f64) -> Self {
        Self {
            v: self.v - c,
            d: self.d,
        }
    }
}
impl<const N: usize> Mul<f64> for Dual<N> {
    type Output = Self;
    #[inline(always)]
    fn mul(self, c: f64) -> Self {
        Self {
            v: self.v * c,
            d: self.d.map(|x| x * c),
        }
    }
}
impl<const N: usize> Div<f64> for Dual<N> {
    type Output = Self;
    #[inline(always)]
    fn div(self, c: f64) -> Self {
        Self {
            v: self.v / c,
            d: self.d.map(|x| x / c),
        }
    }
}
impl<const N: usize> Add<Dual<N>> for f64 {
    type Output = Dual<N>;
    #[inline(always)]
    fn add(self, o: Dual<N>) -> Dual<N> {
        o + self
    }
}
impl<const N: usize> Sub<Dual<N>> for f64 {
    type Output = Dual<N>;
    #[inline(always)]
    fn sub(self, o: Dual<N>) -> Dual<N> {
        o.rsub(self)
    }
}
impl<const N: usize> Mul<Dual<N>> for f64 {
    type Output = Dual<N>;
    #[inline(always)]
    fn mul(self, o: Dual<N>) -> Dual<N> {
        o * self
    }
}
impl<const N: usize> Div<Dual<N>> for f64 {
    type Output = Dual<N>;
    #[inline(always)]
    fn div(self, o: Dual<N>) -> Dual<N> {
        o.rdiv(self)
    }
}
impl<const N: usize> AddAssign for Dual<N> {
    #[inline(always)]
    fn add_assign(&mut self, o: Self) {
        *self = *self + o;
    }
}
impl<const N: usize> SubAssign for Dual<N> {
    #[inline(always)]
    fn sub_assign(&mut self, o: Self) {
        *self = *self - o;
    }
}
impl<const N: usize> MulAssign for Dual<N> {
    #[inline(always)]
    fn mul_assign(&mut self, o: Self) {
        *self = *self * o;
    }
}

impl<const N: usize> Scalar for Dual<N> {
    #[inline(always)]
    fn cst(v: f64) -> Self {
        Self { v, d: [0.0; N] }
    }
    #[inline(always)]
    fn val(self) -> f64 {
        self.v
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        let s = self.v.sqrt();
        // d√v = dv/(2√v); at v = 0 the slope is infinite: report 0 rather than NaN·0.
        let df = if s > 0.0 { 0.5 / s } else { 0.0 };
        self.chain(s, df)
    }
    #[inline(always)]
    fn sin_cos(self) -> (Self, Self) {
        let (s, c) = self.v.sin_cos();
        (self.chain(s, c), self.chain(c, -s))
    }
    #[inline(always)]
    fn exp(self) -> Self {
        let e = self.v.exp();
        self.chain(e, e)
    }
    #[inline(always)]
    fn ln(self) -> Self {
        self.chain(self.v.ln(), 1.0 / self.v)
    }
    #[inline(always)]
    fn powi(self, n: i32) -> Self {
        match n {
            0 => Self::cst(1.0),
            1 => self,
            2 => self * self,
            _ => self.chain(self.v.powi(n), n as f64 * self.v.powi(n - 1)),
        }
    }
    #[inline(always)]
    fn powf(self, e: f64) -> Self {
        let f = self.v.powf(e);
        let df = if self.v != 0.0 { e * f / self.v } else { 0.0 };
        self.chain(f, df)
    }
    #[inline(always)]
    fn atan2(self, x: Self) -> Self {
        // θ = atan2(y, x): dθ = (x dy − y dx)/(x² + y²).
        let (y, xv) = (self.v, x.v);
        let r2 = y * y + xv * xv;
        let inv = if r2 > 0.0 { 1.0 / r2 } else { 0.0 };
        Self {
            v: y.atan2(xv),
            d: std::array::from_fn(|k| (xv * self.d[k] - y * x.d[k]) * inv),
        }
    }
    #[inline(always)]
    fn abs(self) -> Self {
        if self.v < 0.0 {
            -self
        } else {
            self
        }
    }
    #[inline(always)]
    fn recip(self) -> Self {
        let r = 1.0 / self.v;
        self.chain(r, -r * r)
    }
    #[inline(always)]
    fn tanh(self) -> Self {
        let t = self.v.tanh();
        self.chain(t, 1.0 - t * t)
    }
    #[inline(always)]
    fn rsub(self, c: f64) -> Self {
        Self {
            v: c - self.v,
            d: self.d.map(|x| -x),
        }
    }
    #[inline(always)]
    fn rdiv(self, c: f64) -> Self {
        let v = c / self.v;
        self.chain(v, -v / self.v)
    }
    #[inline(always)]
    fn with_value(self, v: f64) -> Self {
        Self { v, d: self.d }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    type D = Dual<2>;

    /// Central difference of `f` at `x`, for checking the dual derivative.
    fn central(f: impl Fn(f64) -> f64, x: f64) -> f64 {
        let h = 1e-6 * x.abs().max(1.0);
        (f(x + h) - f(x - h)) / (2.0 * h)
    }

    #[test]
    fn every_function_carries_its_derivative() {
        type Case = (&'static str, fn(D) -> D, fn(f64) -> f64);
        let cases: Vec<Case> = vec![
            ("sqrt", |x| x.sqrt(), f64::sqrt),
            ("sin", |x| x.sin_cos().0, f64::sin),
            ("cos", |x| x.sin_cos().1, f64::cos),
            ("exp", |x| Scalar::exp(x), f64::exp),
            ("ln", |x| Scalar::ln(x), f64::ln),
            ("powi3", |x| x.powi(3), |x| x.powi(3)),
            ("powf", |x| x.powf(1.7), |x| x.powf(1.7)),
            ("recip", |x| x.recip(), |x| 1.0 / x),
            ("tanh", |x| Scalar::tanh(x), f64::tanh),
            ("abs", |x| Scalar::abs(x - 1.0), |x| (x - 1.0).abs()),
            (
                "rsub/rdiv",
                |x| x.rsub(2.0) / x.rdiv(3.0),
                |x| (2.0 - x) / (3.0 / x),
            ),
            (
                "quotient",
                |x| (x * x + 1.0) / (x - 3.0),
                |x| (x * x + 1.0) / (x - 3.0),
            ),
            (
                "atan2",
                |x| (x * 2.0).atan2(x * x - 1.5),
                |x| (2.0 * x).atan2(x * x - 1.5),
            ),
        ];
        for x0 in [0.3, 0.8, 1.7] {
            for (name, fd, ff) in &cases {
                let y = fd(D::var(x0, 1));
                assert_eq!(y.v, ff(x0), "{name}: value at {x0}");
                assert_eq!(y.d[0], 0.0, "{name}: an unseeded lane stays 0");
                let want = central(ff, x0);
                assert!(
                    (y.d[1] - want).abs() <= 1e-7 * want.abs().max(1.0),
                    "{name} at {x0}: {} for {want}",
                    y.d[1]
                );
            }
        }
    }

    #[test]
    fn two_lanes_give_the_partial_derivatives() {
        // f(a, b) = a² b + sin(a b): ∂f/∂a = 2ab + b cos(ab), ∂f/∂b = a² + a cos(ab).
        let (a, b) = (0.7, -1.3);
        let (da, db) = (D::var(a, 0), D::var(b, 1));
        let f = da * da * db + (da * db).sin_cos().0;
        assert!((f.d[0] - (2.0 * a * b + b * (a * b).cos())).abs() < 1e-14);
        assert!((f.d[1] - (a * a + a * (a * b).cos())).abs() < 1e-14);
    }
}
