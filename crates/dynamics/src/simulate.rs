//! Playback simulation of a unit against a measured event.
//!
//! The unit initialises at the operating point estimated from the event's pre-event window
//! (averages and a straight-line angle fit, not one noisy sample: see
//! [`crate::event::Event::operating_point`]), converted to the machine base. The measured
//! terminal phasor is then played back and the integrator stops at every sample instant, where
//! the outputs are recorded.

use std::path::Path;

use crate::block::InitPoint;
use crate::event::{Channel, Event, SetpointStep};
use crate::integrate::{self, Dopri5Options, GoOn, Method, SolveError, Stats};
use crate::unit::{Playback, PlaybackInput, Unit, UnitError};

/// Options of a playback simulation.
#[derive(Debug, Clone, PartialEq)]
pub struct SimOptions {
    pub method: Method,
}

impl Default for SimOptions {
    /// Dormand-Prince 5(4), rtol 1e-6, atol 1e-7, largest step 50 ms (within 2e-6 pu of an
    /// RK4 0.1 ms reference on the 20 s benchmark event; see `tests/integrator_convergence.rs`).
    fn default() -> Self {
        Self {
            method: Method::Dopri5(Dopri5Options {
                rtol: 1e-6,
                atol: 1e-7,
                h_max: 0.05,
                ..Default::default()
            }),
        }
    }
}

/// Why a simulation failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SimError {
    #[error("unit '{unit}' is for {unit_hz} Hz but event '{event}' is at {event_hz} Hz")]
    Frequency {
        unit: String,
        unit_hz: f64,
        event: String,
        event_hz: f64,
    },
    #[error("initialisation failed: {0}")]
    Init(#[from] UnitError),
    #[error("integration failed: {0}")]
    Solve(#[from] SolveError),
    /// A phasor playback of a record without a voltage angle.
    #[error("event '{event}' has no voltage angle (its channels leave it out): a phasor playback imposes the measured angle; play it back with a mode that needs none (exciter_alone, machine_from_efd, closed_loop)")]
    NoAngle { event: String },
    /// A playback mode needs a channel the record lacks.
    #[error("event '{event}' has no {channel} channel, which playback mode {mode} plays back")]
    MissingChannel {
        event: String,
        mode: &'static str,
        channel: &'static str,
    },
    /// The unit cannot be played back in a mode (no exciter for an exciter playback, no grid
    /// equivalent for a closed loop, …).
    #[error("playback mode {mode}: {msg}")]
    ModeSetup { mode: &'static str, msg: String },
    /// A mode's operating point cannot be found (no Q at which the machine's steady E_fd is the
    /// measured one).
    #[error("playback mode {mode}: initialisation failed: {msg}")]
    ModeInit { mode: &'static str, msg: String },
    /// A mode's closure (the load angle held by the measured P, the network equation of the
    /// grid equivalent) has no solution at time `t`.
    #[error("playback mode {mode}: at t = {t:.4} s: {msg}")]
    ModeSolve {
        mode: &'static str,
        t: f64,
        msg: String,
    },
}

impl SimError {
    /// Whether the playback was stopped by its observer ([`GoOn`]), not by a failure.
    pub fn is_stopped(&self) -> bool {
        matches!(self, SimError::Solve(SolveError::Stopped { .. }))
    }

    /// Short identifier of the error kind.
    pub fn kind(&self) -> &'static str {
        match self {
            SimError::Frequency { .. } => "frequency_mismatch",
            SimError::Init(e) => e.kind(),
            SimError::Solve(_) => "solve",
            SimError::NoAngle { .. } => "no_angle",
            SimError::MissingChannel { .. } => "missing_channel",
            SimError::ModeSetup { .. } => "mode_setup",
            SimError::ModeInit { .. } => "init",
            SimError::ModeSolve { .. } => "solve",
        }
    }
}

/// Everything a playback needs from an event, prepared once (shared by many simulations).
#[derive(Debug, Clone, PartialEq)]
pub struct PreparedEvent {
    /// Event name (for messages).
    pub name: String,
    pub input: PlaybackInput,
    /// Operating point on the **system** base.
    pub op_system: crate::event::OperatingPoint,
    pub system_mva: f64,
    pub nominal_hz: f64,
    /// Whether the record holds the voltage angle (a phasor playback needs it).
    pub has_angle: bool,
    /// Known set-point steps ([`crate::mode`] applies them).
    pub steps: Vec<SetpointStep>,
    /// Measured P [pu system base] (the target of the P-held playback modes).
    pub p_pu: Vec<f64>,
    /// Measured E_fd and X_adI_fd [pu], if recorded, and their init-window means.
    pub efd_pu: Option<Vec<f64>>,
    pub ifd_pu: Option<Vec<f64>>,
    pub efd0: Option<f64>,
    pub ifd0: Option<f64>,
}

impl PreparedEvent {
    pub fn new(event: &Event) -> Self {
        let r = &event.record;
        Self {
            name: event.name.clone(),
            input: event.playback_input(),
            op_system: event.operating_point(),
            system_mva: event.system_mva,
            nominal_hz: event.nominal_hz,
            has_angle: event.has_angle(),
            steps: event.steps.clone(),
            p_pu: r.p_pu.clone(),
            efd_pu: r.efd_pu.clone(),
            ifd_pu: r.ifd_pu.clone(),
            efd0: event.init_mean(Channel::Efd),
            ifd0: event.init_mean(Channel::Ifd),
        }
    }

    /// A unit for another nominal frequency than the record's is refused.
    pub fn check_frequency(&self, unit: &Unit) -> Result<(), SimError> {
        if (unit.nominal_hz - self.nominal_hz).abs() > 1e-9 {
            return Err(SimError::Frequency {
                unit: unit.name.clone(),
                unit_hz: unit.nominal_hz,
                event: self.name.clone(),
                event_hz: self.nominal_hz,
            });
        }
        Ok(())
    }

    /// The point the machine of `unit` initialises at: [`PreparedEvent::init_point`] (what
    /// the measuring device saw) plus any load between the machine and the measurement point,
    /// which the machine delivers as well ([`Unit::terminal_load`] at the measured voltage).
    pub fn machine_point(&self, unit: &Unit) -> InitPoint {
        let mut op = self.init_point(unit);
        let (pl, ql) = unit.terminal_load(op.v_mag);
        op.p += pl;
        op.q += ql;
        op
    }

    /// Initial operating point on the machine base of `unit`, at the measurement point.
    pub fn init_point(&self, unit: &Unit) -> InitPoint {
        let k = self.system_mva / unit.machine_mva;
        let op = &self.op_system;
        InitPoint {
            v_mag: op.v_mag_pu,
            v_ang: op.v_ang_rad,
            p: op.p_pu * k,
            q: op.q_pu * k,
            speed_dev: (op.freq_hz - self.nominal_hz) / self.nominal_hz,
        }
    }
}

/// Runs one playback; `record(k, unit)` is called at every sample `k` with the bus evaluated
/// there (read signals with [`Unit::bus`]). Returns the integrator statistics. A `record` that
/// returns `false` ([`GoOn`]) stops the playback at that sample ([`SimError::is_stopped`]).
///
/// A record without a voltage angle is refused ([`SimError::NoAngle`]). An event with
/// set-point steps is played back by [`crate::mode`] (the unit given to `record` is then the
/// unit as played back, with the set-point block: read its signals by name on it).
pub fn run_playback<F, G>(
    unit: &mut Unit,
    ev: &PreparedEvent,
    opts: &SimOptions,
    mut record: F,
) -> Result<Stats, SimError>
where
    F: FnMut(usize, &Unit, &[f64]) -> G,
    G: GoOn,
{
    if !ev.has_angle {
        return Err(SimError::NoAngle {
            event: ev.name.clone(),
        });
    }
    if !ev.steps.is_empty() {
        let mut mu = crate::mode::ModeUnit::new(unit, ev, crate::mode::PlaybackMode::Phasor)?;
        return crate::mode::run_mode_unit(&mut mu, ev, opts, record);
    }
    ev.check_frequency(unit)?;
    let mut x = unit.initialise(&ev.machine_point(unit))?;
    let over = matches!(&opts.method, Method::Dopri5(o) if o.soft_knots);
    let mut sys = Playback::new(unit, &ev.input).over_samples(over);
    let stats = integrate::solve(
        &opts.method,
        &mut sys,
        &mut x,
        &ev.input.time_s,
        |k, t, x, sys| {
            sys.eval_signals(t, x);
            record(k, sys.unit, x)
        },
    )?;
    Ok(stats)
}

/// Simulated P and Q on the system base at every sample (the quantities a fit compares).
pub fn simulate_pq(
    unit: &mut Unit,
    ev: &PreparedEvent,
    opts: &SimOptions,
) -> Result<(Vec<f64>, Vec<f64>), SimError> {
    simulate_pq_watched(unit, ev, opts, |_, _, _| true)
        .map(|pq| pq.expect("a watch that never stops"))
}

/// [`simulate_pq`], showing `watch(k, P_k, Q_k)` each sample's simulated P and Q (system base,
/// final: as [`simulate_pq`] returns them) as soon as it is known; a `watch` that returns
/// `false` stops the playback there, and the result is `Ok(None)`. The values and the error of a
/// run that is not stopped are [`simulate_pq`]'s, bit for bit.
///
/// A sample is known at once when nothing acts on the recorded series after the playback; a
/// unit that transforms them ([`Unit::transforms_pq`]: a measuring device's delay moves a
/// sample by later ones) or an event with set-point steps shows every sample after the whole
/// playback (a stop then saves no simulation).
/// Simulated P and Q at the record's samples.
pub type PqSeries = (Vec<f64>, Vec<f64>);

pub fn simulate_pq_watched<W>(
    unit: &mut Unit,
    ev: &PreparedEvent,
    opts: &SimOptions,
    mut watch: W,
) -> Result<Option<PqSeries>, SimError>
where
    W: FnMut(usize, f64, f64) -> bool,
{
    let (p, q) = if !ev.steps.is_empty() && ev.has_angle {
        let o = crate::mode::simulate_mode(unit, ev, crate::mode::PlaybackMode::Phasor, opts)?;
        (o.p, o.q)
    } else {
        let n = ev.input.time_s.len();
        let (mut p, mut q) = (vec![0.0; n], vec![0.0; n]);
        let to_sys = unit.machine_mva / ev.system_mva;
        let (ip, iq) = unit.pq_signals()?;
        let live = !unit.transforms_pq();
        let run = run_playback(unit, ev, opts, |k, u, _| {
            let (pk, qk) = u.measured_pq_now(ip, iq);
            p[k] = pk * to_sys;
            q[k] = qk * to_sys;
            !live || watch(k, p[k], q[k])
        });
        match run {
            Err(e) if e.is_stopped() => return Ok(None),
            r => r?,
        };
        if live {
            return Ok(Some((p, q)));
        }
        unit.transform_pq(&ev.input.time_s, &mut p, &mut q);
        (p, q)
    };
    for k in 0..p.len() {
        if !watch(k, p[k], q[k]) {
            return Ok(None);
        }
    }
    Ok(Some((p, q)))
}

/// Recorded traces: one row per sample, named columns.
#[derive(Debug, Clone, PartialEq)]
pub struct Traces {
    pub time_s: Vec<f64>,
    /// Column names (without `time_s`).
    pub names: Vec<String>,
    /// Column data, same order as `names`.
    pub columns: Vec<Vec<f64>>,
    pub stats: Stats,
}

impl Traces {
    /// A column by name.
    pub fn get(&self, name: &str) -> Option<&[f64]> {
        self.names
            .iter()
            .position(|n| n == name)
            .map(|k| self.columns[k].as_slice())
    }

    /// Writes `time_s` and every column as CSV.
    pub fn write_csv(&self, path: &Path) -> std::io::Result<()> {
        let mut w = csv::Writer::from_path(path)?;
        let mut header = vec!["time_s".to_string()];
        header.extend(self.names.iter().cloned());
        w.write_record(&header)?;
        let mut row = Vec::with_capacity(header.len());
        for k in 0..self.time_s.len() {
            row.clear();
            row.push(format!("{}", self.time_s[k]));
            for c in &self.columns {
                row.push(format!("{:.10e}", c[k]));
            }
            w.write_record(&row)?;
        }
        w.flush()
    }
}

/// Simulates `unit` against `event` and records, at every sample:
/// `p_pu`, `q_pu` (simulated, system base, as a measuring device would record them: after any
/// `pmu_measurement` block's skew, phase and ratio errors), `p_meas_pu`, `q_meas_pu` (measured, system base),
/// `p_mach_pu`, `q_mach_pu` (simulated, machine base, at the measurement point: after any
/// `terminal_load`), every signal on the bus (`v_term`,
/// `theta_term`, `delta`, `speed`, `pe`, `qe`, `te`, `efd`, `xadifd`, `pm`, `vs`, …, machine
/// base) and every state as `block.state`; measured `efd_meas_pu`, `ifd_meas_pu`,
/// `freq_meas_hz` when the event has them.
pub fn simulate(unit: &Unit, event: &Event, opts: &SimOptions) -> Result<Traces, SimError> {
    if !event.steps.is_empty() && event.has_angle() {
        return crate::mode::simulate_mode_traces(
            unit,
            event,
            crate::mode::PlaybackMode::Phasor,
            opts,
        );
    }
    let ev = PreparedEvent::new(event);
    let mut unit = unit.clone();
    simulate_prepared(&mut unit, &ev, event, opts)
}

/// [`simulate`] with a prepared event and a unit that may be reused.
pub fn simulate_prepared(
    unit: &mut Unit,
    ev: &PreparedEvent,
    event: &Event,
    opts: &SimOptions,
) -> Result<Traces, SimError> {
    if !ev.steps.is_empty() && ev.has_angle {
        // The unit as played back has the set-point block: its own columns.
        return crate::mode::simulate_mode_traces(
            unit,
            event,
            crate::mode::PlaybackMode::Phasor,
            opts,
        );
    }
    let n = ev.input.time_s.len();
    let to_sys = unit.machine_mva / ev.system_mva;
    // The column layout is fixed once the wiring is resolved (run_playback initialises).
    if unit.instances().is_empty() {
        return Err(SimError::Init(UnitError::Wiring("empty unit".into())));
    }
    unit.ensure_finished()?;
    let signals: Vec<String> = unit.signal_names().to_vec();
    let states = unit.state_names();
    let (ip, iq) = unit.pq_signals()?;
    let names = trace_names(&signals, &states);
    let mut cols: Vec<Vec<f64>> = vec![Vec::with_capacity(n); names.len()];
    let stats = run_playback(unit, ev, opts, |_, u, x| {
        let bus = u.bus();
        let (pk, qk) = u.measured_pq_now(ip, iq);
        cols[0].push(pk * to_sys);
        cols[1].push(qk * to_sys);
        cols[4].push(pk);
        cols[5].push(qk);
        for (j, v) in bus.iter().enumerate() {
            cols[6 + j].push(*v);
        }
        for (j, v) in x.iter().enumerate() {
            cols[6 + signals.len() + j].push(*v);
        }
    })?;
    Ok(finish_traces(
        unit,
        event,
        &ev.input.time_s,
        names,
        cols,
        stats,
        true,
        false,
    ))
}

/// The columns of [`Traces`] holding a channel: `(simulated, measured)`. The simulated column
/// is the system-base P or Q, or the bus signal (`v_term`, `efd`, `xadifd`); the measured one
/// is present where the record holds the channel ([`finish_traces`]). `None` for the angle and
/// the frequency, which a playback imposes rather than simulates.
pub fn trace_columns(c: Channel) -> Option<(&'static str, &'static str)> {
    Some(match c {
        Channel::P => ("p_pu", "p_meas_pu"),
        Channel::Q => ("q_pu", "q_meas_pu"),
        Channel::V => ("v_term", "v_meas_pu"),
        Channel::Efd => ("efd", "efd_meas_pu"),
        Channel::Ifd => ("xadifd", "ifd_meas_pu"),
        Channel::Angle | Channel::Freq => return None,
    })
}

/// The columns of [`Traces`] before the measured ones: P and Q on the system base, their
/// measured columns, P and Q on the machine base, every bus signal, every state.
pub(crate) fn trace_names(signals: &[String], states: &[String]) -> Vec<String> {
    let col = |c: Channel| trace_columns(c).expect("P and Q have trace columns");
    let (p, q) = (col(Channel::P), col(Channel::Q));
    let mut names: Vec<String> = [p.0, q.0, p.1, q.1, "p_mach_pu", "q_mach_pu"]
        .map(String::from)
        .to_vec();
    names.extend(signals.iter().cloned());
    names.extend(states.iter().cloned());
    names
}

/// Completes a playback's [`Traces`] (columns laid out by [`trace_names`]): with `measuring`,
/// P and Q as a measuring device would record them (the unit's skew, phase and ratio errors, on
/// both bases); the recorded P and Q in their measured columns; with `v_meas` the recorded |V|;
/// then the recorded optional channels.
#[allow(clippy::too_many_arguments)]
pub(crate) fn finish_traces(
    unit: &Unit,
    event: &Event,
    time_s: &[f64],
    mut names: Vec<String>,
    mut cols: Vec<Vec<f64>>,
    stats: Stats,
    measuring: bool,
    v_meas: bool,
) -> Traces {
    if measuring {
        let (c0, rest) = cols.split_at_mut(1);
        unit.transform_pq(time_s, &mut c0[0], &mut rest[0]);
        let (c4, rest) = cols[4..].split_at_mut(1);
        unit.transform_pq(time_s, &mut c4[0], &mut rest[0]);
    }
    let r = &event.record;
    cols[2] = r.p_pu.clone();
    cols[3] = r.q_pu.clone();
    let meas = |c: Channel| trace_columns(c).map_or("", |(_, m)| m);
    if v_meas {
        names.push(meas(Channel::V).into());
        cols.push(r.v_mag_pu.clone());
    }
    for (name, col) in [
        (meas(Channel::Efd), &r.efd_pu),
        (meas(Channel::Ifd), &r.ifd_pu),
        ("freq_meas_hz", &r.freq_hz),
    ] {
        if let Some(c) = col {
            names.push(name.to_string());
            cols.push(c.clone());
        }
    }
    Traces {
        time_s: time_s.to_vec(),
        names,
        columns: cols,
        stats,
    }
}
