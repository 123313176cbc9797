//! PSS/E `.dyr`: the bundled Itaipu unit written by hand as a `.dyr` reads to the unit file's
//! parameters and plays back identically; read → write → read keeps every parameter bit for bit
//! for each supported model; malformed files are typed errors naming the file and the line;
//! unsupported records are warnings naming the line.

use std::path::{Path, PathBuf};

use itaipu_dynamics::dyr::{parse_dyr, read_dyr, write_dyr, DyrBases, DyrError, PartialBases};
use itaipu_dynamics::event::{Event, Record};
use itaipu_dynamics::registry;
use itaipu_dynamics::simulate::{simulate, SimOptions};
use itaipu_dynamics::unit::Unit;
use itaipu_dynamics::unit_file::read_unit;

fn data(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../data")
        .join(rel)
}

fn bases(mbase: f64, zx: Option<f64>) -> DyrBases {
    DyrBases {
        mbase,
        nominal_hz: 60.0,
        zr: Some(0.0025),
        zx,
        name: None,
    }
}

fn params_of(u: &Unit) -> Vec<(String, f64)> {
    u.params().into_iter().map(|(p, _, v)| (p, v)).collect()
}

#[test]
fn the_hand_written_itaipu_dyr_gives_the_unit_file_parameters_and_the_same_playback() {
    let toml_unit = read_unit(&data("itaipu/unit.toml")).unwrap();
    let b = DyrBases::from_file(&data("itaipu/unit.bases.toml")).unwrap();
    let d = read_dyr(&data("itaipu/unit.dyr"), None, &b).unwrap();
    assert!(d.warnings.is_empty(), "{:?}", d.warnings);
    assert_eq!((d.bus, d.id.as_str()), (1, "1"));
    assert_eq!(d.unit.name, toml_unit.name);
    assert_eq!(d.unit.machine_mva, toml_unit.machine_mva);
    assert_eq!(d.unit.nominal_hz, toml_unit.nominal_hz);
    // The unit file's constant_pm governor is the absence of a governor record (P_m held).
    let expected: Vec<(String, f64)> = params_of(&toml_unit)
        .into_iter()
        .filter(|(p, _)| !p.starts_with("governor."))
        .collect();
    assert_eq!(params_of(&d.unit), expected);

    let event = Event::from_toml_file(&data("itaipu/event.toml")).unwrap();
    let a = simulate(&toml_unit, &event, &SimOptions::default()).unwrap();
    let c = simulate(&d.unit, &event, &SimOptions::default()).unwrap();
    for col in ["p_pu", "q_pu"] {
        assert_eq!(a.get(col).unwrap(), c.get(col).unwrap(), "{col}");
    }
}

/// A unit of the given models with every parameter moved off its typical value (so that a
/// dropped or swapped CON shows), X''q = X''d as PSS/E has it.
fn unit_of(models: &[(&str, &str)], ieeest_input: Option<&str>) -> Unit {
    let mut u = Unit::new("rt", 737.0, 60.0);
    for (k, (role, model)) in models.iter().enumerate() {
        let mut b = registry::find(model).unwrap().create();
        let n = b.params().specs().len();
        for i in 0..n {
            let s = b.params().specs()[i];
            if s.name.ends_with("_offset") {
                continue;
            }
            let f = 1.0 + 0.0137 * (((i + k) % 5) as f64 - 2.0);
            let v = b.params().get(i) * f;
            b.params_mut().set(i, v);
        }
        if let (Some(xd), Some(xq)) = (b.params().index_of("x_d_pp"), b.params().index_of("x_q_pp"))
        {
            let v = b.params().get(xd);
            b.params_mut().set(xq, v);
        }
        let rew = match (*model, ieeest_input) {
            ("IEEEST", Some(sig)) => vec![("u".to_string(), sig.to_string())],
            _ => vec![],
        };
        b.validate().unwrap_or_else(|e| panic!("{model}: {e}"));
        u.add(role, b, &rew).unwrap();
    }
    u.finish().unwrap();
    u
}

#[test]
fn read_write_read_keeps_every_parameter_of_every_supported_model() {
    type Combo<'a> = (Vec<(&'a str, &'a str)>, Option<&'a str>);
    let combos: Vec<Combo> = vec![
        (
            vec![
                ("machine", "GENSAE"),
                ("exciter", "SEXS"),
                ("pss", "STAB3"),
                ("governor", "HYGOV"),
            ],
            None,
        ),
        (
            vec![
                ("machine", "GENSAL"),
                ("exciter", "SEXS"),
                ("pss", "IEEEST"),
                ("governor", "HYGOV"),
            ],
            Some("pe"),
        ),
        (
            vec![
                ("machine", "GENROU"),
                ("exciter", "SEXS"),
                ("pss", "IEEEST"),
            ],
            None,
        ),
        (
            vec![
                ("machine", "GENROU"),
                ("exciter", "SEXS"),
                ("pss", "IEEEST"),
            ],
            Some("v_term"),
        ),
        (vec![("machine", "GENCLS"), ("governor", "HYGOV")], None),
    ];
    for (models, input) in combos {
        let u = unit_of(&models, input);
        let w = write_dyr(&u, 3001, "G1");
        assert!(w.warnings.is_empty(), "{models:?}: {:?}", w.warnings);
        let b = DyrBases::parse(&w.bases, Path::new("rt.bases.toml"), None).unwrap();
        let d = parse_dyr(&w.dyr, Path::new("rt.dyr"), Some((3001, "G1")), &b).unwrap();
        assert!(d.warnings.is_empty(), "{models:?}: {:?}", d.warnings);
        assert_eq!(params_of(&d.unit), params_of(&u), "{models:?}\n{}", w.dyr);
        assert_eq!(
            d.unit
                .instances()
                .iter()
                .map(|i| i.rewiring())
                .collect::<Vec<_>>(),
            u.instances()
                .iter()
                .map(|i| i.rewiring())
                .collect::<Vec<_>>(),
            "{models:?}: wiring"
        );
        // Written again, the same text.
        assert_eq!(write_dyr(&d.unit, 3001, "G1").dyr, w.dyr);
    }
}

#[test]
fn a_dyr_read_unit_initialises_in_steady_state_and_plays_back() {
    // GENROU + SEXS + IEEEST on P_e (IC = 3; a power-input stabiliser has a negative gain, a
    // speed-tuned KS on P_e destabilises the loop) + HYGOV, selected among other units.
    let text = "\
 7 'GENSAE' 1 7 0.05 0.1 4.5 0 0.95 0.65 0.3 0.22 0.15 0.1 0.3 /
 1 'GENROU' 'G1' 7.0 0.05 0.7 0.1 4.5 0.0 0.95 0.65 0.30 0.5 0.22 0.15 0.1 0.3 /
 1 'SEXS' 'G1' 0.2 10 100 0.05 0 4.5 /
 1 'IEEEST' 'G1' 3 0  0 0 0 0 0 0  0.15 0.03 0.15 0.03 1.65 1.65  -0.3 0.26 -0.1 0 0 /
 1 'HYGOV' 'G1' 0.05 0.3 5 0.05 0.5 0.2 1 0 1.2 1.2 0.5 0.08 /
";
    let d = parse_dyr(
        text,
        Path::new("sys.dyr"),
        Some((1, "G1")),
        &bases(737.0, None),
    )
    .unwrap();
    assert_eq!(
        d.used.iter().map(|u| u.1.as_str()).collect::<Vec<_>>(),
        ["GENROU", "SEXS", "IEEEST", "HYGOV"]
    );
    assert_eq!(d.warnings.len(), 1, "{:?}", d.warnings); // the other unit on bus 7
    assert!(d.warnings[0].msg.contains("bus 7"), "{}", d.warnings[0]);
    // A flat record at a lagging operating point: a unit in exact steady state keeps P and Q.
    let n = 121;
    let t: Vec<f64> = (0..n).map(|k| k as f64 / 60.0).collect();
    let rec = Record::from_rectangular(
        t,
        &vec![1.01; n],
        &vec![0.12; n],
        vec![0.55; n],
        vec![0.11; n],
    );
    let event = Event::from_record("flat", rec, 1000.0, 60.0, None, None).unwrap();
    let tr = simulate(&d.unit, &event, &SimOptions::default()).unwrap();
    for (col, want) in [("p_pu", 0.55), ("q_pu", 0.11)] {
        let dev = tr
            .get(col)
            .unwrap()
            .iter()
            .map(|x| (x - want).abs())
            .fold(0.0, f64::max);
        assert!(dev < 1e-7, "{col}: off steady state by {dev}");
    }
}

fn err(text: &str, select: Option<(i64, &str)>, b: &DyrBases) -> DyrError {
    match parse_dyr(text, Path::new("bad.dyr"), select, b) {
        Ok(_) => panic!("accepted:\n{text}"),
        Err(e) => e,
    }
}

#[test]
fn malformed_records_are_errors_naming_file_and_line() {
    let good = "1 'GENCLS' 1 4.5 0.0 /\n";
    let b = bases(700.0, Some(0.3));
    type Case<'a> = (&'a str, String, Option<(i64, &'a str)>, &'a str, &'a str);
    let cases: Vec<Case> = vec![
        ("no terminating slash", "1 'GENCLS' 1\n 4.5 0.0\n".into(), None, "syntax", "line 1: record not terminated"),
        ("bus not an integer", format!("{good}x1 'SEXS' 1 0.2 10 100 0.05 0 4 /\n"), None, "syntax", "line 2: bus number 'x1'"),
        ("CON not a number", "1 'GENCLS' 1 4.5\n zero /\n".into(), None, "record", "line 2: GENCLS: CON 2 (D) = 'zero'"),
        ("too few CONs", "1 'GENCLS' 1 4.5 /\n".into(), None, "record", "line 1: GENCLS: 2 values expected"),
        ("unclosed quote", "1 'GENCLS 1 4.5 0 /\n".into(), None, "syntax", "line 1: string"),
        ("too short", "1 'GENCLS' /\n".into(), None, "syntax", "line 1: record"),
        ("second machine", format!("{good}\n1 'GENSAL' 1 7 0.05 0.1 4.5 0 0.95 0.65 0.3 0.22 0.15 0.1 0.3 /\n"), None, "record", "line 3: GENSAL: a second machine model"),
        ("refused value", "1 'GENCLS' 1 0.0 0.0 /\n".into(), None, "record", "line 1: GENCLS"),
        ("exciter on GENCLS", format!("{good}1 'SEXS' 1 0.2 10 100 0.05 0 4 /\n"), None, "record", "line 2: SEXS: GENCLS"),
        ("unit not in the file", good.into(), Some((2, "1")), "selection", "no record for bus 2 id '1' (units in the file: bus 1 id '1')"),
        ("several machines, none chosen", format!("{good}2 'GENCLS' 1 4.5 0.0 /\n"), None, "selection", "2 machines"),
        ("no machine", "1 'SEXS' 1 0.2 10 100 0.05 0 4 /\n".into(), Some((1, "1")), "selection", "no machine record"),
        ("IEEEST input without a signal", "1 'GENSAE' 1 7 0.05 0.1 4.5 0 0.95 0.65 0.3 0.22 0.15 0.1 0.3 /\n1 'SEXS' 1 0.2 10 100 0.05 0 4.5 /\n1 'IEEEST' 1\n 2 0 0 0 0 0 0 0 0.15 0.03 0.15 0.03 1.65 1.65 6.2 0.26 -0.1 0 0 /\n".into(), None, "record", "line 4: IEEEST: input code IC = 2"),
        ("IEEEST remote bus", "1 'GENSAE' 1 7 0.05 0.1 4.5 0 0.95 0.65 0.3 0.22 0.15 0.1 0.3 /\n1 'IEEEST' 1 1 5 0 0 0 0 0 0 0.15 0.03 0.15 0.03 1.65 1.65 6.2 0.26 -0.1 0 0 /\n".into(), None, "record", "line 2: IEEEST: remote bus IB = 5"),
    ];
    for (what, text, select, kind, mention) in cases {
        let e = err(&text, select, &b);
        let msg = e.to_string();
        assert_eq!(e.kind(), kind, "{what}: {msg}");
        assert!(msg.starts_with("bad.dyr"), "{what}: {msg}");
        assert!(
            msg.contains(mention),
            "{what}: '{msg}' should contain '{mention}'"
        );
    }
    // GENCLS takes X'd from ZSORCE X: without it, a bases error naming zx.
    let e = err(good, None, &bases(700.0, None));
    assert_eq!(e.kind(), "bases");
    assert!(
        e.to_string().contains("zx") && e.to_string().contains("line 1"),
        "{e}"
    );
}

#[test]
fn unsupported_records_are_warnings_naming_the_line_and_the_unit_is_built_without_them() {
    let text = "\
1 'GENSAE' 1 7 0.05 0.1 4.5 0 0.95 0.65 0.3 0.22 0.15 0.1 0.3 /
1 'ESAC1A' 1 1 1 0 0.01 0 0 1 1 100 0.1 /
1 'USRMDL' 1 'MYGOV' 501 0 0 3 0 0 1 2 3 /
1 'SEXS' 1 0.2 10 100 0.05 0 4.5 /
";
    let b = DyrBases {
        zr: None,
        zx: Some(0.25),
        ..bases(737.0, None)
    };
    let d = parse_dyr(text, Path::new("u.dyr"), None, &b).unwrap();
    let w: Vec<String> = d.warnings.iter().map(|w| w.to_string()).collect();
    assert!(
        w.iter()
            .any(|m| m.starts_with("u.dyr line 2: model ESAC1A (bus 1, id '1') is not supported")),
        "{w:?}"
    );
    assert!(
        w.iter()
            .any(|m| m.starts_with("u.dyr line 3: user model MYGOV")),
        "{w:?}"
    );
    assert!(
        w.iter()
            .any(|m| m.starts_with("u.dyr line 1: GENSAE: R_a = 0")),
        "{w:?}"
    );
    assert!(
        w.iter()
            .any(|m| m.contains("ZSORCE X = 0.25 differs from X'' = 0.22")),
        "{w:?}"
    );
    assert_eq!(
        d.used,
        vec![(1, "GENSAE".to_string()), (4, "SEXS".to_string())]
    );
}

#[test]
fn the_writer_names_what_pss_e_cannot_hold() {
    let mut u = unit_of(&[("machine", "GENSAE"), ("exciter", "SEXS")], None);
    let r = u.param("machine.x_q_pp").unwrap();
    u.set(r, 0.25);
    let shaft = registry::find("two_mass_shaft").unwrap().create();
    u.add("shaft", shaft, &[]).unwrap();
    let w = write_dyr(&u, 1, "1");
    assert!(
        w.warnings.iter().any(|m| m.contains("X''q = 0.25")),
        "{:?}",
        w.warnings
    );
    assert!(
        w.warnings
            .iter()
            .any(|m| m.contains("'shaft' (two_mass_shaft)")),
        "{:?}",
        w.warnings
    );
}

#[test]
fn bases_come_from_the_side_file_or_the_command_line() {
    let p = Path::new("b.toml");
    let e = DyrBases::parse("nominal_hz = 60\n", p, None).unwrap_err();
    assert!(e.to_string().starts_with("b.toml: mbase: missing"), "{e}");
    let over = PartialBases {
        mbase: Some(800.0),
        ..Default::default()
    };
    let b = DyrBases::parse("nominal_hz = 60\nmbase = 1\n", p, Some(&over)).unwrap();
    assert_eq!(b.mbase, 800.0);
    let e = DyrBases::parse("mbase = 1\nnominal_hz = 60\nsbase = 100\n", p, None).unwrap_err();
    assert!(e.to_string().contains("sbase: unknown key"), "{e}");
    let e = DyrBases::parse("mbase = -1\nnominal_hz = 60\n", p, None).unwrap_err();
    assert!(
        e.to_string().contains("mbase: must be a finite number > 0"),
        "{e}"
    );
}
