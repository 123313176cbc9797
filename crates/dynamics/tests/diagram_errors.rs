//! Bad diagrams are refused with an error naming the file, the block and the field; diagrams
//! that cannot start in steady state name the block; a diagram unit round-trips through
//! `unit_to_toml` and its parameters are addressed like any model's (`exciter.k`).

use std::path::{Path, PathBuf};

use itaipu_dynamics::event::Event;
use itaipu_dynamics::simulate::{simulate, SimOptions};
use itaipu_dynamics::unit_file::{parse_unit, unit_to_toml, UnitFileError};

fn data(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../data")
        .join(rel)
}

const UNIT_HEAD: &str = "name = \"u\"\nmachine_mva = 737.0\nnominal_hz = 60.0\n";

fn machine() -> String {
    let t = std::fs::read_to_string(data("itaipu/unit.toml")).unwrap();
    let a = t.find("[machine]").unwrap();
    let b = t.find("[exciter]").unwrap();
    t[a..b].to_string()
}

const SEXS_DEF: &str = r#"
[exciter.diagram]
title = "inline SEXS"
inputs = { vt = "v_term", vs = "vs" }
outputs = { efd = "efd" }
[exciter.diagram.params]
k = { range = [30.0, 400.0], min = 0.0, unit = "pu", doc = "gain" }
te = { range = [0.02, 0.1], min = 0.0, unit = "s", doc = "time constant" }
[[exciter.diagram.block]]
name = "v_ref"
type = "reference"
out = "vref"
[[exciter.diagram.block]]
name = "error"
type = "sum"
in = ["vref", "vt", "vs"]
signs = "+-+"
out = "v_err"
[[exciter.diagram.block]]
name = "exc"
type = "lag"
in = "v_err"
k = "k"
t = "te"
min = 0.0
max = 6.0
out = "efd"
"#;

const PSS: &str =
    "[pss]\nmodel = \"STAB3\"\nt_t = 0.1\nt_x1 = 0.04\nt_x2 = 3.0\nk_x = 1.0\nv_lim = 0.1\n";

fn unit_text(def: &str) -> String {
    format!(
        "{UNIT_HEAD}{}[exciter]\nmodel = \"diagram\"\nk = 100.0\nte = 0.05\n{def}\n{PSS}",
        machine()
    )
}

fn err(text: &str) -> UnitFileError {
    match parse_unit(text, Path::new("bad-unit.toml")) {
        Ok(_) => panic!("accepted:\n{text}"),
        Err(e) => e,
    }
}

#[test]
fn an_inline_diagram_runs_round_trips_and_exposes_its_parameters() {
    let text = unit_text(SEXS_DEF);
    let u = parse_unit(&text, Path::new("u.toml")).unwrap();
    let r = u.param("exciter.k").unwrap();
    assert_eq!(u.get(r), 100.0);
    assert_eq!(u.param_spec(r).unit, "pu");
    assert!(u.param("exciter.nope").is_err());
    // Written back with its definition inline, it reads again and simulates identically.
    let back = unit_to_toml(&u);
    assert!(
        back.contains("[exciter.diagram]") && back.contains("[[exciter.diagram.block]]"),
        "{back}"
    );
    let u2 = parse_unit(&back, Path::new("again.toml")).unwrap_or_else(|e| panic!("{e}\n{back}"));
    let ev = Event::from_toml_file(&data("itaipu/event.toml")).unwrap();
    let a = simulate(&u, &ev, &SimOptions::default()).unwrap();
    let b = simulate(&u2, &ev, &SimOptions::default()).unwrap();
    assert_eq!(a.get("q_pu").unwrap(), b.get("q_pu").unwrap());
    // A parameter set through the unit (as the calibrator does) changes the simulation.
    let mut u3 = u.clone();
    u3.set(r, 50.0);
    let c = simulate(&u3, &ev, &SimOptions::default()).unwrap();
    let dq = a
        .get("q_pu")
        .unwrap()
        .iter()
        .zip(c.get("q_pu").unwrap())
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max);
    assert!(dq > 1e-3, "K changes Q by {dq}");
    // The unit starts in steady state.
    let mut u4 = u.clone();
    let op = itaipu_dynamics::simulate::PreparedEvent::new(&ev).init_point(&u4);
    let x = u4.initialise(&op).unwrap();
    let mut dx = vec![0.0; x.len()];
    u4.eval_outputs(0.0, &x);
    u4.eval_derivatives(0.0, &x, &mut dx);
    // (The machine's angle turns with the pre-event frequency offset; the controls must not move.)
    let names = u4.state_names();
    let worst = names
        .iter()
        .zip(&dx)
        .filter(|(n, _)| !n.starts_with("machine"))
        .fold(0.0f64, |m, (_, v)| m.max(v.abs()));
    assert!(
        worst < 1e-9,
        "max |dx/dt| of the controls at t = 0: {worst:.3e}"
    );
}

#[test]
fn each_bad_diagram_is_refused_naming_file_block_and_field() {
    let good = unit_text(SEXS_DEF);
    parse_unit(&good, Path::new("u.toml")).unwrap();
    let cases: Vec<(&str, String, &[&str])> = vec![
        ("unknown primitive", good.replace("type = \"lag\"", "type = \"lagg\""), &["block 'exc'", "type", "unknown primitive 'lagg'"]),
        ("signal without writer", good.replace("in = \"v_err\"", "in = \"v_error\""), &["block 'exc' (lag).in", "v_error", "no writer"]),
        ("two writers", good.replace("out = \"v_err\"", "out = \"vref\""), &["block 'error' (sum).out", "two writers", "block 'v_ref'"]),
        ("dangling output", good.replace("in = [\"vref\", \"vt\", \"vs\"]", "in = [\"vt\", \"vt\", \"vs\"]"), &["block 'v_ref' (reference).out", "dangling"]),
        ("missing field", good.replace("t = \"te\"\n", ""), &["block 'exc' (lag).t", "missing"]),
        ("unknown field", good.replace("t = \"te\"\n", "t = \"te\"\ntau = 1\n"), &["block 'exc' (lag).tau", "unknown field"]),
        ("undeclared parameter in a field", good.replace("t = \"te\"", "t = \"t_e\""), &["block 'exc' (lag).t", "unknown parameter 't_e'"]),
        ("missing parameter value", good.replace("te = 0.05\n", ""), &["exciter", "needs these parameters", "te"]),
        ("parameter out of range", good.replace("k = 100.0\n", "k = -5.0\n"), &["exciter.k", "allowed range"]),
        ("field out of its domain", good.replace("te = 0.05\n", "te = 0.0\n"), &["block 'exc' (lag).t", "must be > 0"]),
        ("wrong arity", good.replace("in = \"v_err\"", "in = [\"v_err\", \"vt\"]"), &["block 'exc' (lag).in", "one input"]),
        ("bad signs", good.replace("signs = \"+-+\"", "signs = \"+-\""), &["block 'error' (sum).signs", "one + or -"]),
        ("no reference for a target", good.replace("type = \"reference\"", "type = \"constant\"\nvalue = 1.0"), &["outputs", "reference"]),
        ("unknown key", good.replace("title = \"inline SEXS\"", "title = \"x\"\ncolour = 1"), &["exciter.diagram.colour", "unknown key"]),
        ("no definition", unit_text(""), &["exciter.diagram", "missing"]),
        (
            "algebraic loop",
            good.replace("in = [\"vref\", \"vt\", \"vs\"]", "in = [\"vref\", \"vt\", \"fb\"]").replace(
                "[[exciter.diagram.block]]\nname = \"exc\"",
                "[[exciter.diagram.block]]\nname = \"loop_gain\"\ntype = \"gain\"\nin = \"v_err\"\nk = 0.5\nout = \"fb\"\n[[exciter.diagram.block]]\nname = \"exc\"",
            ),
            &["algebraic loop", "'error'", "'loop_gain'"],
        ),
    ];
    for (what, text, mentions) in cases {
        let e = err(&text);
        let msg = e.to_string();
        assert!(msg.starts_with("bad-unit.toml"), "{what}: {msg}");
        for m in mentions {
            assert!(msg.contains(m), "{what}: '{msg}' should mention {m}");
        }
    }
}

#[test]
fn an_error_in_a_diagram_file_names_that_file() {
    let dir = std::env::temp_dir().join(format!("itaipu-diagram-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let def = std::fs::read_to_string(data("diagrams/sexs.toml")).unwrap();
    std::fs::write(
        dir.join("bad.toml"),
        def.replace("type = \"lead_lag\"", "type = \"leadlag\""),
    )
    .unwrap();
    let unit = std::fs::read_to_string(data("itaipu/unit.toml"))
        .unwrap()
        .replace(
            "model = \"SEXS\"",
            "model = \"diagram\"\ndiagram = \"bad.toml\"",
        );
    let e = parse_unit(&unit, &dir.join("unit.toml"))
        .err()
        .expect("refused");
    let msg = e.to_string();
    assert!(
        msg.contains("bad.toml") && msg.contains("block 'lead_lag'") && msg.contains("leadlag"),
        "{msg}"
    );
    // A missing file is an I/O error naming it.
    let unit2 = unit.replace("bad.toml", "absent.toml");
    let e = parse_unit(&unit2, &dir.join("unit.toml"))
        .err()
        .expect("refused");
    assert_eq!(e.kind(), "io");
    assert!(e.to_string().contains("absent.toml"));
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn diagrams_that_cannot_initialise_name_the_block() {
    let ev = Event::from_toml_file(&data("itaipu/event.toml")).unwrap();
    let opts = SimOptions::default();
    let init_err = |text: &str| -> String {
        let u = parse_unit(text, Path::new("u.toml")).unwrap_or_else(|e| panic!("{e}"));
        let e = match simulate(&u, &ev, &opts) {
            Ok(tr) => panic!("initialised: efd {:?}", &tr.get("efd").unwrap()[..3]),
            Err(e) => e,
        };
        assert_eq!(e.kind(), "init", "{e}");
        e.to_string()
    };
    // A ceiling below the machine's E_fd0: a limit violated at t = 0.
    let low = unit_text(SEXS_DEF).replace("max = 6.0", "max = 1.0");
    let m = init_err(&low);
    assert!(
        m.contains("block 'exc' (lag)") && m.contains("limit violated at t = 0"),
        "{m}"
    );
    // An integrator whose steady state is not unique: it integrates ΔP = P_e − P_e(0), which
    // is zero whatever its state, and nothing feeds its state back (no reference to solve it).
    let pss = "[pss]\nmodel = \"diagram\"\n[pss.diagram]\ninputs = { pe = \"pe\" }\noutputs = { vs = \"vs\" }\n\
[[pss.diagram.block]]\nname = \"p0\"\ntype = \"initial\"\nin = \"pe\"\nout = \"p0\"\n\
[[pss.diagram.block]]\nname = \"dp\"\ntype = \"sum\"\nin = [\"pe\", \"p0\"]\nsigns = \"+-\"\nout = \"dp\"\n\
[[pss.diagram.block]]\nname = \"drift\"\ntype = \"integrator\"\nin = \"dp\"\nout = \"xi\"\n\
[[pss.diagram.block]]\nname = \"out\"\ntype = \"gain\"\nin = \"xi\"\nk = 0.01\nout = \"vs\"\n";
    let text = unit_text(SEXS_DEF).replace(PSS, pss);
    let m = init_err(&text);
    assert!(
        m.contains("block 'drift' (integrator)") && m.contains("not determined"),
        "{m}"
    );
    // With feedback (dx/dt = ΔP − 0.5 x) the same diagram starts, at x = 0.
    let ok = text.replace(
        "in = [\"pe\", \"p0\"]\nsigns = \"+-\"",
        "in = [\"pe\", \"p0\", \"xi\"]\ngains = [1, -1, -0.5]",
    );
    let u = parse_unit(&ok, Path::new("u.toml")).unwrap();
    let tr = simulate(&u, &ev, &opts).unwrap();
    assert_eq!(tr.get("pss.drift").unwrap()[0], 0.0);
}

#[test]
fn a_diagram_beside_a_builtin_block_takes_a_limiter_role() {
    // An over-excitation limiter written as a diagram, in a [[block]] beside the built-in SEXS,
    // writing the SEXS's `voel` input: inactive at the operating point, it pulls E_fd down when
    // the field current exceeds a pickup set just above its initial value.
    let base = std::fs::read_to_string(data("itaipu/unit.toml")).unwrap();
    let oel = |pickup: f64| {
        format!(
            "{base}\n[[block]]\nname = \"oel\"\nmodel = \"diagram\"\npickup = {pickup}\n[block.diagram]\n\
             inputs = {{ ifd = \"xadifd\" }}\noutputs = {{ v_oel = \"voel\" }}\n\
             [block.diagram.params]\npickup = {{ min = 0.0, unit = \"pu\" }}\n\
             [[block.diagram.block]]\nname = \"limit\"\ntype = \"constant\"\nvalue = \"pickup\"\nout = \"lim\"\n\
             [[block.diagram.block]]\nname = \"excess\"\ntype = \"sum\"\nin = [\"lim\", \"ifd\"]\nsigns = \"+-\"\nout = \"e\"\n\
             [[block.diagram.block]]\nname = \"integral\"\ntype = \"lag\"\nin = \"e\"\nk = 5.0\nt = 0.5\nout = \"ei\"\n\
             [[block.diagram.block]]\nname = \"only_above\"\ntype = \"min\"\nin = [\"ei\", \"zero\"]\nout = \"v_oel\"\n\
             [[block.diagram.block]]\nname = \"zero\"\ntype = \"constant\"\nvalue = 0\nout = \"zero\"\n"
        )
    };
    let ev = Event::from_toml_file(&data("itaipu/event.toml")).unwrap();
    let opts = SimOptions::default();
    let plain = simulate(&parse_unit(&base, Path::new("u.toml")).unwrap(), &ev, &opts).unwrap();
    let ifd = plain.get("xadifd").unwrap();
    let (ifd0, top) = (
        ifd[0],
        ifd.iter().cloned().fold(f64::NEG_INFINITY, f64::max),
    );
    assert!(
        top > ifd0 * 1.02,
        "the record drives the field current up ({ifd0} → {top})"
    );
    // Far above: no effect at all.
    let far = simulate(
        &parse_unit(&oel(10.0), Path::new("u.toml")).unwrap(),
        &ev,
        &opts,
    )
    .unwrap();
    // (Its one state joins the adaptive step's error norm: equal to the integrator's tolerance.)
    let d = plain
        .get("q_pu")
        .unwrap()
        .iter()
        .zip(far.get("q_pu").unwrap())
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    assert!(d < 1e-6, "an inactive limiter changes Q by {d:.3e}");
    assert!(far.get("voel").unwrap().iter().all(|v| *v == 0.0));
    // Just above the initial value: the limiter acts and the field current peaks lower.
    let u = parse_unit(&oel(ifd0 * 1.01), Path::new("u.toml")).unwrap();
    let near = simulate(&u, &ev, &opts).unwrap();
    let voel = near.get("voel").unwrap();
    assert_eq!(voel[0], 0.0, "inactive at t = 0");
    assert!(
        voel.iter().cloned().fold(0.0, f64::min) < -1e-3,
        "acts during the event"
    );
    let top2 = near
        .get("xadifd")
        .unwrap()
        .iter()
        .cloned()
        .fold(f64::NEG_INFINITY, f64::max);
    assert!(
        top2 < top,
        "the limiter lowers the field-current peak ({top} → {top2})"
    );
}
