//! The plots of the `diagnose` report: residuals with the noise band and the implicated window,
//! residual spectra, measured against simulated P, Q and every other measured channel.

use std::collections::BTreeSet;
use std::path::Path;

use itaipu_calib::diagnose::{Diagnosis, EventEvidence};
use itaipu_dynamics::simulate::Traces;

use super::diagnose::{top_window, PlotFile};
use super::svg as plot;
use super::{file_stem, num, residual};
use crate::CliError;

/// Draws the diagnosis plots of every event into `out` (residuals with the noise band,
/// residual spectra, measured against simulated P, Q and every other measured channel) and
/// returns them with their SVG text. `nominal_hz` gives each event's nominal frequency.
pub fn draw_plots(
    out: &Path,
    nominal_hz: &[(String, f64)],
    r: &Diagnosis,
    before: &[(String, Traces)],
    after: &[(String, Traces)],
) -> Result<Vec<PlotFile>, CliError> {
    let mut files = vec![];
    let mut stems = BTreeSet::new();
    let named = Some(r.verdict.cause.as_str()).filter(|_| r.verdict.names_a_cause());
    for (k, (event, tr)) in before.iter().enumerate() {
        let mut stem = file_stem(event);
        if !stems.insert(stem.clone()) {
            stem = format!("{stem}-{}", k + 1);
            stems.insert(stem.clone());
        }
        let ev = r.evidence.iter().find(|e| &e.event == event);
        let tr_after = after.iter().find(|(e, _)| e == event).map(|(_, t)| t);
        let t = &tr.time_s;
        let draw = |file: &str,
                    title: &str,
                    x_label: &str,
                    panels: &[plot::Panel],
                    decor: &[plot::Decor]| {
            let svg = plot::render(title, x_label, panels, decor)
                .map_err(|e| CliError::new(7, format!("plot {file}: {e}")))?;
            crate::output::write_synced(&out.join(file), svg.as_bytes())?;
            Ok::<String, CliError>(svg)
        };

        // Residuals of the compared signals with the implicated window and the noise band.
        let compared: Vec<(&str, &str, &str, f64)> = r
            .noise
            .sigmas
            .iter()
            .filter_map(|(s, sigma)| {
                let c = itaipu_calib::diagnose::playback::signal_channel(s)?;
                let (sim, meas) = itaipu_dynamics::simulate::trace_columns(c)?;
                Some((s.as_str(), sim, meas, *sigma))
            })
            .collect();
        let res_before: Vec<Vec<f64>> = compared
            .iter()
            .map(|(_, sim, meas, _)| residual(tr, sim, meas))
            .collect();
        let res_after: Option<Vec<Vec<f64>>> = tr_after.map(|ta| {
            compared
                .iter()
                .map(|(_, sim, meas, _)| residual(ta, sim, meas))
                .collect()
        });
        let mut panels = vec![];
        let mut decor = vec![];
        for (k, &(signal, _, _, sigma)) in compared.iter().enumerate() {
            let res = &res_before[k];
            let mut series = vec![plot::Series {
                label: "as given".into(),
                x: t,
                y: res,
                color: plot::START,
                thin: false,
            }];
            if let (Some(ta), Some(after), Some(cause)) = (tr_after, &res_after, named) {
                let y = &after[k];
                series.push(plot::Series {
                    label: format!("with {cause}"),
                    x: &ta.time_s,
                    y,
                    color: plot::SIMULATED,
                    thin: false,
                });
            }
            panels.push(plot::Panel {
                y_label: format!("{signal} residual (sim − meas) [pu]"),
                series,
            });
            decor.push(plot::Decor {
                spans: implicated_window(r, ev, signal).into_iter().collect(),
                y_bands: vec![plot::YBand {
                    label: format!("±σ{signal} noise {}", num(sigma)),
                    y0: -sigma,
                    y1: sigma,
                    color: plot::NOISE,
                }],
                markers: vec![],
            });
        }
        let file = format!("residual-{stem}.svg");
        let svg = draw(
            &file,
            &format!("{event}: residuals; verdict {}", r.verdict.cause),
            "time [s]",
            &panels,
            &decor,
        )?;
        files.push(PlotFile {
            file,
            event: event.clone(),
            caption: format!(
                "{} residuals (simulated − measured) of the unit as given, the implicated window \
                 shaded, ±σ noise band",
                compared.iter().map(|c| c.0).collect::<Vec<_>>().join(", ")
            ),
            svg,
        });

        // Residual spectra with the peak marked.
        if let Some(ev) = ev {
            let mut panels = vec![];
            let mut decor = vec![];
            for signal in r.noise.sigmas.iter().map(|(s, _)| s.as_str()) {
                let Some(s) = ev.signals.iter().find(|s| s.signal == signal) else {
                    continue;
                };
                let sp = &s.spectrum;
                let mut series = vec![plot::Series {
                    label: "as given".into(),
                    x: &sp.freq_hz,
                    y: &sp.amplitude,
                    color: plot::START,
                    thin: false,
                }];
                let sa = r
                    .evidence_after
                    .iter()
                    .find(|e| &e.event == event)
                    .and_then(|e| e.signals.iter().find(|x| x.signal == signal));
                if let (Some(sa), Some(cause)) = (sa, named) {
                    series.push(plot::Series {
                        label: format!("with {cause}"),
                        x: &sa.spectrum.freq_hz,
                        y: &sa.spectrum.amplitude,
                        color: plot::SIMULATED,
                        thin: true,
                    });
                }
                panels.push(plot::Panel {
                    y_label: format!("{signal} residual amplitude [pu]"),
                    series,
                });
                decor.push(plot::Decor {
                    markers: sp
                        .peak_hz
                        .map(|f| plot::Marker {
                            label: format!(
                                "peak {f:.2} Hz, {} pu ({:.1}× median)",
                                num(sp.peak_amplitude),
                                sp.peak_significance
                            ),
                            x: f,
                            y: sp.peak_amplitude,
                            color: plot::SIMULATED,
                        })
                        .into_iter()
                        .collect(),
                    ..Default::default()
                });
            }
            if !panels.is_empty() {
                let file = format!("spectrum-{stem}.svg");
                let svg = draw(
                    &file,
                    &format!("{event}: residual amplitude spectra"),
                    "frequency [Hz]",
                    &panels,
                    &decor,
                )?;
                files.push(PlotFile {
                    file,
                    event: event.clone(),
                    caption: "amplitude spectra of the compared signals' residuals (Hann window), \
                              the peak marked"
                        .into(),
                    svg,
                });
            }
        }

        // Measured against simulated, before and after the extension.
        let col = |tr: &Traces, n: &str| {
            tr.get(n)
                .map(|c| c.to_vec())
                .unwrap_or_else(|| vec![f64::NAN; tr.time_s.len()])
        };
        let (pm, qm, pb, qb) = (
            col(tr, "p_meas_pu"),
            col(tr, "q_meas_pu"),
            col(tr, "p_pu"),
            col(tr, "q_pu"),
        );
        let (pa, qa) = match tr_after {
            Some(ta) => (col(ta, "p_pu"), col(ta, "q_pu")),
            None => (vec![], vec![]),
        };
        let mut panels = vec![];
        for (signal, m, b, af) in [("P", &pm, &pb, &pa), ("Q", &qm, &qb, &qa)] {
            let mut series = vec![
                plot::Series {
                    label: "measured".into(),
                    x: t,
                    y: m,
                    color: plot::MEASURED,
                    thin: true,
                },
                plot::Series {
                    label: "unit as given".into(),
                    x: t,
                    y: b,
                    color: plot::START,
                    thin: false,
                },
            ];
            if let (Some(ta), Some(cause)) = (tr_after, named) {
                series.push(plot::Series {
                    label: format!("extended ({cause}), re-fitted"),
                    x: &ta.time_s,
                    y: af,
                    color: plot::SIMULATED,
                    thin: false,
                });
            }
            panels.push(plot::Panel {
                y_label: format!("{signal} [pu, system base]"),
                series,
            });
        }
        let file = format!("before-after-{stem}.svg");
        let title = match named {
            Some(c) => format!("{event}: measured, unit as given and extended for {c}"),
            None => format!("{event}: measured and simulated (no cause named, no extension)"),
        };
        let hz = nominal_hz
            .iter()
            .find(|(e, _)| e == event)
            .map(|(_, f)| *f)
            .unwrap_or(60.0);
        let channels = super::other_channels(tr, hz);
        for (label, meas, sim) in &channels {
            let mut series = vec![plot::Series {
                label: if sim.is_empty() {
                    "measured (played back)".into()
                } else {
                    "measured".into()
                },
                x: t,
                y: meas,
                color: plot::MEASURED,
                thin: true,
            }];
            if !sim.is_empty() {
                series.push(plot::Series {
                    label: "unit as given".into(),
                    x: t,
                    y: sim,
                    color: plot::START,
                    thin: false,
                });
            }
            panels.push(plot::Panel {
                y_label: label.clone(),
                series,
            });
        }
        let svg = draw(&file, &title, "time [s]", &panels, &[])?;
        files.push(PlotFile {
            file,
            event: event.clone(),
            caption: "measured and simulated P and Q (before and after the extension) and every other measured channel".into(),
            svg,
        });
    }
    Ok(files)
}

/// The window to shade in the `signal` residual panel of an event: the verdict's (the same
/// labelled window of this event when it has one), otherwise the signal's window with the
/// largest share of the squared error.
pub fn implicated_window(
    r: &Diagnosis,
    ev: Option<&EventEvidence>,
    signal: &str,
) -> Option<plot::Span> {
    if let Some((sig, label, a, b)) = &r.verdict.where_ {
        let own = ev
            .and_then(|e| e.signals.iter().find(|s| &s.signal == sig))
            .and_then(|s| s.windows.iter().find(|w| &w.label == label))
            .map(|w| (w.start_s, w.end_s));
        let (a, b) = own.unwrap_or((*a, *b));
        return Some(plot::Span {
            label: format!("verdict's window: {sig} residual, {label}"),
            x0: a,
            x1: b,
            color: plot::HIGHLIGHT,
        });
    }
    let s = ev?.signals.iter().find(|s| s.signal == signal)?;
    let w = top_window(s)?;
    Some(plot::Span {
        label: format!("most SSE: {} ({:.0} %)", w.label, 100.0 * w.share_of_sse),
        x0: w.start_s,
        x1: w.end_s,
        color: plot::HIGHLIGHT,
    })
}
