//! User-defined diagrams against the built-in blocks they re-implement (paper 000 verified its
//! Modelica re-implementations against the original tool the same way).
//!
//! `data/diagrams/sexs.toml`, `stab3.toml` and `hygov.toml` replace the built-in SEXS, STAB3 and
//! HYGOV in a unit; the played-back P, Q and the block outputs (E_fd, V_S, P_m) must agree with
//! the built-in unit's within 1e-6 pu at every sample, on the bundled Itaipu record and on a
//! synthetic fault dip and frequency excursion (which drive the HYGOV gate-rate limit and the
//! exciter ceiling).

use std::path::{Path, PathBuf};

use itaipu_dynamics::event::Event;
use itaipu_dynamics::simulate::{simulate, SimOptions, Traces};
use itaipu_dynamics::synthetic::{synthesize, EventKind, PmuNoise, VoltageProfile};
use itaipu_dynamics::unit::Unit;
use itaipu_dynamics::unit_file::parse_unit;

fn data(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../data")
        .join(rel)
}

fn unit(text: &str) -> Unit {
    // The unit "lives" in data/itaipu/, so `../diagrams/…` resolves.
    parse_unit(text, &data("itaipu/test-unit.toml")).unwrap_or_else(|e| panic!("{e}\n{text}"))
}

/// Replaces the section `[name]` (up to the next section) of `text` with `with`.
fn replace_section(text: &str, name: &str, with: &str) -> String {
    let head = format!("[{name}]\n");
    let a = text.find(&head).unwrap_or_else(|| panic!("no [{name}]"));
    let rest = &text[a + head.len()..];
    let b = rest
        .find("\n[")
        .map(|k| a + head.len() + k + 1)
        .unwrap_or(text.len());
    format!("{}{}\n{}", &text[..a], with, &text[b..])
}

/// The parameter lines of section `[name]` (without `model`).
fn section_params(text: &str, name: &str) -> String {
    let head = format!("[{name}]\n");
    let a = text.find(&head).unwrap() + head.len();
    let rest = &text[a..];
    let b = rest.find("\n[").unwrap_or(rest.len());
    rest[..b]
        .lines()
        .filter(|l| !l.trim_start().starts_with("model"))
        .collect::<Vec<_>>()
        .join("\n")
}

/// `text` with the built-in block of `section` replaced by the diagram `file`, same values.
fn as_diagram(text: &str, section: &str, file: &str) -> String {
    let params = section_params(text, section);
    replace_section(
        text,
        section,
        &format!("[{section}]\nmodel = \"diagram\"\ndiagram = \"../diagrams/{file}\"\n{params}\n"),
    )
}

const HYGOV: &str = "[governor]\nmodel = \"HYGOV\"\nr_perm = 0.05\nr_temp = 0.3\nt_r = 5.0\nt_f = 0.05\nt_g = 0.5\nvelm = 0.2\ng_max = 1.0\ng_min = 0.0\nt_w = 1.2\na_t = 1.2\nd_turb = 0.5\nq_nl = 0.08\n";

fn itaipu_text() -> String {
    let t = std::fs::read_to_string(data("itaipu/unit.toml")).unwrap();
    // The bundled unit holds P_m constant; put a HYGOV in so that the governor is exercised.
    replace_section(&t, "governor", HYGOV)
}

fn max_dev(a: &Traces, b: &Traces, cols: &[&str]) -> (f64, String) {
    let mut worst = (0.0, String::new());
    for c in cols {
        let (x, y) = (a.get(c).unwrap(), b.get(c).unwrap());
        assert_eq!(x.len(), y.len());
        for (k, (u, v)) in x.iter().zip(y).enumerate() {
            let d = (u - v).abs();
            assert!(d.is_finite(), "{c}[{k}]: {u} vs {v}");
            if d > worst.0 {
                worst = (d, format!("{c} at sample {k}"));
            }
        }
    }
    worst
}

const COLS: &[&str] = &["p_pu", "q_pu", "efd", "vs", "pm", "speed", "xadifd"];

fn check(base: &str, ev: &Event, what: &str) -> f64 {
    let opts = SimOptions::default();
    let reference = simulate(&unit(base), ev, &opts).unwrap();
    let mut worst = 0.0f64;
    for (section, file) in [
        ("exciter", "sexs.toml"),
        ("pss", "stab3.toml"),
        ("governor", "hygov.toml"),
    ] {
        let text = as_diagram(base, section, file);
        let u = unit(&text);
        assert_eq!(u.block(section).unwrap().model(), "diagram");
        let tr = simulate(&u, ev, &opts).unwrap_or_else(|e| panic!("{what} {file}: {e}"));
        let (d, at) = max_dev(&reference, &tr, COLS);
        println!("{what}: {file} deviates by at most {d:.3e} ({at})");
        assert!(d < 1e-6, "{what}: {file} deviates by {d:.3e} at {at}");
        worst = worst.max(d);
    }
    // All three at once.
    let all = as_diagram(
        &as_diagram(
            &as_diagram(base, "exciter", "sexs.toml"),
            "pss",
            "stab3.toml",
        ),
        "governor",
        "hygov.toml",
    );
    let tr = simulate(&unit(&all), ev, &opts).unwrap();
    let (d, at) = max_dev(&reference, &tr, COLS);
    println!("{what}: all three diagrams deviate by at most {d:.3e} ({at})");
    assert!(d < 1e-6, "{what}: all three deviate by {d:.3e} at {at}");
    worst.max(d)
}

#[test]
fn sexs_stab3_hygov_diagrams_reproduce_the_builtin_blocks_on_the_itaipu_record() {
    let ev = Event::from_toml_file(&data("itaipu/event.toml")).unwrap();
    let base = itaipu_text();
    let d = check(&base, &ev, "itaipu");
    // The record moves the unit: the comparison is not between two flat lines.
    let tr = simulate(&unit(&base), &ev, &SimOptions::default()).unwrap();
    let efd = tr.get("efd").unwrap();
    let span = efd.iter().cloned().fold(f64::NEG_INFINITY, f64::max)
        - efd.iter().cloned().fold(f64::INFINITY, f64::min);
    assert!(span > 0.1, "E_fd moves by {span}");
    println!("itaipu: max deviation {d:.3e}");
}

#[test]
fn the_diagrams_reproduce_the_builtin_blocks_on_synthetic_events_with_limits_hit() {
    let base_text =
        std::fs::read_to_string(data("synthetic/unit_gensae_sexs_stab3_hygov.toml")).unwrap();
    // A low ceiling so that the dip drives E_fd onto it.
    // And a slow gate so that the frequency excursion drives the gate-rate limit.
    let base = base_text
        .replacen("e_max = 4.5", "e_max = 2.6", 1)
        .replacen("velm = 0.2", "velm = 0.004", 1);
    assert!(
        base.contains("e_max = 2.6") && base.contains("velm = 0.004"),
        "the synthetic unit's e_max / velm lines changed"
    );
    for kind in [EventKind::FaultDip, EventKind::FrequencyExcursion] {
        let profile = VoltageProfile::preset(kind, 12.0, 60.0, 7);
        let ev = synthesize(
            "diagram-test",
            &unit(&base),
            &profile,
            1000.0,
            &PmuNoise::none(),
            &SimOptions::default(),
        )
        .unwrap();
        check(&base, &ev, &format!("{kind:?}"));
        let tr = simulate(&unit(&base), &ev, &SimOptions::default()).unwrap();
        if kind == EventKind::FaultDip {
            let top = tr
                .get("efd")
                .unwrap()
                .iter()
                .cloned()
                .fold(f64::NEG_INFINITY, f64::max);
            assert!(
                (top - 2.6).abs() < 1e-9,
                "the ceiling is hit (E_fd max {top})"
            );
        } else {
            // The gate moves at the rate limit at least once.
            let c = tr.get("governor.c").unwrap();
            let t = &tr.time_s;
            let rate = c
                .windows(2)
                .zip(t.windows(2))
                .map(|(c, t)| ((c[1] - c[0]) / (t[1] - t[0])).abs())
                .fold(0.0, f64::max);
            println!("FrequencyExcursion: fastest gate rate {rate:.5} pu/s");
            assert!(
                rate > 0.0039 && rate < 0.0040001,
                "the gate moves at VELM = 0.004 pu/s (fastest {rate})"
            );
        }
    }
}

/// Set-point offsets are nuisances added after the initialisation, in a diagram's `reference`
/// block as in the built-in models: with `v_ref_offset` and `n_ref_offset` non-zero the
/// diagrams initialise (before, the steady-state check included the offset and refused every
/// non-zero value, so a fit could not free it) and reproduce the built-in blocks, whose offsets
/// act from t = 0.
#[test]
fn the_diagrams_reference_offsets_act_after_initialisation_like_the_builtin_ones() {
    let ev = Event::from_toml_file(&data("itaipu/event.toml")).unwrap();
    let base = itaipu_text()
        .replacen("[exciter]\n", "[exciter]\nv_ref_offset = 0.004\n", 1)
        .replacen("[governor]\n", "[governor]\nn_ref_offset = 0.002\n", 1);
    assert!(base.contains("v_ref_offset = 0.004") && base.contains("n_ref_offset = 0.002"));
    check(&base, &ev, "itaipu with offsets");
    // The offsets move the playback: the comparison is not of the offset-free runs.
    let plain = simulate(&unit(&itaipu_text()), &ev, &SimOptions::default()).unwrap();
    let shifted = simulate(&unit(&base), &ev, &SimOptions::default()).unwrap();
    let (d, at) = max_dev(&plain, &shifted, &["q_pu", "pm"]);
    assert!(d > 1e-3, "the offsets move Q or P_m by only {d:.2e} ({at})");
}
