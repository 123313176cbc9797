//! The reports a reviewer reads: one self-contained HTML page per `fit` and per `diagnose`
//! (inline CSS and SVG, no script, no network), in the spirit of a model-validation
//! (NERC MOD-026/027) submission, and the SVG plotter they and `simulate` draw with.
//!
//! Every number of a table that comes from the command's JSON result carries the JSON pointer
//! it was read from (`data-json="/stages/0/parameters/2/result"`) and its exact value
//! (`data-value`), so that a test can check the page against `report.json` / `diagnosis.json`
//! number by number. The page is also well-formed XML (every element closed, attributes
//! quoted, no named entities but the XML ones), which a test parses.
//!
//! - [`svg`]: line plots (plotters' SVG backend) as text and files;
//! - [`fit`]: the `fit` report;
//! - [`diagnose`]: the `diagnose` report and its plots.

use std::fmt::Write as _;
use std::path::Path;

pub mod diagnose;
pub mod diagnose_plots;
pub mod fit;
pub mod svg;

/// Numbers for people: 4 decimals, scientific when very small or large.
pub fn num(v: f64) -> String {
    if !v.is_finite() {
        return format!("{v}");
    }
    if v != 0.0 && (v.abs() < 1e-2 || v.abs() >= 1e4) {
        format!("{v:.3e}")
    } else {
        format!("{v:.4}")
    }
}

/// A χ² value: one decimal, scientific when large.
pub fn chi2(v: f64) -> String {
    if v.is_finite() && v.abs() < 1e7 {
        format!("{v:.1}")
    } else {
        format!("{v:.4e}")
    }
}

/// A fraction as a percentage with one decimal.
pub fn pct(v: f64) -> String {
    if v.is_finite() {
        format!("{:.1} %", 100.0 * v)
    } else {
        "-".into()
    }
}

/// Escapes text for HTML (and XML) element content and attribute values.
pub fn escape(s: &str) -> String {
    let mut o = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => o.push_str("&amp;"),
            '<' => o.push_str("&lt;"),
            '>' => o.push_str("&gt;"),
            '"' => o.push_str("&quot;"),
            '\'' => o.push_str("&#39;"),
            _ => o.push(c),
        }
    }
    o
}

/// An SVG document's text ready to be inlined: without an XML declaration or DOCTYPE, with a
/// viewBox so that it scales with the page.
pub fn inline_svg(text: &str) -> String {
    let start = text.find("<svg").unwrap_or(0);
    let mut svg = text[start..].trim_end().to_string();
    let tag_end = svg.find('>').unwrap_or(0);
    if !svg[..tag_end].contains("viewBox") {
        let attr = |name: &str| -> Option<String> {
            let tag = &svg[..tag_end];
            let k = tag.find(&format!(" {name}=\""))? + name.len() + 3;
            let v = &tag[k..];
            Some(v[..v.find('"')?].to_string())
        };
        if let (Some(w), Some(h)) = (attr("width"), attr("height")) {
            svg.insert_str(
                4,
                &format!(" viewBox=\"0 0 {} {}\"", escape(&w), escape(&h)),
            );
        }
    }
    svg
}

/// The residual-against-noise multiples both reports colour by (the library's one definition,
/// which the headline sentence quotes).
pub use itaipu_calib::noise::{AT_NOISE, FAR_ABOVE_NOISE};

/// The library's headline sentence ([`itaipu_calib::noise::Headline`]) as a paragraph, its
/// number carrying the JSON pointer `pointer` it is read from.
pub fn headline_html(h: &itaipu_calib::noise::Headline, pointer: &str) -> String {
    match (h.parts(), h.worst) {
        (Some((before, w, after)), Some(v)) => format!(
            "<p>{}<span data-derived=\"worst-ratio\" data-json=\"{}\" data-value=\"{}\">{w}</span>{}</p>\n",
            escape(before),
            escape(pointer),
            serde_json::to_string(&v).unwrap_or_default(),
            escape(after)
        ),
        _ => format!("<p>{}</p>\n", escape(&h.sentence)),
    }
}

/// The colour of a verdict, decided in one place for both reports.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Tone {
    /// The residual is at the noise floor and nothing is named: the model reproduces the
    /// record as well as the record allows.
    Good,
    /// Something is named (a cause, a parameter at a bound or not identifiable) or the residual
    /// is above the noise floor but not far above it.
    Caution,
    /// The residual is far above the noise, or what is wrong is unexplained.
    Bad,
}

impl Tone {
    /// `worst` is the largest RMS/noise ratio of any residual shown; `named` whether anything
    /// is named (a cause, a flagged parameter); `unexplained` whether the diagnosis found a
    /// misfit no cause explains.
    pub fn judge(worst: f64, named: bool, unexplained: bool) -> Tone {
        if unexplained || !worst.is_finite() || worst > FAR_ABOVE_NOISE {
            Tone::Bad
        } else if named || worst > AT_NOISE {
            Tone::Caution
        } else {
            Tone::Good
        }
    }

    /// CSS class of the verdict box.
    pub fn class(self) -> &'static str {
        match self {
            Tone::Good => "good",
            Tone::Caution => "caution",
            Tone::Bad => "bad",
        }
    }
}

/// One input file of a run, with its SHA-256.
#[derive(Debug, Clone)]
pub struct InputFile {
    /// What the file is (`event`, `measurements`, `unit`, `calibration spec`, …).
    pub role: String,
    pub path: String,
    /// Lower-case hex, or why it could not be read.
    pub sha256: String,
}

impl InputFile {
    /// Hashes `path`; a file that cannot be read is listed with the reason instead.
    pub fn new(role: &str, path: &Path) -> Self {
        Self {
            role: role.into(),
            path: path.display().to_string(),
            sha256: crate::output::sha256_file(path)
                .unwrap_or_else(|e| format!("(not readable: {e})")),
        }
    }

    /// The event file and the measurement file it names.
    pub fn event(e: &itaipu_dynamics::event::Event, held_out: bool) -> Vec<Self> {
        let tag = if held_out { " (held out)" } else { "" };
        let mut v = vec![];
        if let Some(t) = &e.toml_path {
            v.push(Self::new(&format!("event {}{tag}", e.name), t));
        }
        if !e.csv_path.as_os_str().is_empty() {
            v.push(Self::new(
                &format!("measurements {}{tag}", e.name),
                &e.csv_path,
            ));
        }
        v
    }
}

/// Where a report's numbers come from.
#[derive(Debug, Clone)]
pub struct Provenance {
    pub inputs: Vec<InputFile>,
    pub seed: u64,
    /// The command line as given.
    pub command: Vec<String>,
    /// UTC time the report was written (ISO 8601).
    pub date: String,
}

impl Provenance {
    pub fn new(inputs: Vec<InputFile>, seed: u64) -> Self {
        let now = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .unwrap_or_default();
        let date = itaipu_dynamics::pmu_import::format_iso(now.as_secs() as i64, 0.0);
        // Seconds are enough for a report.
        let date = match date.split_once('.') {
            Some((d, _)) => format!("{d}Z"),
            None => date,
        };
        Self {
            inputs,
            seed,
            command: crate::output::command(),
            date,
        }
    }
}

/// A table cell.
pub enum Cell {
    /// Text, escaped when written.
    Text(String),
    /// Markup written as is (already escaped).
    Html(String),
    /// A number read from the JSON result at `pointer`, shown as `shown` (`scale` × value: 100
    /// for a percentage).
    Json {
        shown: String,
        value: f64,
        pointer: String,
        scale: f64,
    },
    /// A number not in the JSON result (derived for the page), right-aligned.
    Num(String),
}

impl Cell {
    pub fn text(s: impl Into<String>) -> Self {
        Cell::Text(s.into())
    }
    /// A number of the JSON result, formatted by `fmt`.
    pub fn json(value: f64, pointer: impl Into<String>, fmt: fn(f64) -> String) -> Self {
        Cell::Json {
            shown: fmt(value),
            value,
            pointer: pointer.into(),
            scale: 1.0,
        }
    }
    /// A fraction of the JSON result shown as a percentage.
    pub fn json_pct(value: f64, pointer: impl Into<String>) -> Self {
        Cell::Json {
            shown: if value.is_finite() {
                format!("{:.1}", 100.0 * value)
            } else {
                "-".into()
            },
            value,
            pointer: pointer.into(),
            scale: 100.0,
        }
    }

    fn write(&self, h: &mut String) {
        match self {
            Cell::Text(s) => {
                let _ = write!(h, "<td>{}</td>", escape(s));
            }
            Cell::Html(s) => {
                let _ = write!(h, "<td>{s}</td>");
            }
            Cell::Num(s) => {
                let _ = write!(h, "<td class=\"n\">{}</td>", escape(s));
            }
            Cell::Json {
                shown,
                value,
                pointer,
                scale,
            } => {
                let scale_attr = if *scale == 1.0 {
                    String::new()
                } else {
                    format!(" data-scale=\"{scale}\"")
                };
                let _ = write!(
                    h,
                    "<td class=\"n\"><span data-json=\"{}\" data-value=\"{}\"{scale_attr}>{}</span></td>",
                    escape(pointer),
                    json_number(*value),
                    escape(shown)
                );
            }
        }
    }
}

/// A value as serde_json writes it (shortest round trip; `null` for a non-finite value).
fn json_number(v: f64) -> String {
    if v.is_finite() {
        serde_json::to_string(&v).unwrap_or_else(|_| "null".into())
    } else {
        "null".into()
    }
}

/// JSON pointer escaping of one reference token (RFC 6901).
pub fn token(s: &str) -> String {
    s.replace('~', "~0").replace('/', "~1")
}

/// An HTML page being built.
pub struct Page {
    h: String,
}

const CSS: &str = "body{font-family:system-ui,-apple-system,'Segoe UI',Helvetica,Arial,sans-serif;max-width:1100px;margin:2em auto;\
padding:0 1em;color:#222;line-height:1.45}h1{font-size:1.6em;margin-bottom:.2em}h2{border-bottom:1px solid #ccc;padding-bottom:.2em;\
margin-top:1.8em}h3{margin-bottom:.3em}table{border-collapse:collapse;margin:.5em 0 1em;font-size:.92em}\
th,td{border:1px solid #d0d0d0;padding:.25em .55em;text-align:left;vertical-align:top}th{background:#f2f2f2}\
td.n{text-align:right;font-variant-numeric:tabular-nums;white-space:nowrap}.verdict{border:2px solid #888;border-radius:6px;\
padding:.8em 1.1em;margin:1em 0;background:#f7f7f7}.verdict.good{border-color:#2c7a2c;background:#eef8ee}\
.verdict.caution{border-color:#c77700;background:#fff5e6}.verdict.bad{border-color:#b3261e;background:#fdeceb}\
.verdict h2{border:none;margin:.1em 0 .4em}.muted{color:#666}.flag{font-weight:bold;color:#b35900}\
.sig{font-weight:bold;color:#2c7a2c}ul.tight{margin:.2em 0;padding-left:1.2em}figure{margin:1em 0}\
figure svg{max-width:100%;height:auto;border:1px solid #e3e3e3}figcaption{color:#555;font-size:.9em}code{font-size:.95em}\
dl.prov{display:grid;grid-template-columns:max-content auto;gap:.15em 1em}dl.prov dt{font-weight:bold}dl.prov dd{margin:0}\
td.hash{font-family:monospace;font-size:.85em;word-break:break-all}";

impl Page {
    /// Starts a page with its title (also the first heading).
    pub fn new(title: &str) -> Self {
        let mut h = String::new();
        let _ = write!(
            h,
            "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\"/>\n<title>{t}</title>\n<style>{CSS}</style>\n</head>\n<body>\n<h1>{t}</h1>\n",
            t = escape(title)
        );
        Self { h }
    }

    /// Markup written as is (already escaped, well-formed).
    pub fn raw(&mut self, html: &str) {
        self.h.push_str(html);
    }

    pub fn h2(&mut self, id: &str, text: &str) {
        let _ = writeln!(self.h, "<h2 id=\"{}\">{}</h2>", escape(id), escape(text));
    }

    pub fn h3(&mut self, text: &str) {
        let _ = writeln!(self.h, "<h3>{}</h3>", escape(text));
    }

    /// A paragraph of text (escaped).
    pub fn p(&mut self, text: &str) {
        let _ = writeln!(self.h, "<p>{}</p>", escape(text));
    }

    /// A muted paragraph of text (escaped).
    pub fn note(&mut self, text: &str) {
        let _ = writeln!(self.h, "<p class=\"muted\">{}</p>", escape(text));
    }

    /// A table with a header row; `id` names it for readers and tests.
    pub fn table(&mut self, id: &str, head: &[&str], rows: &[Vec<Cell>]) {
        let _ = write!(self.h, "<table id=\"{}\">\n<tr>", escape(id));
        for c in head {
            let _ = write!(self.h, "<th>{}</th>", escape(c));
        }
        self.h.push_str("</tr>\n");
        for r in rows {
            self.h.push_str("<tr>");
            for c in r {
                c.write(&mut self.h);
            }
            self.h.push_str("</tr>\n");
        }
        self.h.push_str("</table>\n");
    }

    /// The provenance section: tool, date, command, seed and every input file with its hash.
    pub fn provenance(&mut self, p: &Provenance) {
        self.h2("provenance", "Provenance");
        let _ = writeln!(
            self.h,
            "<dl class=\"prov\"><dt>tool</dt><dd>itaipu-calib {}</dd><dt>written</dt><dd>{}</dd><dt>command</dt><dd><code>{}</code></dd><dt>seed</dt><dd id=\"seed\">{}</dd></dl>",
            env!("CARGO_PKG_VERSION"),
            escape(&p.date),
            escape(&p.command.join(" ")),
            p.seed
        );
        let rows: Vec<Vec<Cell>> = p
            .inputs
            .iter()
            .map(|f| {
                vec![
                    Cell::text(&f.role),
                    Cell::Html(format!("<code>{}</code>", escape(&f.path))),
                    Cell::Html(format!("<span class=\"hash\">{}</span>", escape(&f.sha256))),
                ]
            })
            .collect();
        self.table("inputs", &["input", "file", "SHA-256"], &rows);
        self.note("Every output file, with its size and SHA-256, is listed in manifest.json beside this report.");
    }

    /// The verdict box, coloured by `tone`; `body` is markup.
    pub fn verdict(&mut self, tone: Tone, heading: &str, body: &str) {
        let _ = writeln!(
            self.h,
            "<div id=\"verdict\" class=\"verdict {}\" data-tone=\"{}\">\n<h2>{}</h2>\n{body}</div>",
            tone.class(),
            tone.class(),
            escape(heading)
        );
    }

    /// An inlined SVG figure with a caption.
    pub fn figure(&mut self, svg: &str, caption: &str) {
        let _ = writeln!(
            self.h,
            "<figure>\n{}\n<figcaption>{}</figcaption>\n</figure>",
            inline_svg(svg),
            escape(caption)
        );
    }

    pub fn finish(mut self) -> String {
        self.h.push_str("</body>\n</html>\n");
        self.h
    }
}

/// `name` made safe as part of a file name.
pub fn file_stem(name: &str) -> String {
    let s: String = name
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || "-_.".contains(c) {
                c
            } else {
                '_'
            }
        })
        .collect();
    if s.is_empty() {
        "event".into()
    } else {
        s
    }
}

/// `simulated − measured` of two trace columns (NaN where a column is missing).
pub fn residual(tr: &itaipu_dynamics::simulate::Traces, sim: &str, meas: &str) -> Vec<f64> {
    match (tr.get(sim), tr.get(meas)) {
        (Some(s), Some(m)) => s.iter().zip(m).map(|(a, b)| a - b).collect(),
        _ => vec![f64::NAN; tr.time_s.len()],
    }
}

/// The measured channels of a trace besides P and Q, with the simulated signal each compares
/// with (`freq_meas_hz` against the rotor speed in Hz): `(measured, simulated, label)`.
pub fn other_channels(
    tr: &itaipu_dynamics::simulate::Traces,
    nominal_hz: f64,
) -> Vec<(String, Vec<f64>, Vec<f64>)> {
    let mut v = vec![];
    match (tr.get("v_meas_pu"), tr.get("v_term")) {
        // A closed-loop playback simulates |V| (traces of a playback mode carry v_meas_pu).
        (Some(m), Some(s)) if m.iter().zip(s).any(|(a, b)| a != b) => {
            v.push(("|V| [pu]".to_string(), m.to_vec(), s.to_vec()))
        }
        // The terminal voltage is played back: the measurement is the simulation's input.
        (_, Some(vm)) => v.push(("|V| played back [pu]".to_string(), vm.to_vec(), vec![])),
        _ => {}
    }
    for (meas, sim, label, scale) in [
        ("efd_meas_pu", "efd", "E_fd [pu]", 1.0),
        ("ifd_meas_pu", "xadifd", "I_fd [pu]", 1.0),
        ("freq_meas_hz", "speed", "frequency [Hz]", nominal_hz),
    ] {
        if let Some(m) = tr.get(meas) {
            let s = tr
                .get(sim)
                .map(|s| s.iter().map(|x| x * scale).collect())
                .unwrap_or_default();
            v.push((label.to_string(), m.to_vec(), s));
        }
    }
    v
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn escape_covers_markup_and_quotes() {
        assert_eq!(
            escape("a<b & \"c\" 'd'>"),
            "a&lt;b &amp; &quot;c&quot; &#39;d&#39;&gt;"
        );
        assert_eq!(escape("Δχ² ζ"), "Δχ² ζ");
    }

    #[test]
    fn inline_svg_drops_the_declaration_and_adds_a_viewbox() {
        let s = inline_svg("<?xml version=\"1.0\"?>\n<svg width=\"1000\" height=\"580\" xmlns=\"http://www.w3.org/2000/svg\"><g/></svg>");
        assert!(
            s.starts_with("<svg viewBox=\"0 0 1000 580\" width=\"1000\""),
            "{s}"
        );
        let kept = inline_svg("<svg viewBox=\"0 0 1 1\" width=\"5\" height=\"5\"></svg>");
        assert_eq!(kept.matches("viewBox").count(), 1);
    }

    #[test]
    fn green_only_at_the_noise_floor_with_nothing_named() {
        assert_eq!(Tone::judge(1.0, false, false), Tone::Good);
        assert_eq!(Tone::judge(AT_NOISE, false, false), Tone::Good);
        // Named: never green, even at the noise floor.
        assert_eq!(Tone::judge(1.0, true, false), Tone::Caution);
        // Above the floor: not green; far above: red whatever is named.
        assert_eq!(Tone::judge(2.0, false, false), Tone::Caution);
        assert_eq!(Tone::judge(188.0, false, false), Tone::Bad);
        assert_eq!(Tone::judge(188.0, true, false), Tone::Bad);
        assert_eq!(Tone::judge(f64::NAN, false, false), Tone::Bad);
        assert_eq!(Tone::judge(1.0, false, true), Tone::Bad);
    }

    #[test]
    fn json_cells_carry_the_pointer_and_the_exact_value() {
        let mut h = String::new();
        Cell::json(0.1 + 0.2, "/a/0/b", num).write(&mut h);
        assert_eq!(
            h,
            "<td class=\"n\"><span data-json=\"/a/0/b\" data-value=\"0.30000000000000004\">0.3000</span></td>"
        );
        let mut h = String::new();
        Cell::json_pct(0.1234, "/x").write(&mut h);
        assert!(
            h.contains("data-scale=\"100\"") && h.contains(">12.3<"),
            "{h}"
        );
        assert_eq!(token("a/b~c"), "a~1b~0c");
    }

    #[test]
    fn file_stems_are_safe() {
        assert_eq!(file_stem("itaipu-60hz-fault"), "itaipu-60hz-fault");
        assert_eq!(file_stem("a/b c"), "a_b_c");
        assert_eq!(file_stem(""), "event");
    }
}
