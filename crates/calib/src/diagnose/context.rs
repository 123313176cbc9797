//! What the operating point, the playback and the evidence tell the causes about a unit on its
//! events ([`Context`]), the part of the unit a cause acts through ([`Acts`]), and the regime
//! thresholds the causes read.

/// What the operating point and the evidence tell the catalog about a unit on an event.
#[derive(Debug, Clone, Default)]
pub struct Context {
    /// Field voltage at the pre-event operating point [pu], if the unit has an exciter.
    pub efd0: Option<f64>,
    /// Field current X_adI_fd at the operating point [pu].
    pub xadifd0: Option<f64>,
    /// PMU reporting rate [samples/s].
    pub rate_hz: f64,
    /// Frequency of the dominant oscillation in the P residual above 1 Hz, if any [Hz].
    pub mode_hint_hz: Option<f64>,
    /// A resonance of the P residual in the shaft band that passes [`resonance_stands_out`]
    /// (the most significant over the events), if any.
    pub shaft_resonance: Option<crate::evidence::SpectralPeak>,
    /// Deepest voltage dip of the events after the onset, as a fraction of the pre-event |V|
    /// (`None`: unknown, e.g. when hiding a cause, and no regime is required).
    pub deepest_dip: Option<f64>,
    /// Largest sustained frequency change of the events (last quarter against pre-event) [Hz].
    pub sustained_df_hz: Option<f64>,
    /// Largest rise of the field current X_adI_fd of the unit as given over its pre-event value,
    /// as a fraction (`None`: unknown).
    pub field_current_rise: Option<f64>,
    /// Largest set-point step the events apply to the voltage regulator, as a fraction
    /// (`None`: no step, or a mode that does not play them). At the summing point a step of
    /// the reference by x drives the AVR as a dip of |V| by x does.
    pub setpoint_step: Option<f64>,
    /// How the events are played back ([`super::playback::Playback`]): a cause whose extension does not
    /// act on what the mode compares is not applicable there ([`Context::not_seen`]).
    pub mode: itaipu_dynamics::mode::PlaybackMode,
    /// The compared channels (empty: the phasor playback's P and Q).
    pub compared: Vec<itaipu_dynamics::event::Channel>,
}

impl Context {
    /// Whether the events drive the AVR by at least `x` (a fraction): a dip of |V| or a
    /// set-point step of that size; `true` when the regime is unknown.
    pub fn drives_avr_by(&self, x: f64) -> bool {
        self.deepest_dip.is_none_or(|d| d >= x) || self.setpoint_step.is_some_and(|s| s >= x)
    }

    /// Whether the diagnosis compares channel `c`.
    pub fn compares(&self, c: itaipu_dynamics::event::Channel) -> bool {
        use itaipu_dynamics::event::Channel;
        if self.compared.is_empty() {
            matches!(c, Channel::P | Channel::Q)
        } else {
            self.compared.contains(&c)
        }
    }
}

/// The part of the unit a cause's extension acts through, for [`Context::not_seen`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Acts {
    /// The exciter (its limits, its limiters).
    Exciter,
    /// The machine's electrical equations (saturation).
    Machine,
    /// A load at the terminal bus, between the machine and the measurement.
    Terminal,
    /// The measuring device's P and Q channels.
    PowerMeasurement,
    /// The turbine and governor, the swing equation.
    Mechanical,
    /// Oscillations of the active power (a shaft's torsional mode, the PSS).
    ActivePower,
    /// Not stated: a cause file declares the blocks its extension adds and rewires, not the
    /// part of the unit it acts through, so no playback rules it out; its re-fit judges it.
    Unstated,
}

/// Largest chance that noise alone gives a resonance, for it to name a torsional mode: one in
/// a million (with the band's windows counted), the "very strong" end of the usual scales.
pub const RESONANCE_P: f64 = 1e-6;
/// Smallest prominence of a resonance over its neighbourhood (see
/// [`crate::evidence::SpectralPeak::prominence`]): twice its neighbours' power. The shoulder
/// of a low-frequency misfit leaking into the band has a prominence near or below 1.
pub const RESONANCE_PROMINENCE: f64 = 2.0;

/// Whether a resonance of the P residual is a mode the model lacks rather than noise or leakage.
pub fn resonance_stands_out(p: &crate::evidence::SpectralPeak) -> bool {
    p.p_value < RESONANCE_P && p.prominence >= RESONANCE_PROMINENCE
}

/// Dip of |V| (a fraction) from which a high-gain AVR is taken to run to its limits: a static
/// AVR's gain of 100-400 pu/pu asks a 5 % dip for 5-20 pu of field voltage, beyond the ceiling
/// of any exciter (a few pu).
pub const LIMIT_DIP: f64 = 0.05;
/// Rise of the field current from which an over-excitation limiter can pick up: a voltage step
/// down that the AVR answers with a sustained field forcing reaches the limiter's pickup
/// (typically 1.05-1.1 × rated, a few percent above a loaded unit's field current) without any
/// dip. Below it, a limiter just above the operating point would only trim a bent AVR gain.
pub const OEL_IFD_RISE: f64 = 0.05;
/// Sustained frequency change from which a governor is taken to act [Hz]: a hydro governor's
/// speed deadband is of this order (0.02-0.04 Hz), below it the gate does not move.
pub const GOVERNOR_DF_HZ: f64 = 0.02;
