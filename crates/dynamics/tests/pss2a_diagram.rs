//! PSS2A's independent check (ANDES has no PSS2A): the built-in model
//! (`models/pss/pss2a.rs`) against the same stabiliser written a second way, from the diagram
//! primitives (`data/diagrams/pss2a.toml`, M = 5, N = 1, every washout and lag present), in the
//! thermal unit (GENROU, ESST4B, PSS2A, IEEEG1) on a fault dip with the default 0.2 Hz
//! frequency fall, where both inputs move and V_S reaches its limits. Both are integrated on
//! the same RK4 steps, so the two discrete maps differ only by rounding: P, Q, V_S, E_fd and
//! P_m agree to 1e-9 at every sample.

use std::path::{Path, PathBuf};

use itaipu_dynamics::dyr::{parse_dyr, DyrBases};
use itaipu_dynamics::integrate::Method;
use itaipu_dynamics::simulate::{simulate, SimOptions};
use itaipu_dynamics::synthetic::{synthesize, PmuNoise, VoltageProfile};
use itaipu_dynamics::unit::Unit;
use itaipu_dynamics::unit_file::{parse_unit, unit_to_toml};

fn repo(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../..")
        .join(rel)
}

/// The thermal unit with the built-in PSS2A (both washouts of input 2 and the input-1
/// transducer present), and the same unit with the diagram in its place.
fn units() -> (Unit, Unit) {
    let path = repo("data/thermal/unit.dyr");
    let bases = DyrBases {
        mbase: 700.0,
        nominal_hz: 60.0,
        zr: Some(0.0025),
        zx: None,
        name: None,
    };
    let text = std::fs::read_to_string(&path).unwrap();
    let mut u = parse_dyr(&text, &path, None, &bases).unwrap().unit;
    for (p, v) in [("pss.tw4", 5.0), ("pss.t6", 0.05)] {
        let r = u.param(p).unwrap();
        u.set(r, v);
    }
    let toml = unit_to_toml(&u);
    let diagram = repo("data/diagrams/pss2a.toml");
    let mut out = String::new();
    let mut in_pss = false;
    for line in toml.lines() {
        if line.starts_with('[') {
            in_pss = line == "[pss]";
        }
        if in_pss && line.starts_with("model = ") {
            out.push_str(&format!(
                "model = \"diagram\"\ndiagram = {:?}\n",
                diagram.display().to_string()
            ));
            continue;
        }
        // The ramp-tracking filter's orders are the diagram's structure, not parameters.
        if in_pss && (line.starts_with("m = ") || line.starts_with("n = ")) {
            continue;
        }
        out.push_str(line);
        out.push('\n');
    }
    let d = parse_unit(&out, &repo("data/thermal/pss2a_diagram.toml")).unwrap();
    (u, d)
}

#[test]
fn pss2a_agrees_with_its_diagram_to_1e_9() {
    let (builtin, diagram) = units();
    assert_eq!(diagram.block("pss").unwrap().model(), "diagram");
    let ev = synthesize(
        "dip",
        &builtin,
        &VoltageProfile {
            duration_s: 10.0,
            ..Default::default()
        },
        700.0,
        &PmuNoise::typical(5),
        &SimOptions::default(),
    )
    .unwrap();
    let opts = SimOptions {
        method: Method::Rk4 { h: 1e-3 },
    };
    let a = simulate(&builtin, &ev, &opts).unwrap();
    let b = simulate(&diagram, &ev, &opts).unwrap();
    let (vs_lo, vs_hi) = a
        .get("vs")
        .unwrap()
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), v| {
            (l.min(*v), h.max(*v))
        });
    // The comparison is through V_S's limits (0.2, -0.066), not on a quiet stabiliser.
    assert!(
        vs_hi >= 0.2 - 1e-12 && vs_lo <= -0.066 + 1e-12,
        "V_S {vs_lo}..{vs_hi}"
    );
    let mut worst = 0.0f64;
    for c in ["p_pu", "q_pu", "vs", "efd", "pm"] {
        let (x, y) = (a.get(c).unwrap(), b.get(c).unwrap());
        let d = x
            .iter()
            .zip(y)
            .fold(0.0f64, |m, (p, q)| m.max((p - q).abs()));
        println!("{c}: max |Δ| {d:.1e}");
        worst = worst.max(d);
    }
    assert!(
        worst < 1e-9,
        "built-in and diagram PSS2A differ by {worst:e}"
    );
}
