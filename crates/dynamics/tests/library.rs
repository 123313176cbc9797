//! The model library as a whole: what every registered model gets by its registration line,
//! with no test of its own. Every exciter, stabiliser and governor starts in exact steady state
//! at several operating points; every model with a PSS/E record reads a record of the model
//! back to the same parameters, options and wiring and writes it back bit for bit; every model
//! declares the roles of its kind, naming its own parameters; docs/model-library.md's table is
//! the registry's. Then the thermal unit of issue 64 (GENROU, ESST4B, PSS2A, IEEEG1) read from a
//! planning `.dyr`, simulated and written back within the round-trip guard, and the refusal of
//! a record the engine lacks.

use std::path::{Path, PathBuf};

use itaipu_dynamics::block::InitPoint;
use itaipu_dynamics::dyr::{
    parse_dyr, parse_dyr_with, write_dyr, write_dyr_checked, DyrBases, DyrReadOptions,
};
use itaipu_dynamics::integrate::OdeSystem;
use itaipu_dynamics::registry::{self, Role};
use itaipu_dynamics::simulate::{simulate, SimOptions};
use itaipu_dynamics::synthetic::{synthesize, PmuNoise, VoltageProfile};
use itaipu_dynamics::unit::{Playback, PlaybackInput, Unit};

fn repo(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../..")
        .join(rel)
}

fn bases() -> DyrBases {
    DyrBases {
        mbase: 700.0,
        nominal_hz: 60.0,
        zr: Some(0.0025),
        zx: None,
        name: None,
    }
}

/// GENROU with `model` in its role's section (and SEXS in front of a stabiliser, so that its
/// output acts).
fn unit_with(model: &str) -> Unit {
    let info = registry::find(model).unwrap();
    let mut u = Unit::new("library", 700.0, 60.0);
    u.add("machine", registry::find("GENROU").unwrap().create(), &[])
        .unwrap();
    if info.role == Role::Pss {
        u.add("exciter", registry::find("SEXS").unwrap().create(), &[])
            .unwrap();
    }
    u.add(info.role.section(), info.create(), &[]).unwrap();
    u.finish().unwrap();
    u
}

fn controllers() -> impl Iterator<Item = &'static registry::ModelInfo> {
    registry::all().filter(|m| matches!(m.role, Role::Exciter | Role::Pss | Role::Governor))
}

fn op(p: f64, q: f64, v: f64, ang_deg: f64, f_hz: f64) -> InitPoint {
    InitPoint {
        v_mag: v,
        v_ang: ang_deg.to_radians(),
        p,
        q,
        speed_dev: (f_hz - 60.0) / 60.0,
    }
}

/// Max |dx/dt| at t = 0 of a playback that holds the operating point (δ less its ramp at an
/// off-nominal frequency).
fn worst_derivative(u: &mut Unit, op: &InitPoint) -> Result<(f64, String), String> {
    let x = u.initialise(op).map_err(|e| e.to_string())?;
    let w_b = 2.0 * std::f64::consts::PI * 60.0;
    let input = PlaybackInput::linear(
        vec![0.0, 1.0],
        vec![op.v_mag, op.v_mag],
        vec![op.v_ang, op.v_ang + w_b * op.speed_dev],
    );
    let names = u.state_names();
    let mut sys = Playback::new(u, &input);
    let mut dx = vec![0.0; x.len()];
    sys.rhs(0.0, &x, &mut dx);
    let mut worst = (0.0, String::new());
    for (k, d) in dx.iter().enumerate() {
        let d = if names[k] == "machine.delta" {
            d - w_b * op.speed_dev
        } else {
            *d
        };
        if d.abs() > worst.0 || d.is_nan() {
            worst = (d.abs(), names[k].clone());
        }
    }
    Ok(worst)
}

#[test]
fn every_controller_of_the_library_starts_in_exact_steady_state() {
    let points = [
        ("lagging", op(0.8, 0.2, 1.0, 17.0, 60.0)),
        ("leading", op(0.9, -0.2, 1.02, -30.0, 60.0)),
        ("light load", op(0.3, 0.05, 0.97, 0.0, 60.0)),
        ("off-nominal 59.8 Hz", op(0.7, 0.1, 1.0, -40.0, 59.8)),
    ];
    let mut checked = 0;
    for m in controllers() {
        let mut u = unit_with(m.name);
        for (label, op) in &points {
            let (d, state) = worst_derivative(&mut u, op)
                .unwrap_or_else(|e| panic!("{} at {label}: {e}", m.name));
            assert!(d < 1e-9, "{} at {label}: |d{state}/dt| = {d:e}", m.name);
        }
        checked += 1;
    }
    assert!(checked >= 13, "{checked} controllers");
}

/// A value of parameter `i` inside its plausible range and different from the typical one, so
/// that a record read back to the typical value (a CON the writer drops) shows.
fn distinct(lo: f64, hi: f64, typical: f64, i: usize) -> f64 {
    let v = lo + (hi - lo) * (0.3 + 0.4 * ((i as f64 * 0.618) % 1.0));
    if v == typical {
        0.5 * (v + hi)
    } else {
        v
    }
}

#[test]
fn every_record_of_the_library_reads_back_bit_for_bit() {
    let mut checked = vec![];
    for m in registry::all().filter(|m| m.dyr.is_some() && m.role != Role::Machine) {
        let mut u = unit_with(m.name);
        let section = m.role.section();
        // Every parameter the record holds at a distinct value inside its range.
        let layout = m.dyr.as_ref().unwrap();
        for (i, con) in layout.cons.iter().enumerate() {
            let r = u.param(&format!("{section}.{con}")).unwrap();
            let (lo, hi) = u.param_spec(r).range;
            u.set(r, distinct(lo, hi, u.param_spec(r).typical, i));
        }
        let text = write_dyr(&u, 5, "G1");
        assert!(text.warnings.is_empty(), "{}: {:?}", m.name, text.warnings);
        let back = parse_dyr(&text.dyr, Path::new("w.dyr"), Some((5, "G1")), &bases())
            .unwrap_or_else(|e| panic!("{}: {e}\n{}", m.name, text.dyr));
        let (a, b) = (u.block(section).unwrap(), back.unit.block(section).unwrap());
        assert_eq!(a.model(), b.model());
        for (i, s) in a.params().specs().iter().enumerate() {
            assert_eq!(
                a.params().get(i).to_bits(),
                b.params().get(i).to_bits(),
                "{}.{} read back differs",
                m.name,
                s.name
            );
        }
        assert_eq!(a.options(), b.options(), "{}", m.name);
        checked.push(m.name);
    }
    assert!(checked.len() >= 11, "{checked:?}");
}

#[test]
fn every_controller_declares_the_roles_of_its_kind_naming_its_own_parameters() {
    for m in controllers() {
        let b = m.create();
        let (ident, what) = match m.role {
            Role::Exciter => {
                let r = b
                    .exciter_roles()
                    .unwrap_or_else(|| panic!("{}: no exciter roles", m.name));
                r.check(b.params())
                    .unwrap_or_else(|e| panic!("{}: {e}", m.name));
                (r.identifiable(), "exciter")
            }
            Role::Pss => {
                let r = b
                    .pss_roles()
                    .unwrap_or_else(|| panic!("{}: no stabiliser roles", m.name));
                r.check(b.params())
                    .unwrap_or_else(|e| panic!("{}: {e}", m.name));
                (r.identifiable(), "stabiliser")
            }
            _ => {
                let r = b
                    .governor_roles()
                    .unwrap_or_else(|| panic!("{}: no governor roles", m.name));
                r.check(b.params())
                    .unwrap_or_else(|e| panic!("{}: {e}", m.name));
                (r.identifiable(), "governor")
            }
        };
        // A default calibration frees something of every model but the constant P_m.
        assert!(
            !ident.is_empty() || m.name == "constant_pm",
            "{}: no identifiable {what} parameter",
            m.name
        );
    }
}

#[test]
fn the_library_table_of_the_docs_is_the_registry_s() {
    let doc = std::fs::read_to_string(repo("docs/model-library.md")).unwrap();
    let table = registry::library_table();
    let (begin, end) = (
        "<!-- library table: begin -->\n",
        "<!-- library table: end -->",
    );
    let a = doc.find(begin).expect("begin marker") + begin.len();
    let b = doc.find(end).expect("end marker");
    assert!(
        doc[a..b] == table,
        "docs/model-library.md's table is stale: replace it with the output of `itaipu-calib models --table`:\n{table}"
    );
}

/// Published-style records of the new models (PSS/E's field order): the values land on the
/// parameters the manual names.
#[test]
fn pss_e_records_put_each_value_on_the_named_parameter() {
    let text = "\
1 'GENROU' 1 6.0 0.05 1.0 0.08 3.5 0.0 1.0 0.65 0.3 0.65 0.22 0.15 0.0 0.0 /
1 'ESST4B' 1 0.02 4.0 2.0 5.0 -5.0 0.05 1.0 1.0 2.0 -2.0 0.1 6.0 0.1 10.0 0.08 0.02 5.0 /
1 'PSS2A' 1 1 0 3 0 5 1 10 10 0 10 0 10 1.47 1 0.5 0.1 2.4 0.16 0.02 0.16 0.02 0.1 -0.1 /
1 'TGOV1' 1 0.05 0.49 33.0 0.4 2.1 7.0 0.0 /
";
    let d = parse_dyr(text, Path::new("x.dyr"), None, &bases()).unwrap();
    let get = |p: &str| {
        let u = &d.unit;
        u.get(u.param(p).unwrap())
    };
    for (p, v) in [
        ("exciter.k_pr", 4.0),
        ("exciter.k_ir", 2.0),
        ("exciter.vm_min", -2.0),
        ("exciter.k_g", 0.1),
        ("exciter.k_p", 6.0),
        ("exciter.theta_p", 5.0),
        ("pss.tw1", 10.0),
        ("pss.t6", 0.0),
        ("pss.ks2", 1.47),
        ("pss.t8", 0.5),
        ("pss.t9", 0.1),
        ("pss.ks1", 2.4),
        ("pss.vst_min", -0.1),
        ("governor.t1", 0.49),
        ("governor.v_max", 33.0),
        ("governor.v_min", 0.4),
        ("governor.t3", 7.0),
    ] {
        assert_eq!(get(p), v, "{p}");
    }
    let pss = d.unit.instances().iter().find(|i| i.name == "pss").unwrap();
    assert_eq!(
        pss.rewiring(),
        vec![],
        "ICS1 = 1 (speed), ICS2 = 3 (P_e): the default wiring"
    );
    assert_eq!(
        pss.block.options(),
        vec![("m", "5".to_string()), ("n", "1".to_string())]
    );
    // An input code the engine has no signal for, a remote bus, a second machine: refused
    // naming the field.
    for (rec, says) in [
        (
            "1 'PSS2A' 1 2 0 3 0 5 1 10 10 0 10 0 10 1.47 1 0.5 0.1 2.4 0.16 0.02 0.16 0.02 0.1 -0.1 /",
            "ICS1 = 2 (bus frequency deviation)",
        ),
        (
            "1 'PSS2A' 1 1 0 3 7 5 1 10 10 0 10 0 10 1.47 1 0.5 0.1 2.4 0.16 0.02 0.16 0.02 0.1 -0.1 /",
            "remote bus REMBUS2 = 7",
        ),
        (
            "1 'IEEEG1' 1 9 1 20 0.1 0 0.1 0.5 -0.5 1 0 0.3 0.3 0 7 0.4 0 0.5 0.3 0 0 0 0 /",
            "JBUS = 9",
        ),
        (
            "1 'PSS2A' 1 1 0 3 0 5 2 10 10 0 10 0 10 1.47 1 0.5 0.1 2.4 0.16 0.02 0.16 0.02 0.1 -0.1 /",
            "exceeds 8",
        ),
    ] {
        let t = format!("{}\n{rec}\n", text.lines().next().unwrap());
        let e = parse_dyr(&t, Path::new("x.dyr"), None, &bases())
            .err()
            .unwrap_or_else(|| panic!("accepted: {rec}"))
            .to_string();
        assert!(e.contains("x.dyr line 2") && e.contains(says), "{e}");
    }
}

/// The thermal unit of issue 64: a four-record planning `.dyr` (GENROU, ESST4B, PSS2A, IEEEG1)
/// reads, starts in steady state, plays back a fault dip with the limits reached, and writes
/// back to a `.dyr` that plays back within the round-trip guard.
#[test]
fn the_thermal_unit_reads_simulates_and_writes_back_within_the_guard() {
    let path = repo("data/thermal/unit.dyr");
    let text = std::fs::read_to_string(&path).unwrap();
    let d = parse_dyr(&text, &path, None, &bases()).unwrap();
    assert_eq!(
        d.used.iter().map(|u| u.1.as_str()).collect::<Vec<_>>(),
        vec!["GENROU", "ESST4B", "PSS2A", "IEEEG1"]
    );
    assert!(d.warnings.is_empty(), "{:?}", d.warnings);
    let profile = VoltageProfile {
        duration_s: 10.0,
        ..Default::default()
    };
    let ev = synthesize(
        "dip",
        &d.unit,
        &profile,
        700.0,
        &PmuNoise::typical(3),
        &SimOptions::default(),
    )
    .unwrap();
    let tr = simulate(&d.unit, &ev, &SimOptions::default()).unwrap();
    let range = |n: &str| {
        let c = tr.get(n).unwrap();
        c.iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
                (a.min(*v), b.max(*v))
            })
    };
    // The field voltage and the stabiliser move, the valve follows the frequency fall.
    let (efd_lo, efd_hi) = range("efd");
    let (vs_lo, vs_hi) = range("vs");
    let (pm_lo, pm_hi) = range("pm");
    assert!(efd_hi - efd_lo > 0.5, "E_fd {efd_lo}..{efd_hi}");
    assert!(vs_hi - vs_lo > 0.01, "V_S {vs_lo}..{vs_hi}");
    assert!(pm_hi - pm_lo > 1e-3, "P_m {pm_lo}..{pm_hi}");
    let w = write_dyr_checked(
        &d.unit,
        d.bus,
        &d.id,
        &[ev],
        &SimOptions::default(),
        itaipu_dynamics::dyr::ROUND_TRIP_TOL_PU,
        Path::new("back.dyr"),
    )
    .unwrap();
    assert!(w.faithful(), "{:?} {:?}", w.lost, w.events);
    assert!(w.lost.is_empty(), "{:?}", w.lost);
}

#[test]
fn a_record_the_engine_lacks_is_refused_naming_what_the_unit_would_lack() {
    let path = repo("data/thermal/unit.dyr");
    let text = std::fs::read_to_string(&path).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    // Each of the unit's controllers replaced by a record of a model the engine lacks.
    for (line, model, fields, lacks) in [
        (2, "ESAC7B", "0 1 1 1 1 1 1 1 1 1 1 1", "the exciter (E_fd held at its initial value"),
        (3, "PSS2B", "1 0 3 0 5 1 10 10 0 10 0 10 1.47 1 0.5 0.1 2.4 0.16 0.02 0.16 0.02 0.1 -0.1 0.1 0.1 0.1 0.1", "the stabiliser (V_S held at 0"),
        (4, "GGOV1", "0 0 0 0.04 1 1 1 0.5 0.5 0.1 1 0 0 1 0 0 0 0 0 0 0", "the governor (P_m held at its initial value"),
    ] {
        let mut l = lines.clone();
        let rec = format!("1 '{model}' 1 {fields} /");
        l[line - 1] = &rec;
        let t = l.join("\n") + "\n";
        let e = parse_dyr(&t, &path, None, &bases()).err().unwrap();
        assert_eq!(e.kind(), "unsupported");
        let msg = e.to_string();
        assert!(
            msg.contains(&format!("line {line}: model {model} (bus 1, id '1') is not supported")),
            "{msg}"
        );
        assert!(msg.contains(lacks), "{model}: {msg}");
        // Asked to build without it: the unit says what it lacks, and the plausibility layer
        // (every report's warnings) repeats it.
        let opts = DyrReadOptions {
            select: None,
            skip_unsupported: true,
        };
        let d = parse_dyr_with(&t, &path, &bases(), &opts).unwrap();
        assert_eq!(d.unit.lacks.len(), 1);
        let f = itaipu_dynamics::plausibility::check_unit(&d.unit, Path::new("u.toml"));
        assert!(
            f.iter().any(|f| f.kind == "model_missing" && f.message.contains(model)),
            "{f:?}"
        );
        // The unit file keeps it.
        let toml = itaipu_dynamics::unit_file::unit_to_toml(&d.unit);
        let again = itaipu_dynamics::unit_file::parse_unit(&toml, Path::new("u.toml")).unwrap();
        assert_eq!(again.lacks, d.unit.lacks);
    }
}
