//! End-to-end: the HTML reports of `fit` and `diagnose` (tiny budgets). Each page is parsed as
//! XML (well-formed: every element closed, every inline SVG too); every number that carries a
//! JSON pointer equals the number at that pointer in report.json / diagnosis.json and is
//! shown rounded from it; the page references nothing outside itself; the verdict's colour
//! follows the rule (green only at the noise floor with nothing named). When a headless
//! Chromium is installed (`chromium-headless-shell` or `chromium`), the page is also loaded in
//! it and the DOM it builds is checked; without one that part says so and is skipped, unless
//! `ITAIPU_REQUIRE_BROWSER` is set (CI installs the browser and sets it).

use std::path::{Path, PathBuf};

use itaipu_calib_e2e::{cli, cli_on, data, synth_skewed_dip, TempDir};

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// Rounding allowed for a shown number: half a unit of its last shown digit.
fn shown_tolerance(text: &str) -> f64 {
    let (mantissa, exp) = match text.split_once('e') {
        Some((m, e)) => (m, e.parse::<i32>().unwrap()),
        None => (text, 0),
    };
    let decimals = mantissa.split_once('.').map(|(_, d)| d.len()).unwrap_or(0) as i32;
    0.5 * 10f64.powi(exp - decimals) * 1.000001
}

/// Parses a report, checks it and returns (number of JSON-backed numbers, the verdict tone).
fn check_report(html_path: &Path, result: &serde_json::Value) -> (usize, String) {
    let html = std::fs::read_to_string(html_path).unwrap();
    assert!(html.starts_with("<!DOCTYPE html>"));
    let doc = roxmltree::Document::parse_with_options(
        &html,
        roxmltree::ParsingOptions {
            allow_dtd: true,
            ..Default::default()
        },
    )
    .unwrap_or_else(|e| panic!("{} is not well-formed: {e}", html_path.display()));
    let mut checked = 0;
    for n in doc.descendants().filter(|n| n.has_attribute("data-json")) {
        let ptr = n.attribute("data-json").unwrap();
        let in_json = result
            .pointer(ptr)
            .unwrap_or_else(|| panic!("{ptr} is not in the JSON"));
        let v = in_json
            .as_f64()
            .unwrap_or_else(|| panic!("{ptr}: {in_json} is not a number"));
        let attr: f64 = n.attribute("data-value").unwrap().parse().unwrap();
        // serde_json's default float parser (without `float_roundtrip`) may miss the correctly
        // rounded value by an ulp: both are the same number written once.
        assert!(
            (attr - v).abs() <= 4.0 * f64::EPSILON * v.abs(),
            "{ptr}: data-value {attr} differs from the JSON's {v}"
        );
        let scale: f64 = n
            .attribute("data-scale")
            .map(|s| s.parse().unwrap())
            .unwrap_or(1.0);
        let text = n.text().unwrap_or("").trim();
        let shown: f64 = text
            .parse()
            .unwrap_or_else(|_| panic!("{ptr}: shown '{text}' is not a number"));
        assert!(
            (shown - scale * v).abs() <= shown_tolerance(text),
            "{ptr}: shown {text}, JSON {v} (× {scale})"
        );
        checked += 1;
    }
    // Nothing outside the page: no script, no linked resources, no external references.
    for n in doc.descendants().filter(|n| n.is_element()) {
        let name = n.tag_name().name();
        assert!(
            !["script", "link", "iframe", "img", "object", "embed"].contains(&name),
            "<{name}> in a self-contained report"
        );
        for a in n.attributes() {
            if ["href", "src"].contains(&a.name()) {
                assert!(
                    a.value().starts_with('#'),
                    "external reference {}",
                    a.value()
                );
            }
        }
    }
    let lower = html.to_lowercase();
    assert!(!lower.contains("@import") && !lower.contains("url("));
    // Every inline SVG is an <svg> element with drawn content and a viewBox.
    let svgs: Vec<_> = doc
        .descendants()
        .filter(|n| n.tag_name().name() == "svg")
        .collect();
    for s in &svgs {
        assert!(s.has_attribute("viewBox"));
        assert!(s.descendants().count() > 20, "an empty plot");
    }
    let verdict = doc
        .descendants()
        .find(|n| n.attribute("id") == Some("verdict"))
        .expect("a verdict box");
    let tone = verdict.attribute("data-tone").unwrap().to_string();
    assert!(verdict
        .attribute("class")
        .unwrap()
        .split(' ')
        .any(|c| c == tone));
    // Provenance: every input file with a 64-hex-digit SHA-256.
    let inputs = doc
        .descendants()
        .find(|n| n.attribute("id") == Some("inputs"))
        .expect("the input table");
    let hashes: Vec<&str> = inputs
        .descendants()
        .filter(|n| n.attribute("class") == Some("hash"))
        .filter_map(|n| n.text())
        .collect();
    assert!(hashes.len() >= 3, "unit, event and measurements hashed");
    for h in &hashes {
        assert!(
            h.len() == 64 && h.chars().all(|c| c.is_ascii_hexdigit()),
            "{h}"
        );
    }
    (checked, tone)
}

/// Headless Chromium, if installed.
fn browser() -> Option<PathBuf> {
    let path = std::env::var_os("PATH")?;
    for name in ["chromium-headless-shell", "chromium", "chromium-browser"] {
        for dir in std::env::split_paths(&path) {
            let p = dir.join(name);
            if p.is_file() {
                return Some(p);
            }
        }
    }
    None
}

/// Loads the page in a headless browser and returns the DOM it built (None without one).
fn rendered_dom(html: &Path) -> Option<String> {
    let Some(b) = browser() else {
        // CI installs the browser (.ci/run) and sets ITAIPU_REQUIRE_BROWSER: there the check
        // cannot be skipped.
        assert!(
            std::env::var_os("ITAIPU_REQUIRE_BROWSER").is_none(),
            "ITAIPU_REQUIRE_BROWSER is set but no chromium-headless-shell / chromium is on PATH"
        );
        eprintln!("no headless browser (chromium-headless-shell / chromium) on PATH: rendering check skipped");
        return None;
    };
    let profile = TempDir::new("chromium-profile");
    let out = std::process::Command::new(&b)
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--no-first-run",
            &format!("--user-data-dir={}", profile.path().display()),
            "--dump-dom",
        ])
        .arg(format!("file://{}", html.canonicalize().unwrap().display()))
        .output()
        .expect("run the browser");
    assert!(
        out.status.success(),
        "{} failed: {}",
        b.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    Some(String::from_utf8(out.stdout).unwrap())
}

fn check_rendered(html: &Path) {
    let Some(dom) = rendered_dom(html) else {
        return;
    };
    let source = std::fs::read_to_string(html).unwrap();
    // The browser built the same document: the same figures and JSON-backed numbers, the
    // verdict box, and no parser error page.
    assert_eq!(
        dom.matches("<svg").count(),
        source.matches("<svg").count(),
        "every inline SVG rendered"
    );
    assert_eq!(
        dom.matches("data-json=").count(),
        source.matches("data-json=").count()
    );
    assert!(dom.contains("id=\"verdict\""));
}

#[test]
fn fit_report_matches_report_json_and_stands_alone() {
    let tmp = TempDir::new("report-fit");
    let out = tmp.path().join("fit");
    assert_eq!(
        cli(&[
            "fit",
            "--stage",
            "gen",
            "--particles",
            "4",
            "--pso-iterations",
            "2",
            "--lbfgs-iterations",
            "2",
            "--no-polish",
            "--out",
            out.to_str().unwrap()
        ]),
        0
    );
    let report = json(&out.join("report.json"));
    let (checked, tone) = check_report(&out.join("report.html"), &report);
    // Every parameter of every stage: start, min, max, result and (when determined) std error.
    let params: usize = report["stages"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s["parameters"].as_array().unwrap().len())
        .sum();
    assert!(params >= 5);
    assert!(
        checked >= 4 * params,
        "{checked} numbers checked for {params} parameters"
    );
    let html = std::fs::read_to_string(out.join("report.html")).unwrap();
    for s in report["stages"].as_array().unwrap().iter().enumerate() {
        for (j, _) in s.1["parameters"].as_array().unwrap().iter().enumerate() {
            let ptr = format!("data-json=\"/stages/{}/parameters/{j}/result\"", s.0);
            assert!(html.contains(&ptr), "{ptr}");
        }
        assert!(html.contains(&format!("data-json=\"/stages/{}/fitness/0/j_pq\"", s.0)));
    }
    assert!(html.contains("data-json=\"/start_fitness/0/j_pq\""));
    assert!(html.contains("data-json=\"/noise/0/channels/0/floor/sigma\""));
    // Measured against simulated P, Q, the played-back |V|, and the residuals with the noise band.
    assert_eq!(html.matches("<svg").count(), 1);
    for label in [
        "P [pu, system base]",
        "Q [pu, system base]",
        "|V| played back",
        "±σP noise",
        "±σQ noise",
    ] {
        assert!(html.contains(label), "figure lacks {label}");
    }
    // The colour follows the rule: a two-iteration fit is far from the noise floor, or flags a
    // parameter; it is never green unless the residual is at the noise floor with nothing
    // flagged.
    let last = report["stages"].as_array().unwrap().last().unwrap();
    let noise = &report["noise"][0];
    let ratio = (last["fitness"][0]["rms_p"].as_f64().unwrap()
        / noise["sigma_p"].as_f64().unwrap())
    .max(last["fitness"][0]["rms_q"].as_f64().unwrap() / noise["sigma_q"].as_f64().unwrap());
    let flagged = report["stages"].as_array().unwrap().iter().any(|s| {
        s["parameters"]
            .as_array()
            .unwrap()
            .iter()
            .any(|p| p["at_bound"] == true)
            || !s["unidentified"].as_array().unwrap().is_empty()
            || !s["correlated_pairs"].as_array().unwrap().is_empty()
    });
    let expected = if ratio > 3.0 {
        "bad"
    } else if flagged || ratio > 1.5 {
        "caution"
    } else {
        "good"
    };
    assert_eq!(tone, expected, "ratio {ratio}, flagged {flagged}");
    // Listed in the manifest like every other output.
    let manifest = json(&out.join("manifest.json"));
    assert!(manifest["files"]
        .as_array()
        .unwrap()
        .iter()
        .any(|f| f["path"] == "report.html"));
    check_rendered(&out.join("report.html"));
}

#[test]
fn diagnose_report_matches_diagnosis_json_and_stands_alone() {
    let tmp = TempDir::new("report-diag");
    let synth = tmp.path().join("synth");
    assert_eq!(synth_skewed_dip(&synth, "12"), 0);
    let out = tmp.path().join("diag");
    let unit = data("synthetic/unit_gensae_sexs_stab3_hygov.toml");
    assert_eq!(
        cli_on(
            "diagnose",
            synth.join("event.toml"),
            &unit,
            &out,
            &[
                "--cause",
                "measurement_skew",
                "--particles",
                "8",
                "--pso-iterations",
                "6",
                "--lbfgs-iterations",
                "5"
            ]
        ),
        0
    );
    let d = json(&out.join("diagnosis.json"));
    let (checked, tone) = check_report(&out.join("report.html"), &d);
    assert!(checked >= 30, "{checked} numbers checked");
    let html = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert_eq!(d["verdict"]["cause"], "measurement_skew");
    // A named cause is never green.
    assert_ne!(tone, "good");
    // The named cause's parameters with standard errors, and the candidates' gains.
    assert!(html.contains("data-json=\"/candidates/0/parameters/0/result\""));
    assert!(html.contains("data-json=\"/candidates/0/gains/delta_bic\""));
    assert!(html.contains("data-json=\"/noise/sigmas/0/1\""));
    // The named cause's confidence: the odds its probability weighs, as the JSON holds them.
    assert!(d["verdict"]["confidence"].is_object());
    for part in [
        "odds_baseline",
        "odds_rivals",
        "odds_outside",
        "data_evidence",
    ] {
        assert!(
            html.contains(&format!("data-json=\"/verdict/confidence/{part}\"")),
            "{part} not shown"
        );
    }
    // No window of fewer than 5 samples and no mode with implausible damping among the
    // numbers shown.
    let doc = roxmltree::Document::parse_with_options(
        &html,
        roxmltree::ParsingOptions {
            allow_dtd: true,
            ..Default::default()
        },
    )
    .unwrap();
    for n in doc.descendants().filter_map(|n| n.attribute("data-json")) {
        if let Some(i) = n.find("/windows/") {
            let w = &n[..i + "/windows/".len() + n[i + 9..].find('/').unwrap()];
            let samples = d
                .pointer(&format!("{w}/samples"))
                .unwrap()
                .as_u64()
                .unwrap();
            assert!(samples >= 5, "{w}: {samples} samples shown as evidence");
        }
        if n.ends_with("/damping_ratio") {
            let z = d.pointer(n).unwrap().as_f64().unwrap();
            assert!(z > -0.05 && z < 0.95, "{n}: ζ = {z} shown as a mode");
        }
    }
    assert_eq!(html.matches("<svg").count(), 3);
    // Each plot file parses on its own and is the figure inlined in the page.
    for f in ["residual", "spectrum", "before-after"] {
        let text = std::fs::read_to_string(out.join(format!("{f}-synthetic-dip-1.svg"))).unwrap();
        let svg = roxmltree::Document::parse(&text).unwrap();
        assert_eq!(svg.root_element().tag_name().name(), "svg");
        let body = &text[text.find("<g").unwrap_or(0)..];
        assert!(html.contains(body.trim_end()), "{f} inlined as written");
    }
    check_rendered(&out.join("report.html"));
}
