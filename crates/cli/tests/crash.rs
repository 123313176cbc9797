//! `fit` killed outright (SIGKILL, which no handler sees) at seeded random moments, and once
//! more during a resume: every finished stage survives and is resumed with the numbers of an
//! uninterrupted run, no output folder looks complete when it is not, and no later command
//! (`simulate` into the same folder) deletes a finished stage (issue 62).
#![cfg(unix)]

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use itaipu_calib::output::{finished_stages, stale, verify, MANIFEST, PARTIAL};

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn tmp(tag: &str) -> PathBuf {
    let p = std::env::temp_dir().join(format!("itaipu-crash-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&p);
    std::fs::create_dir_all(&p).unwrap();
    p
}

fn bin() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_itaipu-calib"));
    c.current_dir(repo());
    c
}

/// Three stages and the joint pass on the bundled Itaipu record, with a small search: the
/// path through the stages, not the optimum, is under test.
const FIT: [&str; 12] = [
    "fit",
    "--stage",
    "gen,avr,pss",
    "--particles",
    "6",
    "--pso-iterations",
    "6",
    "--local-iterations",
    "3",
    "--seed",
    "3",
    "--no-plot",
];

/// Kills: the bar's 20, and the one during a resume.
const KILLS: usize = 20;

/// A seeded uniform number in [0, 1) (splitmix64).
fn uniform(state: &mut u64) -> f64 {
    *state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
    let mut z = *state;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^= z >> 31;
    (z >> 11) as f64 / (1u64 << 53) as f64
}

fn fit(out: &Path, extra: &[&str]) -> (i32, String, String) {
    let o = bin()
        .args(FIT)
        .args(["--out", out.to_str().unwrap()])
        .args(extra)
        .output()
        .unwrap();
    (
        o.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&o.stdout).into_owned(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

/// Starts `fit` (with `extra`) and kills it with SIGKILL after `after`.
fn killed(out: &Path, extra: &[&str], after: Duration) {
    let mut child = bin()
        .args(FIT)
        .args(["--out", out.to_str().unwrap()])
        .args(extra)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    std::thread::sleep(after);
    // `Child::kill` is SIGKILL on unix; a run that finished already is reaped as it is.
    let _ = child.kill();
    let _ = child.wait();
}

/// The J of every stage of a finished fit's report.
fn stage_j(dir: &Path) -> Vec<(String, f64)> {
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("report.json")).unwrap()).unwrap();
    r["stages"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| {
            (
                s["stage"].as_str().unwrap().to_string(),
                s["fitness"][0]["j_pq"].as_f64().unwrap(),
            )
        })
        .collect()
}

/// Every folder in `parent` that is not hidden looks as complete as it is: a manifest that
/// verifies, or no manifest and a `partial.json` (resumable), or nothing of ours.
fn nothing_looks_complete_that_is_not(parent: &Path) {
    for e in std::fs::read_dir(parent).unwrap() {
        let p = e.unwrap().path();
        let name = p.file_name().unwrap().to_string_lossy().into_owned();
        if name.starts_with('.') || !p.is_dir() {
            continue;
        }
        if p.join(MANIFEST).exists() {
            assert!(verify(&p).is_ok(), "{}: {:?}", p.display(), verify(&p));
            assert!(
                !p.join(PARTIAL).exists(),
                "{} has both markers",
                p.display()
            );
        }
    }
}

/// The finished work beside and in `out`: (folder, its finished stages), each stage folder
/// complete (its `unit.toml`, written last, is there).
fn finished_work(out: &Path) -> Vec<(PathBuf, Vec<String>)> {
    let mut v: Vec<(PathBuf, Vec<String>)> = stale(out)
        .into_iter()
        .filter(|s| !s.finished.is_empty())
        .map(|s| (s.path, s.finished))
        .collect();
    if out.join(PARTIAL).exists() {
        v.push((out.to_path_buf(), finished_stages(out)));
    }
    for (dir, stages) in &v {
        for st in stages {
            assert!(
                dir.join(st).join("unit.toml").is_file(),
                "{}: finished stage {st} without its unit.toml",
                dir.display()
            );
        }
    }
    v
}

/// Every file under `dir` with its size, sorted.
fn files(dir: &Path) -> Vec<(String, u64)> {
    itaipu_calib::output::list_files(dir)
        .unwrap()
        .into_iter()
        .map(|f| (f.path, f.bytes))
        .collect()
}

#[test]
fn a_fit_killed_outright_at_random_moments_keeps_and_resumes_every_finished_stage() {
    let root = tmp("kill");
    // The uninterrupted run: its numbers and its duration.
    let reference = root.join("reference");
    let t0 = Instant::now();
    let (code, _, err) = fit(&reference, &[]);
    let wall = t0.elapsed();
    assert_eq!(code, 0, "{err}");
    let j_ref = stage_j(&reference);
    assert_eq!(j_ref.len(), 4, "{j_ref:?}");

    let mut rng = 62u64;
    let (mut with_work, mut stages_resumed, mut complete_before, mut resume_kills) = (0, 0, 0, 0);
    for k in 0..KILLS {
        let dir = root.join(format!("trial-{k}"));
        std::fs::create_dir_all(&dir).unwrap();
        let out = dir.join("fit");
        // Anywhere from the start to a little past the uninterrupted run's end.
        killed(&out, &[], wall.mul_f64(0.02 + 1.05 * uniform(&mut rng)));
        nothing_looks_complete_that_is_not(&dir);
        let mut work = finished_work(&out);
        let most = work.iter().map(|(_, s)| s.len()).max().unwrap_or(0);

        // A later command into the same folder deletes no finished stage.
        let before: Vec<Vec<(String, u64)>> = work.iter().map(|(d, _)| files(d)).collect();
        let sim = bin()
            .args(["simulate", "--no-plot", "--out", out.to_str().unwrap()])
            .output()
            .unwrap();
        for ((d, _), was) in work.iter().zip(&before) {
            assert!(d.is_dir(), "simulate removed {}", d.display());
            assert_eq!(&files(d), was, "simulate changed {}", d.display());
        }
        if sim.status.success() {
            assert!(
                String::from_utf8_lossy(&sim.stderr).contains("note: kept") || work.is_empty(),
                "simulate did not name the kept work: {}",
                String::from_utf8_lossy(&sim.stderr)
            );
            // The user moves the simulation aside to resume into the folder.
            std::fs::rename(&out, dir.join("simulate")).unwrap();
            work = finished_work(&out);
        }
        nothing_looks_complete_that_is_not(&dir);

        if out.join(MANIFEST).exists() {
            // Killed after it finished: complete, nothing to resume.
            complete_before += 1;
            let (code, _, err) = fit(&out, &["--resume"]);
            assert_eq!(code, 2, "{err}");
            assert_eq!(stage_j(&out), j_ref);
            continue;
        }
        if most == 0 {
            // Nothing finished: nothing to resume, and a fresh fit is not refused.
            let (code, _, err) = fit(&out, &["--resume"]);
            assert_eq!(code, 2, "{err}");
            assert!(err.contains("nothing to resume"), "{err}");
            let (code, _, err) = fit(&out, &[]);
            assert_eq!(code, 0, "{err}");
            assert_eq!(stage_j(&out), j_ref);
            continue;
        }
        with_work += 1;
        // Beside finished work, a fresh fit is refused (it would strand or overwrite it).
        let (code, _, err) = fit(&out, &[]);
        assert_eq!(code, 7, "{err}");
        assert!(
            err.contains("--resume") && err.contains("--discard-interrupted"),
            "{err}"
        );
        assert_eq!(finished_work(&out).len(), work.len());
        // Once, killed again during its resume: the work survives that too.
        if resume_kills == 0 {
            resume_kills += 1;
            killed(
                &out,
                &["--resume"],
                wall.mul_f64(0.1 + 0.8 * uniform(&mut rng)),
            );
            nothing_looks_complete_that_is_not(&dir);
            if !out.join(MANIFEST).exists() {
                let again = finished_work(&out);
                let most_again = again.iter().map(|(_, s)| s.len()).max().unwrap_or(0);
                assert!(most_again >= most, "{again:?} after {work:?}");
            }
        }
        if out.join(MANIFEST).exists() {
            assert_eq!(stage_j(&out), j_ref);
            continue;
        }
        let most = finished_work(&out)
            .iter()
            .map(|(_, s)| s.len())
            .max()
            .unwrap_or(0);
        let (code, stdout, err) = fit(&out, &["--resume"]);
        assert_eq!(code, 0, "{err}");
        assert!(
            stdout.contains(&format!("resume {most} finished stage(s)")),
            "{stdout}"
        );
        stages_resumed += most;
        assert!(verify(&out).is_ok());
        assert_eq!(stage_j(&out), j_ref, "resumed from {most} stage(s)");
        // The work it went on from is in the folder now; nothing of it is left beside.
        assert!(finished_work(&out).is_empty(), "{:?}", finished_work(&out));
        nothing_looks_complete_that_is_not(&dir);
    }
    println!(
        "crash test: {KILLS} SIGKILLs of fit (uninterrupted {:.1} s) and {resume_kills} during a resume: {with_work} left finished stages ({stages_resumed} in all), every one resumed with the uninterrupted run's J; {complete_before} had finished",
        wall.as_secs_f64()
    );
    assert_eq!(resume_kills, 1, "no kill left a finished stage to resume");
    let _ = std::fs::remove_dir_all(&root);
}

#[test]
fn stranded_work_is_named_and_only_discarded_on_request() {
    let root = tmp("discard");
    let out = root.join("fit");
    // Kill as soon as the first stage is in (its folder and partial.json are written).
    let mut child = bin()
        .args(FIT)
        .args(["--out", out.to_str().unwrap()])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    {
        use std::io::{BufRead, BufReader};
        for line in BufReader::new(child.stderr.take().unwrap()).lines() {
            if line.unwrap().starts_with("[avr]") {
                break;
            }
        }
    }
    let _ = child.kill();
    let _ = child.wait();
    let work = finished_work(&out);
    assert_eq!(work.len(), 1, "{work:?}");
    assert_eq!(work[0].1, ["gen"]);
    let hidden = work[0].0.clone();
    // --resume names the folder it goes on from (not "not the folder of an interrupted fit").
    // Here: refused for other options, naming the folder and the difference.
    let (code, _, err) = fit(&out, &["--resume", "--no-polish"]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains(&hidden.display().to_string()), "{err}");
    assert!(err.contains("options differ"), "{err}");
    assert!(hidden.is_dir());
    // A fresh fit names it and refuses; --discard-interrupted deletes it and runs.
    let (code, _, err) = fit(&out, &[]);
    assert_eq!(code, 7, "{err}");
    assert!(err.contains(&hidden.display().to_string()), "{err}");
    let (code, _, err) = fit(&out, &["--discard-interrupted"]);
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("discarded"), "{err}");
    assert!(!hidden.exists());
    assert!(verify(&out).is_ok());
    let _ = std::fs::remove_dir_all(&root);
}
