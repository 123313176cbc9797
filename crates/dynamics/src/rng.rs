//! The workspace's one source of random numbers: SplitMix64 (Steele, Lea and Flood, 2014).
//!
//! Every random number in itaipu-calib comes from here: the particle swarm's designs and
//! velocities, the PMU noise of synthetic events, the diagnosis' surrogate noise, and the seeded
//! test data. Two ways to draw, both pure functions of a seed:
//!
//! * **counter-based** ([`uniform_at`]): the value is a hash of `(seed, word, word, ...)`, so it
//!   does not depend on the order in which values are drawn. The particle swarm keys each number
//!   by its purpose, iteration, particle and dimension, which is what makes a seeded fit give the
//!   same numbers on any number of threads.
//! * **sequential** ([`SplitMix64`], [`Normal`]): a stream for data made in one pass (noise
//!   sequences).
//!
//! SplitMix64 passes BigCrush, has a period of 2⁶⁴ and costs a few multiplications per value;
//! nothing here is for cryptography. The constants are those of the published generator, so the
//! streams are stable: a change here changes every seeded fit and synthetic event.

/// The SplitMix64 increment (2⁶⁴ / φ, odd).
pub const GOLDEN_GAMMA: u64 = 0x9E37_79B9_7F4A_7C15;

/// SplitMix64 output function: a bijection on `u64` that spreads every input bit.
#[inline]
pub fn mix64(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Hashes `(seed, words...)` into 64 bits by chaining SplitMix64 steps (each step is injective
/// in its word for a fixed prefix, so different coordinates give independent-looking values).
#[inline]
pub fn key(seed: u64, words: &[u64]) -> u64 {
    let mut h = mix64(seed.wrapping_add(GOLDEN_GAMMA));
    for &w in words {
        h = mix64(h.wrapping_add(GOLDEN_GAMMA) ^ w);
    }
    h
}

/// Counter-based uniform in `[0, 1)` (53 random bits) at the coordinates `words` of `seed`.
#[inline]
pub fn uniform_at(seed: u64, words: &[u64]) -> f64 {
    (key(seed, words) >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
}

/// A sequential SplitMix64 stream.
#[derive(Debug, Clone)]
pub struct SplitMix64 {
    state: u64,
}

impl SplitMix64 {
    /// A stream whose first state is `seed` (every seed, 0 included, is a good one).
    pub fn new(seed: u64) -> Self {
        Self { state: seed }
    }

    /// The next 64 random bits.
    #[inline]
    pub fn next_u64(&mut self) -> u64 {
        self.state = self.state.wrapping_add(GOLDEN_GAMMA);
        mix64(self.state)
    }

    /// Uniform in the open interval (0, 1) (never 0, so `ln` is safe).
    #[inline]
    pub fn uniform(&mut self) -> f64 {
        ((self.next_u64() >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    }

    /// Uniform in `[lo, hi)`.
    #[inline]
    pub fn uniform_in(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.uniform()
    }
}

/// Standard normal numbers by Box-Muller on a [`SplitMix64`] stream (both values of each pair
/// are used).
#[derive(Debug, Clone)]
pub struct Normal {
    stream: SplitMix64,
    spare: Option<f64>,
}

impl Normal {
    /// A normal stream for `seed` (the underlying stream starts at `seed ^ GOLDEN_GAMMA`).
    pub fn new(seed: u64) -> Self {
        Self {
            stream: SplitMix64::new(seed ^ GOLDEN_GAMMA),
            spare: None,
        }
    }

    /// The next 64 random bits of the underlying stream.
    pub fn next_u64(&mut self) -> u64 {
        self.stream.next_u64()
    }

    /// Uniform in (0, 1), from the same stream.
    pub fn uniform(&mut self) -> f64 {
        self.stream.uniform()
    }

    /// A standard normal value.
    pub fn sample(&mut self) -> f64 {
        if let Some(s) = self.spare.take() {
            return s;
        }
        let (u1, u2) = (self.stream.uniform(), self.stream.uniform());
        let r = (-2.0 * u1.ln()).sqrt();
        let th = 2.0 * std::f64::consts::PI * u2;
        self.spare = Some(r * th.sin());
        r * th.cos()
    }

    /// `n` values of a zero-mean normal with standard deviation `sigma`.
    pub fn noise(&mut self, n: usize, sigma: f64) -> Vec<f64> {
        (0..n).map(|_| sigma * self.sample()).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The published SplitMix64 sequence for seed 1234567 (the reference implementation's
    /// first outputs): the stream is the generator, not an imitation.
    #[test]
    fn splitmix64_matches_the_published_sequence() {
        let mut s = SplitMix64::new(1_234_567);
        let want = [
            6_457_827_717_110_365_317u64,
            3_203_168_211_198_807_973,
            9_817_491_932_198_370_423,
            4_593_380_528_125_082_431,
            16_408_922_859_458_223_821,
        ];
        for w in want {
            assert_eq!(s.next_u64(), w);
        }
    }

    #[test]
    fn counter_based_values_depend_only_on_their_coordinates() {
        let a = uniform_at(7, &[1, 2, 3]);
        let b = uniform_at(7, &[1, 2, 3]);
        assert_eq!(a.to_bits(), b.to_bits());
        assert_ne!(a, uniform_at(7, &[1, 2, 4]));
        assert_ne!(a, uniform_at(8, &[1, 2, 3]));
        assert!((0.0..1.0).contains(&a));
    }

    #[test]
    fn normal_has_unit_variance_and_zero_mean() {
        let mut n = Normal::new(42);
        let x = n.noise(200_000, 1.0);
        let mean = x.iter().sum::<f64>() / x.len() as f64;
        let var = x.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / x.len() as f64;
        assert!(mean.abs() < 0.01, "mean {mean}");
        assert!((var - 1.0).abs() < 0.01, "variance {var}");
        let mut u = SplitMix64::new(3);
        for _ in 0..10_000 {
            let v = u.uniform();
            assert!(v > 0.0 && v < 1.0);
        }
    }
}
