//! `two_mass_shaft`: turbine runner (with its entrained water) and an elastic shaft between the
//! governor and the machine (`models.md` §12.1).
//!
//! The machine keeps its own swing equation and becomes the generator mass (its `h` is then
//! H_g, its `d` D_g, its `speed` Δω_g); this block adds the turbine mass and the shaft:
//!
//! ```text
//! T_m = P_m/(1 + Δω_t)                                  (P_m from the governor, port `pm`)
//! T_s = K_s θ_s + D_s (Δω_t − Δω_g)                      (shaft torque, pu on the machine base)
//! 2H_t dΔω_t/dt = T_m − T_s − D_t Δω_t
//! dθ_s/dt = ω_b (Δω_t − Δω_g)                           (θ_s = δ_t − δ_g, electrical rad)
//! p_shaft = T_s (1 + Δω_g)                              (port `p_shaft`, read by the machine as P_m)
//! ```
//!
//! The machine's swing equation `2H_g dΔω_g/dt = (P_m − D_g Δω_g)/(1 + Δω_g) − T_e` with
//! `P_m = p_shaft` then reads `T_s − D_g Δω_g/(1 + Δω_g) − T_e`: the shaft torque, in the PSS/E
//! "power over speed" convention of the machine. (With `swing = "pm_is_torque"` the machine
//! would see `T_s (1 + Δω_g)`; use the default swing with this block.)
//!
//! **Parameters.** `h_turbine` = H_t, `h_generator` = H_g (**must equal `machine.h`**; the block
//! cannot read another block's parameter, and a calibration freeing one must tie the other),
//! the mode frequency `f_torsion_hz` and damping ratio `zeta` instead of K_s and D_s, and the
//! turbine's own damping `d_turbine` = D_t (HYGOV already has `D_turb`: avoid double counting).
//! With `J = 2 H_t H_g/(H_t + H_g)` and `ω_n = 2π f_torsion_hz`, the free-free shaft mode
//! (turbine against generator, electrical torque held) obeys
//!
//! ```text
//! J dΔω_r/dt = −K_s θ_s − D_s Δω_r,  dθ_s/dt = ω_b Δω_r        (Δω_r = Δω_t − Δω_g)
//! ⇒  θ_s'' + (D_s/J) θ_s' + (ω_b K_s/J) θ_s = 0
//! K_s = ω_n² J/ω_b  [pu torque/elec. rad],   D_s = 2 ζ ω_n J  [pu torque/pu speed]
//! ```
//!
//! (`ζ = D_s/(2 sqrt(K_s M))` with `M = J/ω_b` when the damping is written per elec. rad/s,
//! i.e. `D_s/ω_b`.) Connected to a stiff grid through the generator, the observed torsional
//! frequency is slightly higher, by roughly `Δ(ω²) ≈ ω_b K_e H_t/(2 H_g (H_t + H_g))` with K_e
//! the generator's synchronising torque coefficient: a fraction of a per cent for hydro masses.
//!
//! **Initialisation** at Δω0 (the machine fixes `p_shaft0` = its P_m0 and Δω_g0 = Δω0):
//! `Δω_t = Δω0`, `T_s0 = p_shaft0/(1 + Δω0)`, `θ_s0 = T_s0/K_s`, and the power the governor
//! must deliver, `pm0 = (T_s0 + D_t Δω0)(1 + Δω0)`. Every derivative is then zero.
//!
//! Wiring (unit file):
//!
//! ```toml
//! [machine]
//! wiring = { pm = "p_shaft" }
//! [[block]]
//! name = "shaft"
//! model = "two_mass_shaft"
//! h_turbine = 0.4
//! h_generator = 4.1        # = machine.h
//! f_torsion_hz = 6.0
//! zeta = 0.05
//! d_turbine = 0.0
//! ```

use std::f64::consts::PI;

use crate::block::{guard, Block, InitPoint, Io, ModelError, Port, PortInit};
use crate::sens::{Scalar, D};
use crate::{block_common, param_set};
use crate::registry::{ModelInfo, Role};

/// The registry entry ([`crate::registry`]): name, role, `.dyr` record.
pub const MODEL: ModelInfo = ModelInfo {
    name: "two_mass_shaft",
    role: Role::Other,
    summary: "turbine mass and elastic shaft between governor and machine (extension, §12.1)",
    reference: "models.md §12.1",
    make: || Box::new(TwoMassShaft::default()),
    dyr: None,
};

param_set! {
    /// Two-mass shaft parameters (machine base).
    pub struct TwoMassShaftParams {
        h_turbine: ("Ht", "s", 0.4, (0.1, 1.5), "inertia of the turbine runner and its entrained water H_t"),
        h_generator: ("Hg", "s", 4.1, (2.0, 8.0), "generator inertia H_g (must equal machine.h)"),
        f_torsion_hz: ("ftor", "Hz", 6.0, (2.0, 20.0), "free-free torsional mode frequency (sets K_s)"),
        zeta: ("zeta", "-", 0.05, (0.0005, 0.5), "damping ratio of the torsional mode (sets D_s); a bare shaft mode is lightly damped, 0.001-0.01"),
        d_turbine: ("Dt", "pu", 0.0, (0.0, 1.0), "turbine damping D_t [pu torque / pu speed]"),
    }
}

mod port {
    pub const PM: usize = 0;
    pub const SPEED: usize = 1;
    pub const P_SHAFT: usize = 2;
    pub const SPEED_TURBINE: usize = 3;
}

const PORTS: &[Port] = &[
    Port::input(
        "pm",
        PortInit::Gives,
        "turbine mechanical power P_m from the governor [pu machine base]",
    ),
    Port::input_ft(
        "speed",
        PortInit::Needs,
        "generator speed deviation Δω_g [pu]",
    ),
    Port::output(
        "p_shaft",
        PortInit::Needs,
        "power delivered to the generator rotor T_s (1 + Δω_g) [pu]",
    ),
    Port::output(
        "speed_turbine",
        PortInit::Gives,
        "turbine speed deviation Δω_t [pu]",
    ),
];

/// Two-mass shaft block.
#[derive(Debug, Clone)]
pub struct TwoMassShaft {
    pub p: TwoMassShaftParams,
    omega_b: f64,
    /// K_s, D_s, 1/(2H_t) (refreshed at initialisation).
    k_s: f64,
    d_s: f64,
    inv_2ht: f64,
    /// The parameters and `[K_s, D_s, 1/(2H_t)]` on dual numbers, after [`Block::seed_dual`].
    dual: Option<(TwoMassShaftParams<D>, [D; 3])>,
}

/// `(K_s, D_s)` from the parameters and the nominal frequency `ω_b`.
fn stiffness_damping<S: Scalar>(p: &TwoMassShaftParams<S>, omega_b: f64) -> (S, S) {
    let j = p.h_turbine * 2.0 * p.h_generator / (p.h_turbine + p.h_generator);
    let w_n = p.f_torsion_hz * (2.0 * PI);
    (w_n * w_n * j / omega_b, p.zeta * 2.0 * w_n * j)
}

#[inline(always)]
fn outputs<S: Scalar>([k_s, d_s, _]: [S; 3], x: &[S], io: &mut Io<S>) {
    let w_g = io.get(port::SPEED);
    let t_s = k_s * x[1] + d_s * (x[0] - w_g);
    io.set(port::P_SHAFT, t_s * (w_g + 1.0));
    io.set(port::SPEED_TURBINE, x[0]);
}

#[inline(always)]
fn derivatives<S: Scalar>(
    p: &TwoMassShaftParams<S>,
    [k_s, d_s, inv_2ht]: [S; 3],
    omega_b: f64,
    x: &[S],
    io: &Io<S>,
    dx: &mut [S],
) {
    let w_g = io.get(port::SPEED);
    let t_m = io.get(port::PM) / (x[0] + 1.0);
    let t_s = k_s * x[1] + d_s * (x[0] - w_g);
    dx[0] = (t_m - t_s - p.d_turbine * x[0]) * inv_2ht;
    dx[1] = (x[0] - w_g) * omega_b;
}

impl Default for TwoMassShaft {
    fn default() -> Self {
        Self {
            p: TwoMassShaftParams::default(),
            omega_b: 2.0 * PI * 60.0,
            k_s: 0.0,
            d_s: 0.0,
            inv_2ht: 0.0,
            dual: None,
        }
    }
}

impl TwoMassShaft {
    /// `(K_s, D_s)` from the parameters and the nominal frequency.
    pub fn stiffness_damping(&self) -> (f64, f64) {
        stiffness_damping(&self.p, self.omega_b)
    }
}

impl Block for TwoMassShaft {
    block_common!();

    fn model(&self) -> &'static str {
        "two_mass_shaft"
    }
    fn ports(&self) -> &'static [Port] {
        PORTS
    }
    fn state_names(&self) -> &'static [&'static str] {
        &["speed_t", "theta_s"]
    }
    fn validate(&self) -> Result<(), ModelError> {
        let p = &self.p;
        guard::positive("h_turbine", p.h_turbine)?;
        guard::positive("h_generator", p.h_generator)?;
        guard::positive("f_torsion_hz", p.f_torsion_hz)?;
        guard::non_negative("zeta", p.zeta)?;
        guard::non_negative("d_turbine", p.d_turbine)
    }

    fn init(&mut self, _op: &InitPoint, x: &mut [f64], io: &mut Io) -> Result<(), ModelError> {
        self.validate()?;
        let (k_s, d_s) = self.stiffness_damping();
        self.k_s = k_s;
        self.d_s = d_s;
        self.inv_2ht = 1.0 / (2.0 * self.p.h_turbine);
        let w0 = io.get(port::SPEED);
        let ts0 = io.get(port::P_SHAFT) / (1.0 + w0);
        x[0] = w0;
        x[1] = ts0 / k_s;
        io.set(port::PM, (ts0 + self.p.d_turbine * w0) * (1.0 + w0));
        io.set(port::SPEED_TURBINE, w0);
        if x.iter().any(|v| !v.is_finite()) {
            return Err(ModelError::Init(
                "two_mass_shaft: initial state is not finite".into(),
            ));
        }
        Ok(())
    }

    #[inline]
    fn outputs(&self, _t: f64, x: &[f64], io: &mut Io) {
        outputs([self.k_s, self.d_s, self.inv_2ht], x, io);
    }

    #[inline]
    fn derivatives(&self, _t: f64, x: &[f64], io: &Io, dx: &mut [f64]) {
        let c = [self.k_s, self.d_s, self.inv_2ht];
        derivatives(&self.p, c, self.omega_b, x, io, dx);
    }

    fn seed_dual(&mut self, lanes: &[Option<usize>], _consts: &[D]) -> bool {
        let p = self.p.lift_dual(lanes);
        let (k_s, d_s) = stiffness_damping(&p, self.omega_b);
        let inv_2ht = (p.h_turbine * 2.0).recip();
        self.dual = Some((p, [k_s, d_s, inv_2ht]));
        true
    }

    fn outputs_dual(&self, _t: f64, x: &[D], io: &mut Io<D>) {
        if let Some((_, c)) = &self.dual {
            outputs(*c, x, io);
        }
    }

    fn derivatives_dual(&self, _t: f64, x: &[D], io: &Io<D>, dx: &mut [D]) {
        if let Some((p, c)) = &self.dual {
            derivatives(p, *c, self.omega_b, x, io, dx);
        }
    }

    fn set_nominal_frequency(&mut self, hz: f64) {
        self.omega_b = 2.0 * PI * hz;
    }
}
