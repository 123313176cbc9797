//! Fuzzing the readers (issue 13): mutated and arbitrary CSV, event TOML and unit TOML must
//! give a value or a typed error, never a panic; an event that reads goes through the
//! plausibility layer and the operating point without a panic either. Property tests of the
//! integrators.
//!
//! Bounded for the test suite: 1,000 inputs per reader (a few seconds), proptest's default 256
//! cases for the integrator properties. The measurement of issue 13 runs 10,000 per reader and
//! prints what they gave:
//! `PROPTEST_CASES=10000 cargo test -p itaipu-dynamics --test fuzz_readers -- --nocapture`.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

use itaipu_dynamics::event::{read_csv, Event};
use itaipu_dynamics::integrate::{solve, Dopri5Options, Method, OdeSystem};
use itaipu_dynamics::plausibility::{check_event, has_errors};
use itaipu_dynamics::simulate::{simulate, SimOptions};
use itaipu_dynamics::unit_file::parse_unit;
use proptest::prelude::*;
use proptest::test_runner::{TestCaseError, TestRunner};

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// A per-case folder (several properties run in parallel threads).
fn case_dir() -> PathBuf {
    static N: AtomicUsize = AtomicUsize::new(0);
    let d = std::env::temp_dir().join(format!(
        "itaipu-fuzz-{}-{}",
        std::process::id(),
        N.fetch_add(1, Ordering::Relaxed)
    ));
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Pieces that readers find hard: numbers at the edges, separators, keys, quotes, BOM.
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
    "1e300",
    "NaN",
    "nan",
    "inf",
    "-inf",
    "1e999",
    "99999999999999999999999",
    ",",
    ",,",
    "\n",
    "\r\n",
    "\"",
    "'",
    "=",
    "[",
    "]",
    "[[",
    "]]",
    "{",
    "}",
    "#",
    ".",
    "..",
    "time_s",
    "v_pu",
    "angle_deg",
    "v_re_pu",
    "freq_hz",
    "p_pu",
    "\u{feff}",
    "é",
    "\0",
    " ",
    "\t",
    "true",
    "model",
    "machine",
    "[init]",
    "start_s",
    "end_s",
    "csv",
    "name",
    "h",
    "x_d",
    "GENSAE",
    "SEXS",
    "[[block]]",
    "wiring",
    "60.0",
    "system_mva",
    "nominal_hz",
];

/// Edits applied in order to a seed text: (position fraction, kind, token index or byte).
fn edits() -> impl Strategy<Value = Vec<(f64, u8, usize, u8)>> {
    prop::collection::vec(
        (0.0f64..1.0, 0u8..5, 0usize..TOKENS.len(), any::<u8>()),
        1..8,
    )
}

fn char_boundary(s: &str, frac: f64) -> usize {
    let mut i = ((s.len() as f64) * frac) as usize;
    while i > 0 && !s.is_char_boundary(i) {
        i -= 1;
    }
    i.min(s.len())
}

fn mutate(seed: &str, edits: &[(f64, u8, usize, u8)]) -> String {
    let mut s = seed.to_string();
    for &(at, kind, tok, byte) in edits {
        let i = char_boundary(&s, at);
        match kind {
            // Insert a token.
            0 => s.insert_str(i, TOKENS[tok]),
            // Replace the next "word" (up to a separator) by a token.
            1 => {
                let end = s[i..]
                    .find([',', '\n', ' ', '=', '"'])
                    .map_or(s.len(), |k| i + k);
                s.replace_range(i..end, TOKENS[tok]);
            }
            // Delete a short range.
            2 => {
                let end = char_boundary(&s, (at + 0.01 * (byte as f64 / 255.0)).min(1.0)).max(i);
                s.replace_range(i..end, "");
            }
            // Insert an arbitrary character.
            3 => s.insert(i, char::from(byte)),
            // Truncate.
            _ => s.truncate(i),
        }
    }
    s
}

fn itaipu_csv() -> &'static str {
    static T: std::sync::OnceLock<String> = std::sync::OnceLock::new();
    T.get_or_init(|| {
        // A shorter record keeps each case fast: the first 120 samples.
        let t = std::fs::read_to_string(repo().join("data/itaipu/itaipu_pmu_60sps.csv")).unwrap();
        t.lines().take(121).map(|l| format!("{l}\n")).collect()
    })
}

fn itaipu_unit() -> &'static str {
    static T: std::sync::OnceLock<String> = std::sync::OnceLock::new();
    T.get_or_init(|| std::fs::read_to_string(repo().join("data/itaipu/unit.toml")).unwrap())
}

const EVENT_TOML: &str = "name = \"f\"\ncsv = \"e.csv\"\nsystem_mva = 1000.0\nnominal_hz = 60.0\n[init]\nstart_s = 0.0\nend_s = 0.95\n[fit]\nstart_s = 0.0\nend_s = 1.9\n";

/// What one fuzzed input gave (a panic or a failed assertion fails the test instead).
#[derive(Clone, Copy, Debug)]
enum Outcome {
    /// Read, and the plausibility layer found no error.
    Read,
    /// Read, and the plausibility layer found an error (the CLI stops with exit 3).
    Implausible,
    /// Refused with a typed error naming the file.
    Rejected,
}

/// Cases per reader: `PROPTEST_CASES` if set (10,000 for the measurement of issue 13), else
/// 1,000 (a few seconds in the suite).
fn cases() -> u32 {
    std::env::var("PROPTEST_CASES")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(1000)
}

/// Runs `case` on [`cases`] inputs drawn from `strategy` (proptest: a panic or a failed
/// assertion is a failure, shrunk to a small input), counts the outcomes, prints them and checks
/// that every input was run.
fn fuzz<S: Strategy>(
    name: &str,
    strategy: S,
    case: impl Fn(S::Value) -> Result<Outcome, TestCaseError>,
) {
    let n = cases();
    let config = ProptestConfig {
        cases: n,
        source_file: Some(file!()),
        ..ProptestConfig::default()
    };
    let counts = [0, 1, 2].map(|_| AtomicUsize::new(0));
    let mut runner = TestRunner::new(config);
    let result = runner.run(&strategy, |v| {
        let k = case(v)? as usize;
        counts[k].fetch_add(1, Ordering::Relaxed);
        Ok(())
    });
    if let Err(e) = result {
        panic!("fuzz {name}: {e}");
    }
    let [read, implausible, rejected] = counts.map(|c| c.into_inner());
    println!(
        "fuzz {name}: {} inputs, 0 panics: {read} read, {implausible} read but implausible, {rejected} typed errors",
        read + implausible + rejected
    );
    // At least n: proptest replays any seed saved in a regressions file first.
    assert!(read + implausible + rejected >= n as usize, "{name}");
}

/// Reads an event from `toml` and `csv`; an event that reads is checked and its operating
/// point computed (no panic either way).
fn read_event(dir: &Path, toml: &str, csv: &str) -> Result<Outcome, TestCaseError> {
    std::fs::write(dir.join("e.toml"), toml).unwrap();
    std::fs::write(dir.join("e.csv"), csv).unwrap();
    let outcome = match Event::from_toml_file(&dir.join("e.toml")) {
        Ok(e) => {
            let _ = e.operating_point();
            let findings = check_event(&e, Some(737.0));
            for f in &findings {
                // Every finding names the file it is about.
                prop_assert!(f.to_string().contains("e."), "{}", f);
            }
            if has_errors(&findings) {
                Outcome::Implausible
            } else {
                Outcome::Read
            }
        }
        Err(err) => {
            // Typed, and it names the file it is about.
            prop_assert!(!err.kind().is_empty());
            prop_assert!(err.to_string().contains("e."), "{}", err);
            Outcome::Rejected
        }
    };
    let _ = std::fs::remove_dir_all(dir);
    Ok(outcome)
}

#[test]
fn csv_reader_never_panics_on_mutations() {
    fuzz("mutated CSV", edits(), |e| {
        read_event(&case_dir(), EVENT_TOML, &mutate(itaipu_csv(), &e))
    });
}

#[test]
fn csv_reader_never_panics_on_arbitrary_text() {
    fuzz(
        "arbitrary CSV text",
        "[-0-9a-z_,.\\n\"e+ ]{0,400}",
        |text: String| {
            let dir = case_dir();
            std::fs::write(dir.join("x.csv"), &text).unwrap();
            let outcome = match read_csv(&dir.join("x.csv"), 60.0) {
                Ok(_) => Outcome::Read,
                Err(err) => {
                    prop_assert!(!err.kind().is_empty());
                    prop_assert!(err.to_string().contains("x.csv"), "{}", err);
                    Outcome::Rejected
                }
            };
            let _ = std::fs::remove_dir_all(&dir);
            Ok(outcome)
        },
    );
}

#[test]
fn event_toml_reader_never_panics() {
    fuzz("mutated event TOML", edits(), |e| {
        read_event(&case_dir(), &mutate(EVENT_TOML, &e), itaipu_csv())
    });
}

#[test]
fn unit_toml_reader_never_panics() {
    fuzz("mutated unit TOML", edits(), |e| {
        let text = mutate(itaipu_unit(), &e);
        Ok(match parse_unit(&text, Path::new("u.toml")) {
            Ok(u) => {
                let _ = itaipu_dynamics::plausibility::check_unit(&u, Path::new("u.toml"));
                Outcome::Read
            }
            Err(err) => {
                prop_assert!(err.to_string().contains("u.toml"), "{}", err);
                Outcome::Rejected
            }
        })
    });
}

/// Column layouts of a well-formed CSV (the two voltage forms, with and without frequency).
const LAYOUTS: &[&str] = &[
    "time_s,v_re_pu,v_im_pu,p_pu,q_pu",
    "time_s,v_pu,angle_deg,p_pu,q_pu",
    "time_s,v_pu,angle_deg,p_pu,q_pu,freq_hz",
];

/// Values that readers, the plausibility layer and the initialisation find hard.
fn wild_value() -> impl Strategy<Value = f64> {
    prop_oneof![
        prop::sample::select(vec![
            0.0,
            -0.0,
            1e300,
            -1e300,
            1e-300,
            5e-324,
            f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::MAX,
            1e-12,
            std::f64::consts::PI,
            180.0,
            -180.0,
            360.0,
            19.99,
            -19.99,
            45.0,
            65.0,
        ]),
        -100.0f64..100.0,
        prop::num::f64::ANY,
    ]
}

/// A well-formed CSV (a layout, a sample interval, 0-150 rows near the Itaipu operating point)
/// with wild values put into some of its cells: every number parses, so these inputs go past
/// the syntax into the readers' checks, the plausibility layer, the initialisation and, when
/// they read without an implausibility, a short playback.
fn wild_csv() -> impl Strategy<Value = String> {
    (
        0..LAYOUTS.len(),
        prop_oneof![
            4 => Just(1.0 / 60.0),
            1 => prop::sample::select(vec![1.0 / 30.0, 1e-12, 0.5, 100.0, 0.0]),
        ],
        // Mostly long enough for the event's windows (2 s at 60 samples/s).
        prop_oneof![3 => 118usize..150, 1 => 0usize..150],
        // Cells (row, column, value); the time column rarely (a wild time rarely reads).
        prop::collection::vec(
            (
                0usize..150,
                prop_oneof![1 => Just(0usize), 9 => 1usize..6],
                wild_value(),
            ),
            0..5,
        ),
    )
        .prop_map(|(layout, dt, rows, cells)| {
            let header = LAYOUTS[layout];
            let cols = header.split(',').count();
            let mut table: Vec<Vec<f64>> = (0..rows)
                .map(|k| {
                    let t = k as f64 * dt;
                    let mut r = vec![t];
                    if layout == 0 {
                        r.extend([0.986 * (0.01 * t).cos(), 0.986 * (0.01 * t).sin()]);
                    } else {
                        r.extend([0.986, (0.01 * t).to_degrees()]);
                    }
                    r.extend([0.6235, 0.0225]);
                    if cols == 6 {
                        r.push(60.0);
                    }
                    r
                })
                .collect();
            for (row, col, v) in cells {
                if let Some(r) = table.get_mut(row) {
                    r[if col == 0 {
                        0
                    } else {
                        1 + (col - 1) % (cols - 1)
                    }] = v;
                }
            }
            let mut text = format!("{header}\n");
            for r in table {
                let cells: Vec<String> = r.iter().map(|x| format!("{x:?}")).collect();
                text.push_str(&cells.join(","));
                text.push('\n');
            }
            text
        })
}

#[test]
fn wild_numbers_in_a_well_formed_csv_never_panic() {
    let unit = parse_unit(itaipu_unit(), Path::new("u.toml")).unwrap();
    let opts = SimOptions {
        method: Method::Rk4 { h: 0.01 },
    };
    fuzz("well-formed CSV, wild values", wild_csv(), |csv| {
        let dir = case_dir();
        let outcome = read_event(&dir, EVENT_TOML, &csv)?;
        if let Outcome::Read = outcome {
            // Recreate the files read_event removed; play the event back (result or error).
            std::fs::create_dir_all(&dir).unwrap();
            std::fs::write(dir.join("e.toml"), EVENT_TOML).unwrap();
            std::fs::write(dir.join("e.csv"), &csv).unwrap();
            let e = Event::from_toml_file(&dir.join("e.toml")).unwrap();
            let _ = simulate(&unit, &e, &opts);
            let _ = std::fs::remove_dir_all(&dir);
        }
        Ok(outcome)
    });
}

/// dx/dt = −a·x, one state.
struct Decay(f64);

impl OdeSystem for Decay {
    fn dim(&self) -> usize {
        1
    }
    fn rhs(&mut self, _t: f64, x: &[f64], dx: &mut [f64]) {
        dx[0] = -self.0 * x[0];
    }
}

proptest! {
    /// Both integrators follow exp(−a t) on any increasing knots (RK4 within its h⁴ error,
    /// Dormand-Prince within its tolerance), and report every knot once, in order.
    #[test]
    fn integrators_follow_an_exponential_decay(
        a in 0.1f64..10.0,
        gaps in prop::collection::vec(1e-4f64..0.2, 1..40),
        h in 1e-3f64..0.02,
    ) {
        let mut knots = vec![0.0];
        for g in &gaps {
            knots.push(knots.last().unwrap() + g);
        }
        let methods = [
            (Method::Rk4 { h }, 1e-2 * (a * h).powi(4) + 1e-12),
            (Method::Dopri5(Dopri5Options { rtol: 1e-8, atol: 1e-12, ..Default::default() }), 1e-6),
        ];
        for (m, tol) in methods {
            let mut x = [1.0];
            let mut seen = vec![];
            let r = solve(&m, &mut Decay(a), &mut x, &knots, |k, t, x, _| {
                seen.push(k);
                let exact = (-a * t).exp();
                assert!((x[0] - exact).abs() <= tol * 10.0 + 1e-9, "{m}: t {t}: {} vs {exact}", x[0]);
            });
            prop_assert!(r.is_ok(), "{:?}", r);
            prop_assert_eq!(seen, (0..knots.len()).collect::<Vec<_>>());
            prop_assert!((x[0] - (-a * knots.last().unwrap()).exp()).abs() <= tol * 10.0 + 1e-9);
        }
    }

    /// Knots that do not increase, and bad settings, are errors, not panics.
    #[test]
    fn bad_knots_and_settings_are_errors(
        knots in prop::collection::vec(-1e3f64..1e3, 0..6),
        h in -1.0f64..1.0,
    ) {
        let increasing = knots.windows(2).all(|w| w[1] > w[0]);
        let mut x = [1.0];
        let r = solve(&Method::Rk4 { h }, &mut Decay(1.0), &mut x, &knots, |_, _, _, _| {});
        if h <= 0.0 {
            prop_assert!(r.is_err());
        } else if !increasing {
            prop_assert!(r.is_err());
        }
    }
}
