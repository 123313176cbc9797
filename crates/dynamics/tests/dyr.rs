//! PSS/E `.dyr`: the bundled Itaipu unit written by hand as a `.dyr` reads to the unit file's
//! parameters and plays back identically; read → write → read keeps every parameter bit for bit
//! for each supported model; malformed files are typed errors naming the file and the line;
//! an unsupported record is refused naming the line and what the unit would lack, unless the
//! unit is to be built without it (then warnings, and the unit records what it lacks).

use std::path::{Path, PathBuf};

use itaipu_dynamics::dyr::{
    parse_dyr, parse_dyr_with, read_dyr, side_file, write_dyr, write_dyr_checked, write_dyr_file,
    DyrBases, DyrError, DyrReadOptions, DyrWrite, DyrWriteError, DyrWriteOptions, PartialBases,
    ROUND_TRIP_TOL_PU,
};
use itaipu_dynamics::event::{Event, Record};
use itaipu_dynamics::plausibility::check_unit;
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
        // The checked writer finds nothing lost.
        let c = write_dyr_checked(
            &u,
            3001,
            "G1",
            &[],
            &SimOptions::default(),
            ROUND_TRIP_TOL_PU,
            Path::new("rt.dyr"),
        )
        .unwrap();
        assert!(
            c.faithful() && c.lost.is_empty(),
            "{models:?}: {}",
            c.summary()
        );
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
fn an_unsupported_record_is_refused_naming_the_line_and_what_the_unit_would_lack_unless_asked() {
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
    // By default a record of a model the engine lacks is refused: the unit would not be the
    // file's. The error names each such line, the model and what the unit would lack.
    let e = match parse_dyr(text, Path::new("u.dyr"), None, &b) {
        Ok(_) => panic!("a unit without its ESAC1A and user governor was read"),
        Err(e) => e,
    };
    assert_eq!(e.kind(), "unsupported");
    let msg = e.to_string();
    assert!(
        msg.starts_with("u.dyr line 2: model ESAC1A (bus 1, id '1') is not supported"),
        "{msg}"
    );
    assert!(
        msg.contains("a second exciter record beside SEXS on line 4"),
        "{msg}"
    );
    assert!(
        msg.contains("u.dyr line 3: user model MYGOV (bus 1, id '1') is not supported")
            && msg.contains("the governor (P_m held at its initial value"),
        "{msg}"
    );
    // Asked to build without them: warnings, and the unit records what it lacks.
    let opts = DyrReadOptions {
        select: None,
        skip_unsupported: true,
    };
    let d = parse_dyr_with(text, Path::new("u.dyr"), &b, &opts).unwrap();
    assert_eq!(d.unit.lacks.len(), 2, "{:?}", d.unit.lacks);
    assert!(
        d.unit.lacks[1].contains("user model MYGOV (u.dyr line 3)"),
        "{:?}",
        d.unit.lacks
    );

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
    let r = u.param("exciter.v_ref_offset").unwrap();
    u.set(r, 0.004);
    let shaft = registry::find("two_mass_shaft").unwrap().create();
    u.add("shaft", shaft, &[]).unwrap();
    let w = write_dyr(&u, 1, "1");
    assert!(
        w.warnings
            .iter()
            .any(|m| m
                .starts_with("exciter.v_ref_offset = 0.004 has no place in PSS/E's SEXS record")),
        "{:?}",
        w.warnings
    );
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

// ---- Faithful round trips (issue 25 item 4): write -> read -> simulate equals the unit, or the
// ---- write is refused with J of both and what is lost.

/// The unit `itaipu-calib fit` calibrates on the bundled record (stages gen+avr+pss+tg, seed 1):
/// X''q = 0.956 against X''d = 0.204, RaPId's S(1.0) = S(1.2) = 1, a HYGOV governor.
const CALIBRATED: &str = r#"
name = "itaipu-60hz-unit"
machine_mva = 737.0
nominal_hz = 60.0
[machine]
model = "GENSAE"
t_d0_prime = 4.676291340799366
t_d0_pp = 0.478355518584614
t_q0_pp = 0.16584476048509955
h = 3.5652274014991763
d = 1.0
x_d = 2.0
x_q = 1.7988098998767226
x_d_prime = 1.5120361384127439
x_d_pp = 0.2044101216714163
x_q_pp = 0.9560276355831075
x_l = 0.13
s10 = 1.0
s12 = 1.0
r_a = 5.814855385298601e-5
[exciter]
model = "SEXS"
ta_tb = 50.0
tb = 0.023096102033575983
k = 204.34000137715867
te = 8.812869412818278
e_min = 1.0
e_max = 4.5
[pss]
model = "STAB3"
t_t = 0.36441042031602894
t_x1 = 0.423874018214716
t_x2 = 0.3738452227666129
k_x = 1.0
v_lim = 1.1
[governor]
model = "HYGOV"
r_perm = 0.05
r_temp = 0.1099641431033837
t_r = 1.0
t_f = 0.05
t_g = 0.7154781358743567
velm = 0.2
g_max = 1.0
g_min = 0.0
t_w = 2.2475462324281956
a_t = 1.2
d_turb = 0.5
q_nl = 0.08
"#;

fn calibrated() -> Unit {
    itaipu_dynamics::unit_file::parse_unit(CALIBRATED, Path::new("calibrated.toml")).unwrap()
}

fn itaipu_event() -> Event {
    Event::from_toml_file(&data("itaipu/event.toml")).unwrap()
}

/// A fresh folder under the system temp dir, removed on drop.
struct Tmp(PathBuf);
impl Tmp {
    fn new(tag: &str) -> Tmp {
        let p = std::env::temp_dir().join(format!("itaipu-dyr-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&p);
        std::fs::create_dir_all(&p).unwrap();
        Tmp(p)
    }
}
impl Drop for Tmp {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// J = Σ ΔP² + ΔQ² over the fit window of a simulation (what `simulate` prints).
fn j_of(unit: &Unit, ev: &Event) -> f64 {
    let tr = simulate(unit, ev, &SimOptions::default()).unwrap();
    let (p, q) = (tr.get("p_pu").unwrap(), tr.get("q_pu").unwrap());
    let r = &ev.record;
    (0..r.time_s.len())
        .filter(|&k| ev.fit.contains(r.time_s[k]))
        .map(|k| (p[k] - r.p_pu[k]).powi(2) + (q[k] - r.q_pu[k]).powi(2))
        .sum()
}

/// The written files read back from disk, as `--unit F.dyr` reads them.
fn read_back(out: &Path) -> Unit {
    let b = DyrBases::from_file(&side_file(out)).unwrap();
    read_dyr(out, Some((1, "1")), &b).unwrap().unit
}

fn check(u: &Unit, events: &[Event]) -> DyrWrite {
    write_dyr_checked(
        u,
        1,
        "1",
        events,
        &SimOptions::default(),
        ROUND_TRIP_TOL_PU,
        Path::new("out.dyr"),
    )
    .unwrap()
}

#[test]
fn the_bundled_itaipu_unit_round_trips_exactly_on_the_bundled_event() {
    let u = read_unit(&data("itaipu/unit.toml")).unwrap();
    let ev = itaipu_event();
    let t = Tmp::new("bundled");
    let out = t.0.join("itaipu.dyr");
    let r = write_dyr_file(&u, &out, std::slice::from_ref(&ev), &Default::default()).unwrap();
    assert!(r.faithful() && r.lost.is_empty(), "{}", r.summary());
    let c = &r.events[0];
    assert_eq!((c.max_dp, c.max_dq), (0.0, 0.0), "{c}");
    assert_eq!(c.j_written, Some(c.j_unit));
    // The files on disk play back as the unit.
    let back = read_back(&out);
    let (a, b) = (
        simulate(&u, &ev, &SimOptions::default()).unwrap(),
        simulate(&back, &ev, &SimOptions::default()).unwrap(),
    );
    for col in ["p_pu", "q_pu"] {
        assert_eq!(a.get(col).unwrap(), b.get(col).unwrap(), "{col}");
    }
}

#[test]
fn a_calibrated_unit_with_x_q_pp_apart_from_x_d_pp_is_refused_with_both_j_or_written_lossy() {
    let u = calibrated();
    let ev = itaipu_event();
    let t = Tmp::new("calibrated");
    let out = t.0.join("cal.dyr");
    let e = write_dyr_file(&u, &out, std::slice::from_ref(&ev), &Default::default()).unwrap_err();
    let DyrWriteError::Unfaithful { report, .. } = &e else {
        panic!("{e}");
    };
    let c = &report.events[0];
    let jw = c.j_written.unwrap();
    // The fit's J and the J the .dyr gives, both quoted; P and Q far apart.
    // (0.8713 on the bundled record smoothed at the default 4 Hz; 0.8732 as recorded.)
    assert!((c.j_unit - 0.8713).abs() < 5e-4, "{c}");
    assert!(jw > c.j_unit * 1.2, "{c}");
    assert!(c.max_dp.max(c.max_dq) > 1e-2, "{c}");
    let msg = e.to_string();
    for want in [
        format!("J = {:.4} for the unit", c.j_unit),
        format!("J = {jw:.4} for the .dyr read back"),
        "machine.x_q_pp = 0.9560276355831075, written 0.2044101216714163".to_string(),
    ] {
        assert!(msg.contains(&want), "{want}\nnot in: {msg}");
    }
    // X''q is the only loss (the rest of the unit, HYGOV and RaPId's saturation included, is
    // written as it is).
    assert_eq!(
        report
            .lost
            .iter()
            .map(|l| l.what.as_str())
            .collect::<Vec<_>>(),
        ["machine.x_q_pp"]
    );
    assert!(
        !out.exists() && !side_file(&out).exists(),
        "nothing written"
    );

    // Lossy on request: the J reported for the written model is what the file on disk gives.
    let lossy = DyrWriteOptions {
        lossy: true,
        ..Default::default()
    };
    let r = write_dyr_file(&u, &out, std::slice::from_ref(&ev), &lossy).unwrap();
    assert!(!r.faithful());
    let j_disk = j_of(&read_back(&out), &ev);
    assert!((j_disk - jw).abs() < 1e-12, "{j_disk} against {jw}");

    // With X''q tied to X''d the same unit round-trips exactly.
    let xd = u.get(u.param("machine.x_d_pp").unwrap());
    let tied = u.with_params(&[("machine.x_q_pp", xd)]).unwrap();
    let r = check(&tied, std::slice::from_ref(&ev));
    assert!(r.faithful(), "{}", r.summary());
    assert_eq!(r.events[0].max_dp.max(r.events[0].max_dq), 0.0);
}

#[test]
fn what_a_dyr_cannot_hold_is_listed_and_costs_the_playback() {
    let bundled = std::fs::read_to_string(data("itaipu/unit.toml")).unwrap();
    let ev = itaipu_event();
    let unit =
        |text: &str| itaipu_dynamics::unit_file::parse_unit(text, Path::new("u.toml")).unwrap();
    let hygov = calibrated()
        .with_params(&[("machine.x_q_pp", 0.2044101216714163)])
        .unwrap();
    let cases: Vec<(Unit, &str)> = vec![
        (
            unit(&bundled.replace("e_max = 4.5", "e_max = 4.5\nv_ref_offset = 0.004")),
            "exciter.v_ref_offset",
        ),
        (
            unit(&bundled.replace(
                "model = \"constant_pm\"",
                "model = \"constant_pm\"\npm_offset = 0.003",
            )),
            "governor.pm_offset",
        ),
        (
            hygov
                .with_params(&[("governor.n_ref_offset", 0.002)])
                .unwrap(),
            "governor.n_ref_offset",
        ),
        (
            unit(&bundled.replace(
                "model = \"GENSAE\"",
                "model = \"GENSAE\"\nswing = \"pm_is_torque\"",
            )),
            "machine option swing",
        ),
        (
            unit(&format!(
                "{bundled}\n[[block]]\nname = \"load\"\nmodel = \"terminal_load\"\np_load = 0.04\nq_load = 0.03\nn_p = 2.0\nn_q = 2.0\n"
            )),
            "block 'load'",
        ),
    ];
    for (u, what) in cases {
        // Given the event: the playback differs and the write is refused.
        let r = check(&u, std::slice::from_ref(&ev));
        assert!(!r.faithful(), "{what}: {}", r.summary());
        let c = &r.events[0];
        assert!(c.max_dp.max(c.max_dq) > ROUND_TRIP_TOL_PU, "{what}: {c}");
        assert_eq!(
            r.lost.iter().map(|l| l.what.as_str()).collect::<Vec<_>>(),
            [what],
            "{}",
            r.summary()
        );
        // Without an event, the parameters alone refuse it.
        let s = check(&u, &[]);
        assert!(!s.faithful() && s.lost == r.lost, "{what}: {}", s.summary());
    }
    // constant_pm without offset is the absence of a governor record: nothing lost.
    let r = check(&unit(&bundled), &[]);
    assert!(r.faithful() && r.lost.is_empty(), "{}", r.summary());
}

#[test]
fn write_time_plausibility_is_the_read_time_one_and_flags_flat_saturation() {
    let t = Tmp::new("plausible");
    let out = t.0.join("cal.dyr");
    let xd = 0.2044101216714163;
    let u = calibrated().with_params(&[("machine.x_q_pp", xd)]).unwrap();
    let r = write_dyr_file(&u, &out, &[], &Default::default()).unwrap();
    let sat: Vec<_> = r
        .findings
        .iter()
        .filter(|f| f.kind == "saturation")
        .collect();
    assert_eq!(sat.len(), 1, "{:#?}", r.findings);
    assert_eq!(
        (sat[0].column.as_str(), sat[0].file.as_path()),
        ("machine.s12", out.as_path())
    );
    assert!(
        sat[0].message.starts_with("S(1.0) = 1 and S(1.2) = 1:")
            && sat[0].message.contains("Se = 1 at every flux level"),
        "{}",
        sat[0].message
    );
    // Values far outside the library's ranges too (X'd = 1.51 against 0.25-0.40).
    assert!(
        r.findings
            .iter()
            .any(|f| f.kind == "parameter_range" && f.column == "machine.x_d_prime"),
        "{:#?}",
        r.findings
    );
    // The same findings as reading the written file gives.
    assert_eq!(r.findings, check_unit(&read_back(&out), &out));
    // A curve (0.1, 0.3) and "no saturation" written S(1.0) = 0 (ANDES' S(1.2) = 1) are fine.
    for f in ["itaipu/unit.toml", "andes/unit_gensal.toml"] {
        let u = read_unit(&data(f)).unwrap();
        let r = check(&u, &[]);
        assert!(
            !r.findings.iter().any(|x| x.kind == "saturation"),
            "{f}: {:#?}",
            r.findings
        );
    }
}

#[test]
fn existing_files_are_kept_unless_forced_and_both_files_or_neither_are_written() {
    let u = read_unit(&data("itaipu/unit.toml")).unwrap();
    let t = Tmp::new("force");
    let out = t.0.join("u.dyr");
    write_dyr_file(&u, &out, &[], &Default::default()).unwrap();
    let e = write_dyr_file(&u, &out, &[], &Default::default()).unwrap_err();
    assert!(
        matches!(&e, DyrWriteError::Exists { path } if path == &out),
        "{e}"
    );
    // The side file alone is enough to refuse.
    std::fs::remove_file(&out).unwrap();
    let e = write_dyr_file(&u, &out, &[], &Default::default()).unwrap_err();
    assert!(
        matches!(&e, DyrWriteError::Exists { path } if path == &side_file(&out)),
        "{e}"
    );
    assert!(!out.exists());
    std::fs::write(&out, "old").unwrap();
    let force = DyrWriteOptions {
        force: true,
        ..Default::default()
    };
    write_dyr_file(&u, &out, &[], &force).unwrap();
    assert!(std::fs::read_to_string(&out).unwrap().contains("'GENSAE'"));
    // No temporary file left behind.
    let mut names: Vec<String> = std::fs::read_dir(&t.0)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    assert_eq!(names, ["u.bases.toml", "u.dyr"]);
}
