//! Playback modes: what is imposed from the record, what is simulated, and how the unit is
//! closed where the record has no voltage angle.
//!
//! A phasor playback ([`PlaybackMode::Phasor`], [`crate::simulate`]) imposes the measured
//! terminal phasor |V|∠θ and computes P and Q. A staged excitation test recorded by the
//! excitation system's own recorder (the bundled Mostar record: |V|, P, Q, E_fd on a
//! non-uniform time base, no angle, no frequency) cannot be played back that way. Three modes
//! need no angle; each states what it imposes, what it compares and what it assumes.
//!
//! | mode | imposed from the record | simulated (comparable) | default compared |
//! |---|---|---|---|
//! | `phasor` | \|V\|, θ (and the steps) | P, Q, E_fd, X_adI_fd | P, Q |
//! | `exciter_alone` | \|V\|, P, E_fd (I_fd if recorded), the steps | E_fd | E_fd |
//! | `machine_from_efd` | \|V\|, P, E_fd | Q, X_adI_fd | Q |
//! | `closed_loop` | the steps (and the grid equivalent) | \|V\|, P, Q, E_fd, X_adI_fd | \|V\|, Q, E_fd |
//!
//! # `exciter_alone`: the AVR (and PSS) open loop
//!
//! The standard exciter validation of a step test: the exciter's regulated-voltage input
//! `E_comp` is the measured |V|, the set-point steps enter its reference, and its output E_fd is
//! compared with the measured E_fd; the exciter's output drives nothing. Its field-current input
//! (ST5B's and ESST1A's K_C·X_adI_fd commutation term, a field current limiter) is the recorded
//! I_fd (as X_ad·I_fd) when the record has it; otherwise the machine's X_adI_fd with the machine
//! driven as in `machine_from_efd` by the *measured* E_fd, |V| and P (so the exciter is still
//! open loop: its own E_fd reaches nothing). The K_C term matters: K_C = 0.3 and a field current
//! rising by 0.7 pu after a +5 % step move the bridge output by 0.2 pu. A stabiliser reading P
//! gets the measured P (the machine holds it, below); one reading the rotor speed is refused
//! (not simulated here). Exact initialisation: the exciter starts at the measured pre-event E_fd
//! (the mean over the init window) with its field current input at its pre-event value
//! (X_adI_fd0 = E_fd0 in the steady state of every PSS/E machine, or the recorded I_fd's mean),
//! and solves its reference from them as in every playback.
//!
//! # `machine_from_efd`: the machine driven by its measured field voltage
//!
//! The measured E_fd and |V| drive the machine; Q (and X_adI_fd against a recorded I_fd) is
//! compared. **The rotor angle.** Without a voltage angle one more equation is needed to place
//! the terminal voltage in the rotor's frame. The measured active power gives it: the load
//! angle `φ = δ − θ` is solved at every evaluation so that the machine delivers the measured P
//! at the measured |V| (`P_e(φ, |V|, E'', …) = P_meas(t)`; Newton from the last solution, on the
//! stable branch `φ < 90°` where it starts). This is the phasor playback's boundary condition
//! with P in place of θ: the electrical equations see exactly the terminal state the record
//! shows, and no network model is assumed. The price: P is an input, not an output, and the
//! mechanical side (H, D, the governor) is not exercised: the swing states still integrate but
//! δ and the speed mean nothing in this mode (so a stabiliser reading speed is refused). The
//! alternative, a swing equation against a terminal angle held constant, makes the terminal an
//! infinite bus (it is not: the grid behind it has an impedance) and its P error would show the
//! missing impedance, not the machine. **Face value.** The measured E_fd drives the machine as
//! recorded (pu of the model's air-gap-line field base), so exact initialisation needs the
//! operating point where the machine's steady E_fd equals the measured pre-event E_fd at the
//! measured |V| and P: its reactive power `Q0*` is solved (secant with bracketing) and the
//! machine starts there. `Q_sim(t0) − Q_meas(t0)` is then what the model's E_fd-to-Q map
//! misses (X_d, saturation, or the field base of the recording), and the fit sees it.
//!
//! # `closed_loop`: the whole unit against a grid equivalent
//!
//! The unit (machine, exciter, PSS, governor or constant P_m) behind the impedance
//! `Z_e = R_e + jX_e` of a `grid_equivalent` block to an infinite bus, as RaPId's Mostar model
//! (X = 0.1169 pu); the set-point steps are the event. `Z_e` is a parameter of the unit
//! (`grid.x_e`, `grid.r_e`: a fit may free it); the infinite-bus voltage `E_∞` is initialised
//! from the pre-event operating point, `E_∞ = V_t0 − Z_e I_t0` (magnitude and angle: the unit
//! starts in the measured steady state whatever `Z_e`), and stays fixed, rotating at the
//! pre-event frequency. At every evaluation the terminal voltage solves
//! `V_t = E_∞ + Z_e · I_t(V_t)`, `I_t = conj(S_t / V_t)` the current the unit delivers at its
//! terminal (after a `terminal_load`): Newton in (Re V_t, Im V_t) with a chord Jacobian (the
//! machine's current is affine in V_t, so one step converges to rounding). |V|, Q and E_fd are
//! compared (P too if asked; RaPId's fitness sums P, Q, E_fd and |V|). The machine starts at the
//! measured (|V|, P, Q): its E_fd0 is the model's, and a model whose E_fd0 differs from the
//! recorded one shows it as an E_fd offset (RaPId's model does the same).
//!
//! # Set-point steps
//!
//! A declared step of `v_ref` ([`crate::event::SetpointStep`]) enters the exciter where the
//! stabiliser signal V_S does: a summing block `setpoint` writes `V_S = V_S,pss + ΔV_ref(t)` (the
//! PSS's output is rewired to `vs_pss`), and every exciter of the library adds V_S to
//! `V_ref − V_m` at the voltage summing point (ST5B with its UEL/OEL inputs summing or gates not
//! selecting, SEXS, IEEET1, ESST1A with `vos = "1"`; `vos = "2"` puts V_S after the regulator
//! and is refused). That is where a digital AVR's set point acts: after the voltage transducer
//! (RaPId's Mostar model instead subtracts the step from E_comp, which passes it through the
//! transducer lag T_R). The integration is split at every step instant (a knot on each side of
//! the discontinuity, no step straddles it, Dormand-Prince restarts its FSAL stage), and a
//! sample stamped exactly at a step sees the new set point.
//!
//! # Knots and time base
//!
//! Every mode stops at every recorded stamp (uniform or not) and plays the measured inputs
//! linearly between stamps; the outputs are read at the stamps.

use std::fmt;

use serde::{Deserialize, Serialize};

use crate::block::{Block, Dir, InitPoint, Io, ModelError, Port, PortInit};
use crate::event::{step_level, Channel, Event, SetpointStep};
use crate::integrate::{self, OdeSystem, Stats};
use crate::models::machine::Phasor;
use crate::params::{ParamSet, ParamSpec};
use crate::simulate::{run_playback, PreparedEvent, SimError, SimOptions, Traces};
use crate::unit::{Unit, UnitError};

/// How a record is played back into the unit (see the module documentation).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, Hash)]
#[serde(rename_all = "snake_case")]
pub enum PlaybackMode {
    /// The measured phasor |V|∠θ imposed at the terminal.
    #[default]
    Phasor,
    /// The exciter (and PSS) open loop on the measured |V|, compared on E_fd.
    ExciterAlone,
    /// The machine on the measured E_fd, |V| and P, compared on Q.
    MachineFromEfd,
    /// The whole unit against a grid equivalent, compared on |V|, Q, E_fd.
    ClosedLoop,
}

impl PlaybackMode {
    /// Every mode, in the order of [`PlaybackMode::NAMES`].
    pub const ALL: [PlaybackMode; 4] = [
        PlaybackMode::Phasor,
        PlaybackMode::ExciterAlone,
        PlaybackMode::MachineFromEfd,
        PlaybackMode::ClosedLoop,
    ];
    /// The names, as in a calibration spec.
    pub const NAMES: [&'static str; 4] =
        ["phasor", "exciter_alone", "machine_from_efd", "closed_loop"];

    pub fn name(self) -> &'static str {
        Self::NAMES[self as usize]
    }

    /// The mode named `s`.
    pub fn parse(s: &str) -> Option<PlaybackMode> {
        Self::NAMES
            .iter()
            .position(|n| *n == s)
            .map(|i| Self::ALL[i])
    }

    /// The recorded channels the mode plays back (besides P and Q, which every mode's
    /// operating point needs).
    pub fn inputs(self) -> &'static [Channel] {
        match self {
            PlaybackMode::Phasor => &[Channel::V, Channel::Angle, Channel::P, Channel::Q],
            PlaybackMode::ExciterAlone | PlaybackMode::MachineFromEfd => {
                &[Channel::V, Channel::P, Channel::Q, Channel::Efd]
            }
            PlaybackMode::ClosedLoop => &[Channel::V, Channel::P, Channel::Q],
        }
    }

    /// The channels the mode simulates, which a fit may compare with the record.
    pub fn outputs(self) -> &'static [Channel] {
        match self {
            PlaybackMode::Phasor => &[Channel::P, Channel::Q, Channel::Efd, Channel::Ifd],
            PlaybackMode::ExciterAlone => &[Channel::Efd],
            PlaybackMode::MachineFromEfd => &[Channel::Q, Channel::Ifd],
            PlaybackMode::ClosedLoop => &[
                Channel::V,
                Channel::P,
                Channel::Q,
                Channel::Efd,
                Channel::Ifd,
            ],
        }
    }

    /// The channels compared by default (equal weights).
    pub fn default_channels(self) -> &'static [Channel] {
        match self {
            PlaybackMode::Phasor => &[Channel::P, Channel::Q],
            PlaybackMode::ExciterAlone => &[Channel::Efd],
            PlaybackMode::MachineFromEfd => &[Channel::Q],
            PlaybackMode::ClosedLoop => &[Channel::V, Channel::Q, Channel::Efd],
        }
    }

    /// Whether the declared set-point steps act in this mode (not when E_fd is imposed).
    pub fn applies_steps(self) -> bool {
        self != PlaybackMode::MachineFromEfd
    }

    /// Why `event` cannot be played back in this mode comparing `compared`: a channel the mode
    /// plays back or compares that the record lacks. `None` when it can.
    pub fn missing(self, event: &Event, compared: &[Channel]) -> Option<String> {
        if let Some(c) = self.inputs().iter().find(|c| !event.has(**c)) {
            return Some(if *c == Channel::Angle {
                format!(
                    "has no voltage angle (channels: {}), which a phasor playback imposes; play it \
                     back with a mode that needs none (exciter_alone, machine_from_efd, \
                     closed_loop)",
                    channel_list(&event.channels)
                )
            } else {
                format!(
                    "has no {c} channel (column {}), which mode {} plays back (channels: {})",
                    c.columns(),
                    self.name(),
                    channel_list(&event.channels)
                )
            });
        }
        compared.iter().find(|c| !event.has(**c)).map(|c| {
            format!(
                "has no {c} channel (column {}) to compare with (channels: {})",
                c.columns(),
                channel_list(&event.channels)
            )
        })
    }
}

impl fmt::Display for PlaybackMode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

fn channel_list(c: &[Channel]) -> String {
    c.iter().map(|c| c.name()).collect::<Vec<_>>().join(", ")
}

/// Simulated channels at every sample of the record, as they are compared: P and Q on the
/// **system** base at the measurement point (the measured P in the P-held modes), |V|, E_fd and
/// X_adI_fd on the machine base.
#[derive(Debug, Clone, PartialEq)]
pub struct ModeOutputs {
    pub p: Vec<f64>,
    pub q: Vec<f64>,
    pub v: Vec<f64>,
    pub efd: Vec<f64>,
    pub ifd: Vec<f64>,
    pub stats: Stats,
}

impl ModeOutputs {
    /// `n` samples of every channel, each NaN until a playback writes it.
    fn unset(n: usize) -> Self {
        Self {
            p: vec![f64::NAN; n],
            q: vec![f64::NAN; n],
            v: vec![f64::NAN; n],
            efd: vec![f64::NAN; n],
            ifd: vec![f64::NAN; n],
            stats: Stats::default(),
        }
    }

    /// The simulated series of channel `c` (`None` for the angle and the frequency).
    pub fn channel(&self, c: Channel) -> Option<&[f64]> {
        match c {
            Channel::P => Some(&self.p),
            Channel::Q => Some(&self.q),
            Channel::V => Some(&self.v),
            Channel::Efd => Some(&self.efd),
            Channel::Ifd => Some(&self.ifd),
            Channel::Angle | Channel::Freq => None,
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Helper blocks (put into the unit by a mode; never in a unit file)
// ---------------------------------------------------------------------------------------------

/// No parameters.
#[derive(Debug, Clone, Default)]
struct NoParams;

impl ParamSet for NoParams {
    fn specs(&self) -> &'static [ParamSpec] {
        &[]
    }
    fn get(&self, index: usize) -> f64 {
        panic!("no parameter {index}")
    }
    fn set(&mut self, index: usize, _value: f64) {
        panic!("no parameter {index}")
    }
}

/// `vs = vs_pss + vref_step`: a set-point step added where the stabiliser signal enters.
#[derive(Debug, Clone, Default)]
struct SetpointSum {
    p: NoParams,
}

const SUM_PORTS: &[Port] = &[
    Port::input_ft("vs_pss", PortInit::Needs, "stabiliser output V_S,pss [pu]").optional(),
    Port::input_ft(
        "vref_step",
        PortInit::Needs,
        "set-point step ΔV_ref(t) [pu]",
    ),
    Port::output(
        "vs",
        PortInit::Gives,
        "V_S,pss + ΔV_ref [pu] into the exciter",
    ),
];

impl Block for SetpointSum {
    crate::block_common!();
    fn model(&self) -> &'static str {
        "setpoint_step"
    }
    fn ports(&self) -> &'static [Port] {
        SUM_PORTS
    }
    fn state_names(&self) -> &'static [&'static str] {
        &[]
    }
    fn validate(&self) -> Result<(), ModelError> {
        Ok(())
    }
    fn init(&mut self, _op: &InitPoint, _x: &mut [f64], io: &mut Io) -> Result<(), ModelError> {
        io.set(2, io.get(0) + io.get(1));
        Ok(())
    }
    fn outputs(&self, _t: f64, _x: &[f64], io: &mut Io) {
        io.set(2, io.get(0) + io.get(1));
    }
    fn derivatives(&self, _t: f64, _x: &[f64], _io: &Io, _dx: &mut [f64]) {}
}

/// Gives a signal its initial value (the measured E_fd0 the open-loop exciter starts at).
#[derive(Debug, Clone, Default)]
struct InitTarget {
    p: NoParams,
    value: f64,
}

const TARGET_PORTS: &[Port] = &[Port::input(
    "target",
    PortInit::Gives,
    "the signal whose initial value is the measured one",
)];

impl Block for InitTarget {
    crate::block_common!();
    fn model(&self) -> &'static str {
        "measured_initial_value"
    }
    fn ports(&self) -> &'static [Port] {
        TARGET_PORTS
    }
    fn state_names(&self) -> &'static [&'static str] {
        &[]
    }
    fn validate(&self) -> Result<(), ModelError> {
        Ok(())
    }
    fn init(&mut self, _op: &InitPoint, _x: &mut [f64], io: &mut Io) -> Result<(), ModelError> {
        io.set(0, self.value);
        Ok(())
    }
    fn outputs(&self, _t: f64, _x: &[f64], _io: &mut Io) {}
    fn derivatives(&self, _t: f64, _x: &[f64], _io: &Io, _dx: &mut [f64]) {}
}

// ---------------------------------------------------------------------------------------------
// Building the unit a mode plays back
// ---------------------------------------------------------------------------------------------

/// How the terminal voltage's angle (or the whole terminal voltage) is obtained.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Closure {
    /// The measured angle (phasor playback).
    Measured,
    /// The load angle solved so that the unit delivers the measured P.
    PHeld,
    /// The terminal voltage solved against the grid equivalent `(R_e, X_e)`.
    Grid { r: f64, x: f64 },
}

/// A unit prepared for one mode and one event, with what the driver needs.
pub struct ModeUnit {
    /// The unit as played back (helper blocks added, ports rewired).
    pub unit: Unit,
    pub mode: PlaybackMode,
    closure: Closure,
    /// Bus indices of the driver-written signals.
    ext_efd: Option<usize>,
    ext_ifd: Option<usize>,
    ext_step: Option<usize>,
    /// The steps that act.
    steps: Vec<SetpointStep>,
    /// The operating point the unit initialises at (machine base).
    op: InitPoint,
    preset: Vec<(usize, f64)>,
    ip: usize,
    iq: usize,
    iefd: usize,
    iifd: Option<usize>,
}

fn setup(mode: PlaybackMode, msg: impl Into<String>) -> SimError {
    SimError::ModeSetup {
        mode: mode.name(),
        msg: msg.into(),
    }
}

impl ModeUnit {
    /// Prepares `unit` for playing `ev` back in `mode` and finds its initial operating point
    /// (see the module documentation; errors name what is missing).
    pub fn new(unit: &Unit, ev: &PreparedEvent, mode: PlaybackMode) -> Result<ModeUnit, SimError> {
        ev.check_frequency(unit)?;
        if mode == PlaybackMode::Phasor && !ev.has_angle {
            return Err(SimError::NoAngle {
                event: ev.name.clone(),
            });
        }
        let needs_efd = matches!(
            mode,
            PlaybackMode::ExciterAlone | PlaybackMode::MachineFromEfd
        );
        if needs_efd && ev.efd_pu.is_none() {
            return Err(SimError::MissingChannel {
                event: ev.name.clone(),
                mode: mode.name(),
                channel: "efd",
            });
        }
        let mut u = unit.clone();
        u.ensure_finished()?;
        // The field voltage the exciter writes and the machine reads (as the unit wires it).
        let mut efd_signal = instance(&u, "machine")
            .and_then(|m| port_signal(m, "efd", Dir::In))
            .ok_or_else(|| setup(mode, "the unit has no block named 'machine'"))?;
        if mode == PlaybackMode::MachineFromEfd {
            let drop: Vec<&str> = ["exciter", "pss"]
                .into_iter()
                .filter(|n| u.block(n).is_some())
                .collect();
            u = u.without(&drop)?;
        }
        let steps: Vec<SetpointStep> = if mode.applies_steps() {
            ev.steps.clone()
        } else {
            vec![]
        };
        if !steps.is_empty() {
            add_setpoint(&mut u, mode)?;
        }
        let p_held = matches!(
            mode,
            PlaybackMode::ExciterAlone | PlaybackMode::MachineFromEfd
        );
        if p_held {
            refuse_speed_readers(&u, mode)?;
            u.add_external("efd_meas");
            u.rewire("machine", &[("efd".into(), "efd_meas".into())])?;
        }
        if mode == PlaybackMode::ExciterAlone {
            let exc = instance(&u, "exciter").ok_or_else(|| {
                setup(
                    mode,
                    "the unit has no exciter (no block named 'exciter') to play back",
                )
            })?;
            let efd_sig = port_signal(exc, "efd", Dir::Out)
                .ok_or_else(|| setup(mode, "the exciter has no output port 'efd'"))?;
            efd_signal = efd_sig.clone();
            let has_ifd_port = port_signal(exc, "xadifd", Dir::In).is_some();
            let efd0 = ev.efd0.expect("checked above");
            u.add(
                "measured_efd0",
                Box::new(InitTarget {
                    p: NoParams,
                    value: efd0,
                }),
                &[("target".into(), efd_sig)],
            )?;
            if ev.ifd_pu.is_some() && has_ifd_port {
                u.add_external("xadifd_meas");
                u.rewire("exciter", &[("xadifd".into(), "xadifd_meas".into())])?;
            }
        }
        let closure = match mode {
            PlaybackMode::Phasor => Closure::Measured,
            PlaybackMode::ExciterAlone | PlaybackMode::MachineFromEfd => Closure::PHeld,
            PlaybackMode::ClosedLoop => {
                let g = u
                    .instances()
                    .iter()
                    .find(|i| i.block.model() == crate::models::grid::MODEL.name)
                    .ok_or_else(|| {
                        setup(
                            mode,
                            "the unit has no grid equivalent: add [[block]] name = \"grid\", \
                             model = \"grid_equivalent\", x_e = …, r_e = … (pu on the machine \
                             base) to the unit file, or put one in with a calibration stage's \
                             [calibration.stage.replace.grid]",
                        )
                    })?;
                let ps = g.block.params();
                let get = |n: &str| ps.index_of(n).map(|i| ps.get(i)).unwrap_or(0.0);
                Closure::Grid {
                    r: get("r_e"),
                    x: get("x_e"),
                }
            }
        };
        u.finish()?;
        let idx = |name: &str| u.signal_index(name);
        let ext_efd = if p_held { idx("efd_meas") } else { None };
        let ext_ifd = idx("xadifd_meas").filter(|_| ev.ifd_pu.is_some());
        let ext_step = if steps.is_empty() {
            None
        } else {
            idx("vref_step")
        };
        let (ip, iq) = u.pq_signals()?;
        // E_fd as compared: the exciter's output, or the played-back one the machine reads.
        let iefd = if mode == PlaybackMode::MachineFromEfd {
            ext_efd
        } else {
            idx(&efd_signal)
        }
        .ok_or_else(|| UnitError::Wiring(format!("no signal '{efd_signal}'")))?;
        let iifd = idx("xadifd");

        // The operating point.
        let mut op = ev.machine_point(&u);
        if !ev.has_angle {
            op.v_ang = 0.0;
        }
        let mut preset = vec![];
        if let (Some(i), Some(e)) = (ext_efd, ev.efd0) {
            preset.push((i, e));
        }
        if let (Some(i), Some(e)) = (ext_ifd, ev.ifd0) {
            preset.push((i, e));
        }
        if let Some(i) = ext_step {
            preset.push((i, 0.0));
        }
        if p_held {
            op.q = solve_q0(&u, &op, ext_efd.expect("p-held"), ev, mode)?;
        }
        Ok(ModeUnit {
            unit: u,
            mode,
            closure,
            ext_efd,
            ext_ifd,
            ext_step,
            steps,
            op,
            preset,
            ip,
            iq,
            iefd,
            iifd,
        })
    }

    /// The operating point the unit starts at (machine base; in the P-held modes its Q is the
    /// solved `Q0*`).
    pub fn init_point(&self) -> InitPoint {
        self.op
    }
}

/// The bus indices of the field channels the phasor playback reads: E_fd (the signal the
/// machine's `efd` input is wired to) and X_ad I_fd (`xadifd`); `None` where the unit has none.
pub(crate) fn field_signals(u: &Unit) -> (Option<usize>, Option<usize>) {
    let efd = instance(u, "machine")
        .and_then(|m| port_signal(m, "efd", Dir::In))
        .and_then(|s| u.signal_index(&s));
    (efd, u.signal_index("xadifd"))
}

fn instance<'a>(u: &'a Unit, name: &str) -> Option<&'a crate::unit::Instance> {
    u.instances().iter().find(|i| i.name == name)
}

/// The signal port `port` (of direction `dir`) of an instance is wired to.
fn port_signal(inst: &crate::unit::Instance, port: &str, dir: Dir) -> Option<String> {
    inst.block
        .ports()
        .iter()
        .zip(&inst.wiring)
        .find(|(p, _)| p.name == port && p.dir == dir)
        .map(|(_, w)| w.clone())
}

/// Puts the set-point summing block in front of the exciter's `vs` input.
fn add_setpoint(u: &mut Unit, mode: PlaybackMode) -> Result<(), SimError> {
    let exc = instance(u, "exciter").ok_or_else(|| {
        setup(
            mode,
            "the event declares set-point steps (v_ref) but the unit has no exciter (no block \
             named 'exciter')",
        )
    })?;
    if exc
        .block
        .options()
        .iter()
        .any(|(k, v)| *k == "vos" && v.as_str() != "1")
    {
        return Err(setup(
            mode,
            format!(
                "the exciter ({}) takes its stabiliser signal after the regulator (vos = \"2\"), \
                 not where V_ref acts, so a V_ref step cannot enter there",
                exc.block.model()
            ),
        ));
    }
    let vs = port_signal(exc, "vs", Dir::In).ok_or_else(|| {
        setup(
            mode,
            format!(
                "the exciter ({}) has no input port 'vs', where a V_ref step enters",
                exc.block.model()
            ),
        )
    })?;
    // The block that writes V_S (a PSS) now writes vs_pss.
    let writers: Vec<(String, String)> = u
        .instances()
        .iter()
        .filter_map(|i| {
            i.block
                .ports()
                .iter()
                .zip(&i.wiring)
                .find(|(p, w)| p.dir == Dir::Out && **w == vs)
                .map(|(p, _)| (i.name.clone(), p.name.to_string()))
        })
        .collect();
    for (name, port) in writers {
        u.rewire(&name, &[(port, "vs_pss".into())])?;
    }
    u.add_external("vref_step");
    u.add(
        "setpoint",
        Box::new(SetpointSum::default()),
        &[
            ("vs_pss".into(), "vs_pss".into()),
            ("vref_step".into(), "vref_step".into()),
            ("vs".into(), vs),
        ],
    )?;
    Ok(())
}

/// In the P-held modes the rotor speed is not simulated: a stabiliser or an exciter reading it
/// would be driven by a meaningless signal.
fn refuse_speed_readers(u: &Unit, mode: PlaybackMode) -> Result<(), SimError> {
    for name in ["pss", "exciter"] {
        if let Some(i) = instance(u, name) {
            let reads = i
                .block
                .ports()
                .iter()
                .zip(&i.wiring)
                .any(|(p, w)| p.dir == Dir::In && w == "speed");
            if reads {
                return Err(setup(
                    mode,
                    format!(
                        "the {name} ({}) reads the rotor speed, which {} does not simulate (the \
                         load angle is held by the measured P); use closed_loop, or a unit \
                         without it",
                        i.block.model(),
                        mode.name()
                    ),
                ));
            }
        }
    }
    Ok(())
}

/// The reactive power at which the machine's steady E_fd equals the measured pre-event E_fd
/// (at the measured |V| and P): the P-held modes' exact initial point.
fn solve_q0(
    u: &Unit,
    op: &InitPoint,
    ext_efd: usize,
    ev: &PreparedEvent,
    mode: PlaybackMode,
) -> Result<f64, SimError> {
    let target = ev.efd0.expect("checked");
    let others: Vec<&str> = u
        .instances()
        .iter()
        .map(|i| i.name.as_str())
        .filter(|n| *n != "machine")
        .collect();
    let mut m = u.without(&others)?;
    let efd_at = |m: &mut Unit, q: f64| -> Result<f64, UnitError> {
        let o = InitPoint { q, ..*op };
        m.initialise(&o)?;
        Ok(m.bus()[ext_efd] - target)
    };
    let q0 = op.q;
    let f0 = efd_at(&mut m, q0)?;
    if f0 == 0.0 {
        return Ok(q0);
    }
    // Bracket: E_fd0 rises with Q (over-excitation); step away from q0 doubling.
    let dir = if f0 < 0.0 { 1.0 } else { -1.0 };
    let (mut qa, mut fa) = (q0, f0);
    let mut h = 0.05;
    let mut bracket = None;
    for _ in 0..12 {
        let qb = qa + dir * h;
        match efd_at(&mut m, qb) {
            Ok(fb) => {
                if fb.signum() != fa.signum() || fb == 0.0 {
                    bracket = Some((qa, fa, qb, fb));
                    break;
                }
                (qa, fa) = (qb, fb);
                h *= 2.0;
            }
            Err(_) => break,
        }
    }
    let Some((mut a, mut fa, mut b, mut fb)) = bracket else {
        return Err(SimError::ModeInit {
            mode: mode.name(),
            msg: format!(
                "no operating point at the measured |V| = {:.5} pu, P = {:.5} pu (machine base) \
                 where the machine's steady E_fd equals the measured pre-event E_fd = {target:.5} \
                 pu (at the measured Q = {q0:.5} pu the machine needs E_fd = {:.5} pu); is E_fd \
                 per unit of the machine's field base?",
                op.v_mag,
                op.p,
                f0 + target
            ),
        });
    };
    // Illinois regula falsi to 1e-13 pu of E_fd.
    let mut side = 0;
    for _ in 0..200 {
        let c = (a * fb - b * fa) / (fb - fa);
        let fc = efd_at(&mut m, c)?;
        if fc.abs() < 1e-13 || (b - a).abs() < 1e-15 {
            return Ok(c);
        }
        if fc.signum() == fb.signum() {
            (b, fb) = (c, fc);
            if side == -1 {
                fa *= 0.5;
            }
            side = -1;
        } else {
            (a, fa) = (c, fc);
            if side == 1 {
                fb *= 0.5;
            }
            side = 1;
        }
    }
    Ok((a * fb - b * fa) / (fb - fa))
}

// ---------------------------------------------------------------------------------------------
// The driver
// ---------------------------------------------------------------------------------------------

/// Newton tolerance of the closures [pu].
const CLOSURE_TOL: f64 = 1e-13;
/// Residual accepted when Newton stalls on rounding [pu].
const CLOSURE_STALL_TOL: f64 = 1e-10;
/// Newton iterations before a closure fails.
const CLOSURE_MAX_ITER: usize = 40;

/// The measured inputs of a playback, as the driver reads them.
struct Inputs<'a> {
    t: &'a [f64],
    v: &'a [f64],
    ang: &'a [f64],
    /// Measured P on the machine base (the P-held target).
    p_mach: Vec<f64>,
    efd: Option<&'a [f64]>,
    ifd: Option<&'a [f64]>,
}

impl Inputs<'_> {
    /// `(k, w)`: `t` lies between samples `k` and `k + 1`, weight `w` on `k + 1` (held outside).
    #[inline]
    fn locate(&self, t: f64, cursor: &mut usize) -> (usize, f64) {
        let ts = self.t;
        let n = ts.len();
        if n == 1 || t <= ts[0] {
            return (0, 0.0);
        }
        if t >= ts[n - 1] {
            return (n - 2, 1.0);
        }
        let mut k = (*cursor).min(n - 2);
        while t < ts[k] {
            k -= 1;
        }
        while t > ts[k + 1] {
            k += 1;
        }
        *cursor = k;
        (k, (t - ts[k]) / (ts[k + 1] - ts[k]))
    }
}

#[inline(always)]
fn lerp(y: &[f64], (k, w): (usize, f64)) -> f64 {
    if y.len() == 1 {
        return y[0];
    }
    y[k] + w * (y[k + 1] - y[k])
}

/// The state of a closure between evaluations (warm starts).
struct ClosureState {
    /// P-held: the last terminal angle and dP/dθ there.
    theta: f64,
    dpdth: f64,
    /// Grid: the last terminal voltage (re, im), the chord Jacobian's inverse, E_∞ at t0 and
    /// its rotation [rad/s], the start time.
    v_re: f64,
    v_im: f64,
    jinv: Option<[f64; 4]>,
    e0: Phasor,
    slip: f64,
    t0: f64,
}

struct ModeSystem<'a> {
    unit: &'a mut Unit,
    inp: &'a Inputs<'a>,
    closure: Closure,
    cs: ClosureState,
    ext_efd: Option<usize>,
    ext_ifd: Option<usize>,
    ext_step: Option<usize>,
    level: f64,
    ip: usize,
    iq: usize,
    cursor: usize,
    bus_t: f64,
    bus_x: Vec<f64>,
    bus_valid: bool,
    /// The first closure failure: `(t, message)` (the right-hand side then returns NaN, which
    /// stops the integration; the driver reports this instead).
    fail: Option<(f64, String)>,
}

impl ModeSystem<'_> {
    /// The P and Q at the measurement point now [pu machine base].
    #[inline]
    fn pq(&self) -> (f64, f64) {
        self.unit.measured_pq_now(self.ip, self.iq)
    }

    /// Evaluates every signal at `(t, x)`; returns false when a closure failed.
    fn eval_signals(&mut self, t: f64, x: &[f64]) -> bool {
        if self.bus_valid && t == self.bus_t && x == self.bus_x.as_slice() {
            return true;
        }
        let at = self.inp.locate(t, &mut self.cursor);
        let v = lerp(self.inp.v, at);
        if let (Some(i), Some(e)) = (self.ext_efd, self.inp.efd) {
            self.unit.set_signal(i, lerp(e, at));
        }
        if let (Some(i), Some(e)) = (self.ext_ifd, self.inp.ifd) {
            self.unit.set_signal(i, lerp(e, at));
        }
        if let Some(i) = self.ext_step {
            self.unit.set_signal(i, self.level);
        }
        let ok = match self.closure {
            Closure::Measured => {
                self.unit.set_terminal_voltage(v, lerp(self.inp.ang, at));
                self.unit.eval_outputs(t, x);
                true
            }
            Closure::PHeld => self.solve_p_held(t, x, v, lerp(&self.inp.p_mach, at)),
            Closure::Grid { r, x: xe } => self.solve_grid(t, x, r, xe),
        };
        self.bus_t = t;
        self.bus_x.copy_from_slice(x);
        self.bus_valid = ok;
        ok
    }

    fn fail_at(&mut self, t: f64, msg: String) -> bool {
        if self.fail.is_none() {
            self.fail = Some((t, msg));
        }
        false
    }

    /// P at the terminal with the angle θ [pu machine base].
    fn p_at(&mut self, t: f64, x: &[f64], v: f64, th: f64) -> f64 {
        self.unit.set_terminal_voltage(v, th);
        self.unit.eval_outputs(t, x);
        self.pq().0
    }

    /// Solves θ with P(θ) = `target` (Newton, secant-updated slope, from the last solution).
    fn solve_p_held(&mut self, t: f64, x: &[f64], v: f64, target: f64) -> bool {
        let mut th = self.cs.theta;
        let mut d = self.cs.dpdth;
        let mut g = self.p_at(t, x, v, th) - target;
        let mut best = g.abs();
        for _ in 0..CLOSURE_MAX_ITER {
            if g.abs() <= CLOSURE_TOL {
                self.cs.theta = th;
                self.cs.dpdth = d;
                return true;
            }
            if !(d.is_finite() && d.abs() > 1e-9) {
                let h = 1e-7;
                d = (self.p_at(t, x, v, th + h) - self.p_at(t, x, v, th - h)) / (2.0 * h);
                if !(d.is_finite() && d.abs() > 1e-9) {
                    return self.fail_at(
                        t,
                        format!(
                            "dP/dθ vanishes at |V| = {v:.5} pu (P target {target:.5} pu): pull-out"
                        ),
                    );
                }
            }
            let step = -g / d;
            let th_new = th + step.clamp(-0.2, 0.2);
            let g_new = self.p_at(t, x, v, th_new) - target;
            if !g_new.is_finite() {
                return self.fail_at(t, "the machine's P is not finite".into());
            }
            if (th_new - th).abs() > 1e-15 {
                let ds = (g_new - g) / (th_new - th);
                if ds.is_finite() && ds.abs() > 1e-9 && ds.signum() == d.signum() {
                    d = ds;
                } else {
                    d = f64::NAN;
                }
            }
            th = th_new;
            g = g_new;
            if g.abs() < best {
                best = g.abs();
            }
        }
        if g.abs() <= CLOSURE_STALL_TOL {
            self.cs.theta = th;
            self.cs.dpdth = d;
            return true;
        }
        self.fail_at(
            t,
            format!(
                "no load angle delivers the measured P = {target:.5} pu at |V| = {v:.5} pu \
                 (residual {g:.3e} pu): beyond the machine's pull-out, or its flux collapsed"
            ),
        )
    }

    /// F(V) = V − E_∞(t) − Z·I(V) at the terminal voltage `(vr, vi)`.
    fn grid_residual(
        &mut self,
        t: f64,
        x: &[f64],
        r: f64,
        xe: f64,
        vr: f64,
        vi: f64,
    ) -> (f64, f64) {
        let mag = vr.hypot(vi);
        // The angle nearest the last one (continuous: the traces show it unwrapped).
        let raw = vi.atan2(vr);
        let prev = self.unit.bus()[1];
        let th = raw + ((prev - raw) / std::f64::consts::TAU).round() * std::f64::consts::TAU;
        self.unit.set_terminal_voltage(mag, th);
        self.unit.eval_outputs(t, x);
        let (p, q) = self.pq();
        // I = conj(S / V)
        let d = vr * vr + vi * vi;
        let (sr, si) = ((p * vr + q * vi) / d, (q * vr - p * vi) / d); // S / V
        let (ir, ii) = (sr, -si);
        let ang = self.cs.slip * (t - self.cs.t0);
        let e = self.cs.e0 * Phasor::polar(1.0, ang);
        (
            vr - e.re - (r * ir - xe * ii),
            vi - e.im - (r * ii + xe * ir),
        )
    }

    fn solve_grid(&mut self, t: f64, x: &[f64], r: f64, xe: f64) -> bool {
        let (mut vr, mut vi) = (self.cs.v_re, self.cs.v_im);
        let (mut fr, mut fi) = self.grid_residual(t, x, r, xe, vr, vi);
        let mut fresh = false;
        for _ in 0..CLOSURE_MAX_ITER {
            let norm = fr.hypot(fi);
            if !norm.is_finite() {
                return self.fail_at(t, "the network equation is not finite".into());
            }
            if norm <= CLOSURE_TOL {
                self.cs.v_re = vr;
                self.cs.v_im = vi;
                return true;
            }
            let jinv = match self.cs.jinv {
                Some(j) => j,
                None => {
                    let h = 1e-7;
                    let (ar, ai) = self.grid_residual(t, x, r, xe, vr + h, vi);
                    let (br, bi) = self.grid_residual(t, x, r, xe, vr, vi + h);
                    let (j11, j21) = ((ar - fr) / h, (ai - fi) / h);
                    let (j12, j22) = ((br - fr) / h, (bi - fi) / h);
                    let det = j11 * j22 - j12 * j21;
                    if !(det.is_finite() && det.abs() > 1e-12) {
                        return self.fail_at(t, "the network Jacobian is singular".into());
                    }
                    fresh = true;
                    let j = [j22 / det, -j12 / det, -j21 / det, j11 / det];
                    self.cs.jinv = Some(j);
                    j
                }
            };
            let (nr, ni) = (
                vr - (jinv[0] * fr + jinv[1] * fi),
                vi - (jinv[2] * fr + jinv[3] * fi),
            );
            let (gr, gi) = self.grid_residual(t, x, r, xe, nr, ni);
            let new_norm = gr.hypot(gi);
            if new_norm > 0.5 * norm && !fresh {
                // The chord Jacobian is stale: rebuild it at the current point.
                self.cs.jinv = None;
                continue;
            }
            (vr, vi, fr, fi) = (nr, ni, gr, gi);
        }
        if fr.hypot(fi) <= CLOSURE_STALL_TOL {
            self.cs.v_re = vr;
            self.cs.v_im = vi;
            return true;
        }
        self.fail_at(
            t,
            format!(
                "the terminal voltage has no solution against the grid equivalent (residual \
                 {:.3e} pu): the unit has lost synchronism or its flux collapsed",
                fr.hypot(fi)
            ),
        )
    }
}

impl OdeSystem for ModeSystem<'_> {
    fn dim(&self) -> usize {
        self.unit.n_states()
    }
    fn rhs(&mut self, t: f64, x: &[f64], dx: &mut [f64]) {
        if self.eval_signals(t, x) {
            self.unit.eval_derivatives(t, x, dx);
        } else {
            dx.fill(f64::NAN);
        }
    }
    fn n_events(&self) -> usize {
        self.unit.n_events()
    }
    fn events(&mut self, t: f64, x: &[f64], g: &mut [f64]) {
        if self.eval_signals(t, x) {
            self.unit.eval_events(x, g);
        } else {
            g.fill(1.0);
        }
    }
    fn handle_event(&mut self, t: f64, x: &mut [f64]) -> bool {
        if !self.eval_signals(t, x) {
            return false;
        }
        let changed = self.unit.update_modes(x);
        self.bus_valid = false;
        changed
    }
}

/// The measured inputs of `ev` as the driver of `mu` reads them.
fn inputs<'a>(mu: &ModeUnit, ev: &'a PreparedEvent) -> Inputs<'a> {
    let p_mach_scale = ev.system_mva / mu.unit.machine_mva;
    Inputs {
        t: &ev.input.time_s,
        v: &ev.input.v_mag,
        ang: &ev.input.v_ang,
        p_mach: ev.p_pu.iter().map(|p| p * p_mach_scale).collect(),
        efd: ev.efd_pu.as_deref(),
        ifd: ev.ifd_pu.as_deref(),
    }
}

/// The closure's starting state, from the unit just initialised (its bus at the initial
/// values): the infinite bus of the grid equivalent is placed here.
fn closure_state(mu: &ModeUnit, ev: &PreparedEvent) -> ClosureState {
    let op = mu.op;
    let v0 = Phasor::polar(op.v_mag, op.v_ang);
    let e0 = match mu.closure {
        Closure::Grid { r, x: xe } => {
            // The unit's current at the terminal (after any terminal load).
            let (p, q) = mu.unit.measured_pq_now(mu.ip, mu.iq);
            let i = (Phasor::new(p, q) / v0).conj();
            let zi = Phasor::new(r, xe) * i;
            Phasor::new(v0.re - zi.re, v0.im - zi.im)
        }
        _ => v0,
    };
    ClosureState {
        theta: op.v_ang,
        dpdth: f64::NAN,
        v_re: v0.re,
        v_im: v0.im,
        jinv: None,
        e0,
        slip: 2.0 * std::f64::consts::PI * (ev.op_system.freq_hz - ev.nominal_hz),
        t0: ev.input.time_s[0],
    }
}

fn system<'a>(mu: &'a mut ModeUnit, inp: &'a Inputs<'a>, cs: ClosureState) -> ModeSystem<'a> {
    let n_x = mu.unit.n_states();
    ModeSystem {
        unit: &mut mu.unit,
        inp,
        closure: mu.closure,
        cs,
        ext_efd: mu.ext_efd,
        ext_ifd: mu.ext_ifd,
        ext_step: mu.ext_step,
        level: 0.0,
        ip: mu.ip,
        iq: mu.iq,
        cursor: 0,
        bus_t: f64::NAN,
        bus_x: vec![0.0; n_x],
        bus_valid: false,
        fail: None,
    }
}

/// The playback's right-hand side at its start: `(state names, dx/dt)` of the unit as played
/// back in `mode` at its initial state (the exactness check of every mode's initialisation).
pub fn initial_derivatives(
    unit: &Unit,
    ev: &PreparedEvent,
    mode: PlaybackMode,
) -> Result<(Vec<String>, Vec<f64>), SimError> {
    let mut mu = ModeUnit::new(unit, ev, mode)?;
    let names = mu.unit.state_names();
    let mut x = mu.unit.initialise_with(&mu.op, &mu.preset)?;
    let inp = inputs(&mu, ev);
    let cs = closure_state(&mu, ev);
    let mut sys = system(&mut mu, &inp, cs);
    let t0 = ev.input.time_s[0];
    sys.handle_event(t0, &mut x);
    let mut dx = vec![0.0; x.len()];
    sys.rhs(t0, &x, &mut dx);
    if let Some((t, msg)) = sys.fail.take() {
        return Err(SimError::ModeSolve {
            mode: mode.name(),
            t,
            msg,
        });
    }
    Ok((names, dx))
}

/// Plays `ev` back into a prepared unit; `record(k, unit, x)` is called at every sample `k` with
/// the bus evaluated there (the unit as played back: read signals by name on it).
pub fn run_mode_unit<F, G>(
    mu: &mut ModeUnit,
    ev: &PreparedEvent,
    opts: &SimOptions,
    mut record: F,
) -> Result<Stats, SimError>
where
    F: FnMut(usize, &Unit, &[f64]) -> G,
    G: integrate::GoOn,
{
    let mut x = mu.unit.initialise_with(&mu.op, &mu.preset)?;
    let inp = inputs(mu, ev);
    let cs = closure_state(mu, ev);
    let (steps, mode) = (mu.steps.clone(), mu.mode);
    let mut sys = system(mu, &inp, cs);
    // Knots: every sample and every step instant; segments split at the steps.
    let times = &ev.input.time_s;
    let mut knots: Vec<(f64, Option<usize>)> = times
        .iter()
        .enumerate()
        .map(|(k, &t)| (t, Some(k)))
        .collect();
    for s in &steps {
        if !times.contains(&s.time_s) {
            knots.push((s.time_s, None));
        }
    }
    knots.sort_by(|a, b| a.0.total_cmp(&b.0));
    let kt: Vec<f64> = knots.iter().map(|k| k.0).collect();
    let last = kt.len() - 1;
    let mut bounds = vec![0usize];
    for s in &steps {
        if let Some(j) = kt.iter().position(|&t| t == s.time_s) {
            if j > 0 && !bounds.contains(&j) {
                bounds.push(j);
            }
        }
    }
    if !bounds.contains(&last) {
        bounds.push(last);
    }
    bounds.sort_unstable();
    let mut stats = Stats::default();
    for w in bounds.windows(2) {
        let (a, b) = (w[0], w[1]);
        sys.level = step_level(&steps, kt[a]);
        sys.bus_valid = false;
        let res = integrate::solve(&opts.method, &mut sys, &mut x, &kt[a..=b], |j, t, xx, s| {
            if let Some(k) = knots[a + j].1 {
                if s.eval_signals(t, xx) {
                    return integrate::GoOn::go_on(record(k, s.unit, xx));
                }
            }
            true
        });
        if let Some((t, msg)) = sys.fail.take() {
            return Err(SimError::ModeSolve {
                mode: mode.name(),
                t,
                msg,
            });
        }
        let st = res?;
        stats.steps_accepted += st.steps_accepted;
        stats.steps_rejected += st.steps_rejected;
        stats.rhs_evals += st.rhs_evals;
        stats.events += st.events;
    }
    // A step at the last stamp acts on that sample only (right-continuous).
    let level = step_level(&steps, kt[last]);
    if level != sys.level {
        sys.level = level;
        sys.bus_valid = false;
        if let Some(k) = knots[last].1 {
            if sys.eval_signals(kt[last], &x) && !integrate::GoOn::go_on(record(k, sys.unit, &x)) {
                return Err(SimError::Solve(integrate::SolveError::Stopped {
                    t: kt[last],
                }));
            }
        }
    }
    Ok(stats)
}

/// The channels of [`ModeOutputs`] from the bus of a played-back unit.
struct Reader {
    ip: usize,
    iq: usize,
    iefd: usize,
    iifd: Option<usize>,
    to_sys: f64,
}

impl Reader {
    fn read(&self, k: usize, u: &Unit, out: &mut ModeOutputs) {
        let (p, q) = u.measured_pq_now(self.ip, self.iq);
        let bus = u.bus();
        out.p[k] = p * self.to_sys;
        out.q[k] = q * self.to_sys;
        out.v[k] = bus[0];
        out.efd[k] = bus[self.iefd];
        out.ifd[k] = self.iifd.map_or(f64::NAN, |i| bus[i]);
    }
}

/// Simulates `unit` on `ev` in `mode`: the channels at every sample ([`ModeOutputs`]). A phasor
/// playback without steps is [`crate::simulate::run_playback`]'s, bit for bit.
pub fn simulate_mode(
    unit: &Unit,
    ev: &PreparedEvent,
    mode: PlaybackMode,
    opts: &SimOptions,
) -> Result<ModeOutputs, SimError> {
    simulate_mode_watched(unit, ev, mode, opts, |_, _| true)
        .map(|o| o.expect("a watch that never stops"))
}

/// [`simulate_mode`], showing `watch(k, outputs)` each sample `k` of the channels as soon as it
/// is final (the samples up to `k` are set); a `watch` that returns `false` stops the playback
/// there, and the result is `Ok(None)`. The outputs and the error of a run that is not stopped
/// are [`simulate_mode`]'s, bit for bit.
///
/// Samples are final at once in a phasor playback without set-point steps of a unit that does
/// not transform its recorded P and Q ([`Unit::transforms_pq`]); in every other case `watch`
/// sees each sample after the whole playback (a stop then saves no simulation).
pub fn simulate_mode_watched<W>(
    unit: &Unit,
    ev: &PreparedEvent,
    mode: PlaybackMode,
    opts: &SimOptions,
    mut watch: W,
) -> Result<Option<ModeOutputs>, SimError>
where
    W: FnMut(usize, &ModeOutputs) -> bool,
{
    let (out, seen) = if mode == PlaybackMode::Phasor && ev.steps.is_empty() {
        match phasor_outputs(unit, ev, opts, &mut watch) {
            Err(e) if e.is_stopped() => return Ok(None),
            r => r?,
        }
    } else {
        (mode_unit_outputs(unit, ev, mode, opts)?, false)
    };
    if !seen {
        for k in 0..out.p.len() {
            if !watch(k, &out) {
                return Ok(None);
            }
        }
    }
    Ok(Some(out))
}

/// The phasor playback without steps ([`run_playback`]): the outputs, and whether `watch` saw
/// each sample as it was read (a unit that does not transform its P and Q,
/// [`Unit::transforms_pq`]); otherwise it saw none.
fn phasor_outputs<W>(
    unit: &Unit,
    ev: &PreparedEvent,
    opts: &SimOptions,
    watch: &mut W,
) -> Result<(ModeOutputs, bool), SimError>
where
    W: FnMut(usize, &ModeOutputs) -> bool,
{
    let mut out = ModeOutputs::unset(ev.input.time_s.len());
    let mut u = unit.clone();
    u.ensure_finished()?;
    let (ip, iq) = u.pq_signals()?;
    let (iefd, iifd) = field_signals(&u);
    let r = Reader {
        ip,
        iq,
        iefd: iefd.ok_or_else(|| UnitError::Wiring("no machine reading a field voltage".into()))?,
        iifd,
        to_sys: unit.machine_mva / ev.system_mva,
    };
    let live = !u.transforms_pq();
    out.stats = run_playback(&mut u, ev, opts, |k, u, _| {
        r.read(k, u, &mut out);
        !live || watch(k, &out)
    })?;
    u.transform_pq(&ev.input.time_s, &mut out.p, &mut out.q);
    Ok((out, live))
}

/// Every other playback: the unit as played back in `mode` ([`ModeUnit`], [`run_mode_unit`]).
fn mode_unit_outputs(
    unit: &Unit,
    ev: &PreparedEvent,
    mode: PlaybackMode,
    opts: &SimOptions,
) -> Result<ModeOutputs, SimError> {
    let mut out = ModeOutputs::unset(ev.input.time_s.len());
    let to_sys = unit.machine_mva / ev.system_mva;
    let mut mu = ModeUnit::new(unit, ev, mode)?;
    let r = Reader {
        ip: mu.ip,
        iq: mu.iq,
        iefd: mu.iefd,
        iifd: mu.iifd,
        to_sys,
    };
    out.stats = run_mode_unit(&mut mu, ev, opts, |k, u, _| r.read(k, u, &mut out))?;
    if matches!(mode, PlaybackMode::Phasor | PlaybackMode::ClosedLoop) {
        mu.unit
            .transform_pq(&ev.input.time_s, &mut out.p, &mut out.q);
    }
    Ok(out)
}

/// [`crate::simulate::simulate`] in any mode: the same columns (P and Q simulated and measured,
/// every bus signal of the unit as played back, every state), plus `v_meas_pu` and the measured
/// optional channels. A phasor playback without steps is `simulate`'s.
pub fn simulate_mode_traces(
    unit: &Unit,
    event: &Event,
    mode: PlaybackMode,
    opts: &SimOptions,
) -> Result<Traces, SimError> {
    if mode == PlaybackMode::Phasor && event.steps.is_empty() {
        return crate::simulate::simulate(unit, event, opts);
    }
    simulate_mode_both(unit, event, mode, opts).map(|(traces, _)| traces)
}

/// One playback in `mode` giving both [`simulate_mode_traces`]'s traces and [`simulate_mode`]'s
/// channels, each equal to what its own function gives (the same unit, integrator and steps):
/// for a caller that needs the compared channels and the traces of the same run. A phasor
/// playback without steps runs twice (its traces are `simulate`'s, its channels
/// `run_playback`'s).
pub fn simulate_mode_both(
    unit: &Unit,
    event: &Event,
    mode: PlaybackMode,
    opts: &SimOptions,
) -> Result<(Traces, ModeOutputs), SimError> {
    if mode == PlaybackMode::Phasor && event.steps.is_empty() {
        let traces = crate::simulate::simulate(unit, event, opts)?;
        let outputs = simulate_mode(unit, &PreparedEvent::new(event), mode, opts)?;
        return Ok((traces, outputs));
    }
    let ev = PreparedEvent::new(event);
    let mut mu = ModeUnit::new(unit, &ev, mode)?;
    let n = ev.input.time_s.len();
    let to_sys = unit.machine_mva / ev.system_mva;
    let signals: Vec<String> = mu.unit.signal_names().to_vec();
    let states = mu.unit.state_names();
    let names = crate::simulate::trace_names(&signals, &states);
    let mut cols: Vec<Vec<f64>> = vec![vec![f64::NAN; n]; names.len()];
    let (ip, iq) = (mu.ip, mu.iq);
    let ns = signals.len();
    let reader = Reader {
        ip,
        iq,
        iefd: mu.iefd,
        iifd: mu.iifd,
        to_sys,
    };
    let mut out = ModeOutputs::unset(n);
    let stats = run_mode_unit(&mut mu, &ev, opts, |k, u, x| {
        reader.read(k, u, &mut out);
        let (pk, qk) = u.measured_pq_now(ip, iq);
        cols[0][k] = pk * to_sys;
        cols[1][k] = qk * to_sys;
        cols[4][k] = pk;
        cols[5][k] = qk;
        for (j, v) in u.bus().iter().enumerate() {
            cols[6 + j][k] = *v;
        }
        for (j, v) in x.iter().enumerate() {
            cols[6 + ns + j][k] = *v;
        }
    })?;
    let measuring = matches!(mode, PlaybackMode::Phasor | PlaybackMode::ClosedLoop);
    out.stats = stats;
    if measuring {
        mu.unit
            .transform_pq(&ev.input.time_s, &mut out.p, &mut out.q);
    }
    let traces = crate::simulate::finish_traces(
        &mu.unit,
        event,
        &ev.input.time_s,
        names,
        cols,
        stats,
        measuring,
        true,
    );
    Ok((traces, out))
}
