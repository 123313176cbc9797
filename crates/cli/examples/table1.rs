//! Paper 000's Table 1 for the bundled Itaipu record, staged as the paper staged it.
//!
//! ```sh
//! cargo run --release -p itaipu-calib-cli --example table1 -- [OUT_DIR] [--spec FILE] [--set-ud PATH=VALUE]...
//! # OUT_DIR: default out/table1; FILE: default data/itaipu/calibration_table1.toml;
//! # --set-ud: a value set in the user-defined unit as given (e.g. exciter.e_min=1.0)
//! ```
//!
//! The paper's row "GENSAE generator" is one stage shared by both columns: the generator is
//! calibrated "without any of the control system included in the model" (paper 000, Section 3.1),
//! "the field voltage kept constant" at its initial value EFD0 (paper 001, Section III) and, with
//! no governor, the mechanical power constant. Here that stage runs once
//! (`data/itaipu/calibration_table1.toml`, `stage_blocks = "remove"`: exciter, PSS and governor
//! out, E_fd = E_fd0 and P_m = P_m0) on the machine the two unit files share, and both columns
//! start from its result: the generic controls (`unit.toml`: SEXS, STAB3, then HYGOV with
//! `calibration.toml`'s control stages) and the user-defined diagrams (`unit_ud.toml`:
//! `avr_ud.toml`, `pss_ud.toml`, then `governor_ud.toml` with `calibration_ud.toml`'s control
//! stages). Each control stage adds its block as the paper does (the AVR row is machine + AVR,
//! the AVR/PSS row adds the PSS, the AVR/PSS/TG row the governor), on the stage objective of
//! the column's spec (paper 001: Q only for the AVR and the PSS, P and Q for the governor); the
//! joint pass (not in the paper) then frees everything on the full unit.
//!
//! Reported per row and column: J = Σ(ΔP² + ΔQ²) over the record's 280 samples (paper 000's
//! Eq. 3, RaPId's `cost_type` 1) and the paper's ||x|| = √J, the Frobenius norm of the 280 × 2
//! mismatch matrix ("the Euclidean norm according to Equation 3"; RaPId's `cost_type` 3) on the
//! same samples, next to the paper's ||x|| for its two events; then, per stage, its own
//! objective before and after and J where it starts and ends.
//!
//! Writes `OUT_DIR/table1.json` (every number printed), `OUT_DIR/generator.toml` (the shared
//! generator), and per column `OUT_DIR/<column>/calibrated.toml` and each stage's unit
//! (`avr.toml`, `pss.toml`, `tg.toml`, `joint.toml`: the blocks of that stage, for `simulate`).

use std::path::{Path, PathBuf};

use itaipu_calib::fit::{self, fit_with, FitControl, FitOptions, FitReport, Resume, Silent};
use itaipu_calib::job::{load_event, load_unit};
use itaipu_calib::spec::CalibSpec;
use itaipu_dynamics::event::Event;
use itaipu_dynamics::unit::Unit;
use itaipu_dynamics::unit_file::unit_to_toml;

/// The control blocks: out of the paper's generator stage.
pub const CONTROLS: [&str; 3] = ["exciter", "pss", "governor"];

/// The stages of a column, in order; the first (the generator) is the shared one.
pub const STAGES: [&str; 4] = ["gen", "avr", "pss", "tg"];

/// The paper's Table 1 (||x||, its two events): generator row shared; then per control row the
/// generic and the user-defined value.
pub const PAPER: [(&str, [f64; 2], [f64; 2]); 4] = [
    ("gen", [1.9548, 1.9548], [1.0884, 1.0884]),
    ("avr", [1.5767, 2.2875], [2.2833, 2.2827]),
    ("pss", [1.1017, 1.2], [1.1017, 1.1055]),
    ("tg", [1.3192, 2.0944], [1.3288, 5.6683]),
];

/// Search budget; `None` keeps the spec's.
#[derive(Debug, Clone, Copy, Default)]
pub struct Budget {
    pub particles: Option<usize>,
    pub pso_iterations: Option<usize>,
    pub local_iterations: Option<u64>,
}

/// One stage as the table shows it.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Row {
    pub stage: String,
    /// `pq`, `q` or `p`: what the stage minimised.
    pub objective: String,
    /// The stage's own objective (weighted sum of squares plus the prior's term) at its start
    /// and at its result.
    pub objective_before: f64,
    pub objective_after: f64,
    pub prior_before: f64,
    pub prior_after: f64,
    /// J = Σ(ΔP² + ΔQ²) of the stage's unit at its start (the previous row's result with the
    /// stage's block put in at its datasheet values) and at its result.
    pub j_start: f64,
    pub j: f64,
    pub rms_p: f64,
    pub rms_q: f64,
    pub samples: usize,
    /// The stage's blocks (`name=model`).
    pub models: Vec<String>,
    /// Free parameters: name, start, result, whether the result is on a bound.
    pub params: Vec<(String, f64, f64, bool)>,
}

impl Row {
    /// The paper's ||x||: the Frobenius norm of the mismatch, √J on the same samples.
    pub fn norm(&self) -> f64 {
        self.j.sqrt()
    }
}

/// One column: its unit as given, the unit its control stages start from (the shared
/// generator with the column's controls at their datasheet values), its rows and result.
pub struct Column {
    pub name: &'static str,
    pub as_given_j: f64,
    pub start: Unit,
    /// The unit the column's first control stage (the AVR) started from, as the fit built it.
    pub first_stage_start: Unit,
    pub rows: Vec<Row>,
    /// Each stage's calibrated unit (the blocks of that stage), in the order of `rows`.
    pub stage_units: Vec<Unit>,
    pub calibrated: Unit,
    pub report: FitReport,
}

pub struct Table1 {
    /// The shared generator stage.
    pub gen: Row,
    /// The calibrated generator alone (machine block, E_fd and P_m held).
    pub generator: Unit,
    pub columns: Vec<Column>,
    /// Values set in the user-defined unit as given (none for the table as shipped).
    pub ud_set: Vec<(String, f64)>,
    pub wall_s: f64,
}

fn err(e: impl std::fmt::Display) -> String {
    e.to_string()
}

/// The machine block of `unit` as unit-file text, name and description left out: what two
/// columns must hold byte for byte to share a generator.
pub fn machine_text(unit: &Unit) -> Result<String, String> {
    let mut m = unit.without(&CONTROLS).map_err(err)?;
    m.name = "machine".into();
    m.description.clear();
    Ok(unit_to_toml(&m))
}

/// `unit` with every parameter of `generator` (a machine-only unit) set.
pub fn with_generator(unit: &Unit, generator: &Unit) -> Result<Unit, String> {
    let mut u = unit.clone();
    for (path, _, v) in generator.params() {
        let r = u.param(&path).map_err(err)?;
        u.set(r, v);
    }
    Ok(u)
}

fn options(spec: &CalibSpec, stages: &[&str], b: &Budget) -> FitOptions {
    let mut o = FitOptions::from_spec(spec);
    o.stages = stages.iter().map(|s| s.to_string()).collect();
    if let Some(v) = b.particles {
        o.particles = v;
    }
    if let Some(v) = b.pso_iterations {
        o.pso_iterations = v;
    }
    if let Some(v) = b.local_iterations {
        o.lbfgs_iterations = v;
    }
    o
}

/// J, rms P and rms Q of `unit` on `event` (the accurate integrator, every sample).
fn j_of(unit: &Unit, event: &Event) -> Result<fit::EventFitness, String> {
    Ok(fit::fitness(unit, event, false).map_err(err)?.0)
}

fn rows(res: &fit::FitResult, event: &Event) -> Result<Vec<Row>, String> {
    res.report
        .stages
        .iter()
        .zip(&res.stages)
        .map(|(s, out)| {
            let f = &s.fitness[0];
            Ok(Row {
                stage: s.stage.clone(),
                objective: format!("{:?}", s.objective).to_lowercase(),
                objective_before: s.objective_before,
                objective_after: s.objective_after,
                prior_before: s.prior_before,
                prior_after: s.prior_after,
                j_start: j_of(&out.start_unit, event)?.j_pq,
                j: f.j_pq,
                rms_p: f.rms_p,
                rms_q: f.rms_q,
                samples: f.samples,
                models: s.models.clone(),
                params: s
                    .parameters
                    .iter()
                    .map(|p| (p.param.clone(), p.start, p.result, p.at_bound))
                    .collect(),
            })
        })
        .collect()
}

/// Runs the table: the shared generator stage once, then each column's control stages and
/// joint pass from it. `root` is the repository (holding `data/itaipu`); `table_spec` holds the
/// generator stage and the staging (`data/itaipu/calibration_table1.toml`); `ud_set` are
/// values set in the user-defined unit as given (`--set-ud exciter.e_min=1.0`).
pub fn run(
    root: &Path,
    table_spec: &Path,
    budget: &Budget,
    ud_set: &[(String, f64)],
) -> Result<Table1, String> {
    let t0 = std::time::Instant::now();
    let d = root.join("data/itaipu");
    let event = load_event(&d.join("event.toml")).map_err(err)?;
    let events = std::slice::from_ref(&event);
    let table = CalibSpec::from_file(table_spec).map_err(err)?;
    let gen_stage = table
        .stage("gen")
        .cloned()
        .ok_or("calibration_table1.toml has no gen stage")?;
    let cases = [
        ("generic", "unit.toml", "calibration.toml"),
        ("user-defined", "unit_ud.toml", "calibration_ud.toml"),
    ];
    let mut units: Vec<Unit> = cases
        .iter()
        .map(|(_, u, _)| load_unit(&d.join(u)).map(|l| l.unit).map_err(err))
        .collect::<Result<_, _>>()?;
    units[1] = units[1].with_params(ud_set).map_err(err)?;

    // The generator stage, once, on the machine both unit files hold (with the paper's
    // staging the stage's unit is that machine alone; with `stage_blocks = "keep"` it would
    // hold the first column's controls at their datasheet values).
    for (u, (name, file, _)) in units.iter().zip(&cases).skip(1) {
        if machine_text(u)? != machine_text(&units[0])? {
            return Err(format!(
                "{file} ({name}) has another machine than {}: the generator stage cannot be shared",
                cases[0].1
            ));
        }
    }
    let gen_res = fit_with(
        &units[0],
        &table,
        events,
        &[],
        &options(&table, &["gen"], budget),
        &Silent,
        &FitControl::default(),
    )
    .map_err(err)?;
    let gen = rows(&gen_res, &event)?.remove(0);
    let generator = gen_res.stages[0]
        .calibrated_unit
        .without(&CONTROLS)
        .map_err(err)?;

    let mut columns = vec![];
    for ((name, _, calib), unit) in cases.iter().zip(units) {
        let mut spec = CalibSpec::from_file(&d.join(calib)).map_err(err)?;
        // The table's staging and its (shared) generator stage; the control stages, their
        // bounds, objectives and replacement governor are the column's.
        spec.stage_blocks = table.stage_blocks;
        match spec.stages.iter_mut().find(|s| s.name == "gen") {
            Some(s) => *s = gen_stage.clone(),
            None => spec.stages.insert(0, gen_stage.clone()),
        }
        let start = with_generator(&unit, &generator)?;
        // The generator pass is finished (shared): the fit goes on from `start` with the
        // column's control stages and the joint pass; its prior stays centred on the unit as
        // given.
        let control = FitControl {
            resume: Some(Resume {
                finished: vec!["gen".into()],
                master: start.clone(),
            }),
            ..Default::default()
        };
        let res = fit_with(
            &unit,
            &spec,
            events,
            &[],
            &options(&table, &STAGES, budget),
            &Silent,
            &control,
        )
        .map_err(err)?;
        columns.push(Column {
            name,
            as_given_j: res.report.start_fitness[0].j_pq,
            start,
            first_stage_start: res.stages[0].start_unit.clone(),
            rows: rows(&res, &event)?,
            stage_units: res
                .stages
                .iter()
                .map(|o| o.calibrated_unit.clone())
                .collect(),
            calibrated: res.unit.clone(),
            report: res.report,
        });
    }
    Ok(Table1 {
        gen,
        generator,
        columns,
        ud_set: ud_set.to_vec(),
        wall_s: t0.elapsed().as_secs_f64(),
    })
}

fn label(s: &str) -> &str {
    match s {
        "gen" => "GENSAE generator (shared)",
        "avr" => "AVR",
        "pss" => "AVR/PSS",
        "tg" => "AVR/PSS/TG",
        "joint" => "joint pass (not in paper)",
        other => other,
    }
}

impl Table1 {
    /// The table as printed: J and ||x|| per row and column beside the paper's ||x||, then the
    /// stages' own objectives.
    pub fn to_text(&self) -> String {
        use std::fmt::Write;
        let mut s = String::new();
        let (g, u) = (&self.columns[0], &self.columns[1]);
        let _ = writeln!(
            s,
            "Table 1 (paper 000) for the bundled Itaipu record, {} samples (0-4.65 s), system base:\n\
             J = Σ(ΔP² + ΔQ²) (Eq. 3) and ||x|| = √J (its Frobenius norm, the paper's Table 1)\n",
            self.gen.samples
        );
        for (p, v) in &self.ud_set {
            let _ = writeln!(s, "user-defined unit as given with {p} = {v}\n");
        }
        let _ = writeln!(
            s,
            "{:<27} {:>17} {:>17} | {:>15} {:>15}",
            "", "generic", "user-defined", "paper 9/22/2015", "paper 11/2/2016"
        );
        let _ = writeln!(
            s,
            "{:<27} {:>8} {:>8} {:>8} {:>8} | {:>7} {:>7} {:>7} {:>7}",
            "model setup", "J", "||x||", "J", "||x||", "generic", "UD", "generic", "UD"
        );
        let pair = |j: f64| format!("{:>8.4} {:>8.4}", j, j.sqrt());
        let _ = writeln!(
            s,
            "{:<27} {} {} | {:>7} {:>7} {:>7} {:>7}",
            "as given (datasheet)",
            pair(g.as_given_j),
            pair(u.as_given_j),
            "-",
            "-",
            "-",
            "-"
        );
        let paper = |stage: &str| -> String {
            PAPER
                .iter()
                .find(|(p, _, _)| *p == stage)
                .map(|(_, a, b)| format!("{:>7.4} {:>7.4} {:>7.4} {:>7.4}", a[0], a[1], b[0], b[1]))
                .unwrap_or_else(|| format!("{:>7} {:>7} {:>7} {:>7}", "-", "-", "-", "-"))
        };
        let _ = writeln!(
            s,
            "{:<27} {} {} | {}",
            label("gen"),
            pair(self.gen.j),
            pair(self.gen.j),
            paper("gen")
        );
        for (rg, ru) in g.rows.iter().zip(&u.rows) {
            let _ = writeln!(
                s,
                "{:<27} {} {} | {}",
                label(&rg.stage),
                pair(rg.j),
                pair(ru.j),
                paper(&rg.stage)
            );
        }
        let _ = writeln!(
            s,
            "\nEach stage on its own objective (obj: the stage's weighted sum of squares + prior) and on J,\n\
             from its start (the previous row's result, the stage's block put in at its datasheet values)\n\
             to its result:\n"
        );
        let _ = writeln!(
            s,
            "{:<13} {:<6} {:>4} {:>10} {:>10} {:>9} {:>9} {:>7} {:>7}",
            "column", "stage", "obj", "obj start", "obj end", "J start", "J end", "rms P", "rms Q"
        );
        let mut line = |col: &str, r: &Row| {
            let _ = writeln!(
                s,
                "{:<13} {:<6} {:>4} {:>10.5} {:>10.5} {:>9.4} {:>9.4} {:>7.4} {:>7.4}",
                col,
                r.stage,
                r.objective,
                r.objective_before,
                r.objective_after,
                r.j_start,
                r.j,
                r.rms_p,
                r.rms_q
            );
        };
        line("shared", &self.gen);
        for c in &self.columns {
            for r in &c.rows {
                line(c.name, r);
            }
        }
        // What a reader must be told: a stage that ends above its start, on its own objective
        // (never: the library keeps the start then) or on J (a stage that does not minimise J),
        // and a row above the row before it (the stage's block put in at its datasheet values).
        let mut notes = vec![];
        for (col, r, prev) in
            std::iter::once(("shared", &self.gen, None)).chain(self.columns.iter().flat_map(|c| {
                let prev = std::iter::once(self.gen.j).chain(c.rows.iter().map(|r| r.j));
                c.rows.iter().zip(prev).map(|(r, p)| (c.name, r, Some(p)))
            }))
        {
            if r.objective_after > r.objective_before {
                notes.push(format!(
                    "{col} {}: its objective rose ({:.5} -> {:.5}): a defect",
                    r.stage, r.objective_before, r.objective_after
                ));
            }
            if r.j > r.j_start {
                notes.push(format!(
                    "{col} {}: J rose ({:.4} -> {:.4}) while the stage's own objective ({}) fell \
                     ({:.5} -> {:.5}): J is not what the stage minimises",
                    r.stage, r.j_start, r.j, r.objective, r.objective_before, r.objective_after
                ));
            }
            if let Some(p) = prev.filter(|p| r.j > *p) {
                notes.push(format!(
                    "{col} {}: the row ({:.4}) is above the row before it ({:.4}): the stage \
                     started at J {:.4}, its block put in at its datasheet values",
                    r.stage, r.j, p, r.j_start
                ));
            }
        }
        if notes.is_empty() {
            let _ = writeln!(
                s,
                "\nEvery stage ends at or below its start, on its own objective and on J, and every \
                 row at or below the row before it."
            );
        } else {
            let _ = writeln!(s);
            for n in notes {
                let _ = writeln!(s, "note: {n}");
            }
        }
        let _ = writeln!(s, "\n({:.0} s)", self.wall_s);
        s
    }

    pub fn to_json(&self) -> serde_json::Value {
        serde_json::json!({
            "samples": self.gen.samples,
            "user_defined_set": self.ud_set,
            "norm": "||x|| = sqrt(J), J = sum over the samples of dP^2 + dQ^2 (system base)",
            "generator": self.gen,
            "columns": self.columns.iter().map(|c| serde_json::json!({
                "name": c.name,
                "as_given_j": c.as_given_j,
                "rows": c.rows,
            })).collect::<Vec<_>>(),
            "paper": PAPER.iter().map(|(s, a, b)| serde_json::json!({
                "stage": s, "2015-09-22": { "generic": a[0], "user_defined": a[1] },
                "2016-11-02": { "generic": b[0], "user_defined": b[1] },
            })).collect::<Vec<_>>(),
            "wall_s": self.wall_s,
        })
    }
}

/// The repository (holding `data/itaipu`).
pub fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn write(out: &Path, t: &Table1) -> std::io::Result<()> {
    std::fs::create_dir_all(out)?;
    let json = serde_json::to_string_pretty(&t.to_json()).map_err(std::io::Error::other)?;
    std::fs::write(out.join("table1.json"), json)?;
    std::fs::write(out.join("generator.toml"), unit_to_toml(&t.generator))?;
    for c in &t.columns {
        let dir = out.join(c.name);
        std::fs::create_dir_all(&dir)?;
        std::fs::write(dir.join("calibrated.toml"), unit_to_toml(&c.calibrated))?;
        for (r, u) in c.rows.iter().zip(&c.stage_units) {
            std::fs::write(dir.join(format!("{}.toml", r.stage)), unit_to_toml(u))?;
        }
    }
    Ok(())
}

#[allow(dead_code)] // the test includes this file as a module
fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let mut spec = repo().join("data/itaipu/calibration_table1.toml");
    let mut ud_set = vec![];
    let mut out = PathBuf::from("out/table1");
    let mut it = args.iter();
    while let Some(a) = it.next() {
        let mut value = || {
            it.next().cloned().unwrap_or_else(|| {
                eprintln!("table1: {a} needs a value");
                std::process::exit(2)
            })
        };
        match a.as_str() {
            "--spec" => spec = PathBuf::from(value()),
            "--set-ud" => {
                let v = value();
                match v.split_once('=').map(|(p, x)| (p, x.parse::<f64>())) {
                    Some((p, Ok(x))) => ud_set.push((p.to_string(), x)),
                    _ => {
                        eprintln!("table1: --set-ud {v}: expected PATH=NUMBER");
                        std::process::exit(2)
                    }
                }
            }
            _ => out = PathBuf::from(a),
        }
    }
    let t = match run(&repo(), &spec, &Budget::default(), &ud_set) {
        Ok(t) => t,
        Err(e) => {
            eprintln!("table1: {e}");
            std::process::exit(1);
        }
    };
    print!("{}", t.to_text());
    if let Err(e) = write(&out, &t) {
        eprintln!("table1: {}: {e}", out.display());
        std::process::exit(7);
    }
    println!(
        "wrote {}/table1.json, generator.toml, <column>/{{calibrated,avr,pss,tg,joint}}.toml",
        out.display()
    );
}
