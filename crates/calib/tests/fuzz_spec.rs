//! Fuzzing the calibration-spec parser (issue 13): mutated specs give a spec or a typed error
//! naming the file, never a panic; a spec that parses has no stage whose objective sums
//! nothing. Property tests of the bounds transforms.
//!
//! `PROPTEST_CASES=10000 cargo test -p itaipu-calib --test fuzz_spec -- --nocapture`
//! is the measurement of issue 13 and prints what the specs gave (the suite runs 1,000 specs
//! and proptest's default 256 cases of the bounds property).

use std::path::{Path, PathBuf};

use std::sync::atomic::{AtomicUsize, Ordering};

use itaipu_calib::fit::check_spec;
use itaipu_calib::problem::{logistic, logit, FreeParam};
use itaipu_calib::spec::{CalibSpec, Objective};
use itaipu_dynamics::unit_file::read_unit;
use proptest::prelude::*;
use proptest::test_runner::TestRunner;

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

const TOKENS: &[&str] = &[
    "",
    "0",
    "-0",
    "1",
    "-1",
    "0.5",
    "1e308",
    "-1e308",
    "1e-320",
    "nan",
    "inf",
    "-inf",
    "\n",
    "\"",
    "=",
    "[",
    "]",
    "[[",
    "]]",
    "{",
    "}",
    "#",
    ",",
    ".",
    "true",
    "name",
    "gen",
    "avr",
    "pss",
    "tg",
    "q",
    "p",
    "pq",
    "objective",
    "weights",
    "free",
    "param",
    "min",
    "max",
    "start",
    "spread",
    "window",
    "lowpass_hz",
    "set",
    "tie",
    "replace",
    "prior",
    "particles",
    "iterations",
    "[calibration]",
    "[[calibration.stage]]",
    "weights = { p = 0, q = 0 }",
    "objective = \"q\"",
    "machine.x_d",
    "\u{feff}",
    "é",
    " ",
];

fn edits() -> impl Strategy<Value = Vec<(f64, u8, usize, u8)>> {
    prop::collection::vec(
        (0.0f64..1.0, 0u8..5, 0usize..TOKENS.len(), any::<u8>()),
        1..8,
    )
}

fn boundary(s: &str, frac: f64) -> usize {
    let mut i = ((s.len() as f64) * frac) as usize;
    while i > 0 && !s.is_char_boundary(i) {
        i -= 1;
    }
    i.min(s.len())
}

fn mutate(seed: &str, edits: &[(f64, u8, usize, u8)]) -> String {
    let mut s = seed.to_string();
    for &(at, kind, tok, byte) in edits {
        let i = boundary(&s, at);
        match kind {
            0 => s.insert_str(i, TOKENS[tok]),
            1 => {
                let end = s[i..]
                    .find([',', '\n', ' ', '=', '"'])
                    .map_or(s.len(), |k| i + k);
                s.replace_range(i..end, TOKENS[tok]);
            }
            2 => {
                let end = boundary(&s, (at + 0.01 * (byte as f64 / 255.0)).min(1.0)).max(i);
                s.replace_range(i..end, "");
            }
            3 => s.insert(i, char::from(byte)),
            _ => s.truncate(i),
        }
    }
    s
}

fn seed_spec() -> &'static str {
    static T: std::sync::OnceLock<String> = std::sync::OnceLock::new();
    T.get_or_init(|| std::fs::read_to_string(repo().join("data/itaipu/calibration.toml")).unwrap())
}

/// Specs per run: `PROPTEST_CASES` if set (10,000 for the measurement of issue 13), else 1,000.
fn cases() -> u32 {
    std::env::var("PROPTEST_CASES")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(1000)
}

/// Mutated specs give a spec or a typed error naming the file, never a panic; a spec that
/// parses has no stage whose objective sums nothing, finite bounds and at least 2 particles, and
/// is checked against the Itaipu unit (no panic there either). Prints the counts.
#[test]
fn spec_parser_never_panics() {
    let n = cases();
    let unit = read_unit(&repo().join("data/itaipu/unit.toml")).unwrap();
    let config = ProptestConfig {
        cases: n,
        source_file: Some(file!()),
        ..ProptestConfig::default()
    };
    // Parsed and checked against the unit; parsed but refused by the unit; refused by the parser.
    let counts = [0, 1, 2].map(|_| AtomicUsize::new(0));
    let mut runner = TestRunner::new(config);
    let result = runner.run(&edits(), |e| {
        let text = mutate(seed_spec(), &e);
        let k = match CalibSpec::parse(&text, Path::new("c.toml")) {
            Ok(spec) => {
                for s in &spec.stages {
                    let (wp, wq) = match s.objective {
                        Objective::Pq => (s.weights.p, s.weights.q),
                        Objective::P => (s.weights.p, 0.0),
                        Objective::Q => (0.0, s.weights.q),
                    };
                    prop_assert!(wp > 0.0 || wq > 0.0, "stage {} sums nothing", s.name);
                    for f in &s.free {
                        prop_assert!(f.min < f.max && f.min.is_finite() && f.max.is_finite());
                    }
                }
                prop_assert!(spec.pso.particles >= 2);
                let stages: Vec<String> = spec.stages.iter().map(|s| s.name.clone()).collect();
                match check_spec(&unit, &spec, &stages) {
                    Ok(()) => 0,
                    Err(err) => {
                        prop_assert!(!err.to_string().is_empty());
                        1
                    }
                }
            }
            Err(err) => {
                prop_assert!(["io", "syntax", "missing", "field"].contains(&err.kind()));
                prop_assert!(err.to_string().contains("c.toml"), "{}", err);
                2
            }
        };
        counts[k].fetch_add(1, Ordering::Relaxed);
        Ok(())
    });
    if let Err(e) = result {
        panic!("fuzz calibration spec: {e}");
    }
    let [ok, refused, rejected] = counts.map(|c| c.into_inner());
    println!(
        "fuzz mutated calibration spec: {} inputs, 0 panics: {ok} parsed and fit the unit, {refused} parsed but refused against the unit, {rejected} typed errors",
        ok + refused + rejected
    );
    // proptest also replays the seeds saved in fuzz_spec.proptest-regressions first.
    assert!(ok + refused + rejected >= n as usize);
}

proptest! {
    /// Box coordinates: from_unit maps [0, 1] into [lo, hi], monotonically, and to_unit
    /// inverts it (linear and logarithmic scaling); anything outside is clamped, never NaN.
    #[test]
    fn bounds_transforms_round_trip_and_stay_in_bounds(
        lo in 1e-6f64..100.0,
        width in 1e-3f64..1e4,
        u in 0.0f64..=1.0,
        v in 0.0f64..=1.0,
        wild in prop::num::f64::ANY,
        negative_lo in any::<bool>(),
    ) {
        let lo = if negative_lo { -lo } else { lo };
        let hi = lo + width;
        let unit = read_unit(&repo().join("data/itaipu/unit.toml")).unwrap();
        let r = unit.param("machine.h").unwrap();
        let f = FreeParam::new("machine.h".into(), r, lo, hi, 0.5 * (lo + hi), "s");
        let x = f.from_unit(u);
        prop_assert!(x >= lo && x <= hi, "{x} outside [{lo}, {hi}]");
        let back = f.to_unit(x);
        // Round-off: relative to the box in linear scaling, to the decades spanned in log.
        let decades = if lo > 0.0 { (hi / lo).ln() } else { 0.0 };
        let tol = 1e-9 * (1.0 + decades) * (1.0 + lo.abs() / width);
        prop_assert!((back - u).abs() <= tol, "{u} -> {x} -> {back} (tol {tol})");
        if u < v {
            prop_assert!(f.from_unit(u) <= f.from_unit(v));
        }
        // Out-of-range or non-finite coordinates are clamped, not propagated.
        if !wild.is_nan() {
            let y = f.from_unit(wild);
            prop_assert!(y >= lo && y <= hi);
            let w = f.to_unit(wild);
            prop_assert!((0.0..=1.0).contains(&w), "to_unit({wild}) = {w}");
        }
        // The start is clamped into the box.
        let g = FreeParam::new("machine.h".into(), r, lo, hi, hi + 10.0 * width, "s");
        prop_assert_eq!(g.start, hi);
        // The unbounded coordinate of the local method: logistic inverts logit on (0, 1).
        if u > 1e-9 && u < 1.0 - 1e-9 {
            prop_assert!((logistic(logit(u)) - u).abs() < 1e-9);
        }
    }
}
