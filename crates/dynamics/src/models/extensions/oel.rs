//! `oel`: generic inverse-time over-excitation limiter, summing-point type (`models.md` §12.4).
//!
//! Reads the field current `xadifd` (X_adI_fd, from the machine) and writes `voel` (≤ 0), which
//! SEXS adds to its voltage error (its `voel` port is wired to the signal `voel` by default).
//!
//! ```text
//! I = X_adI_fd / I_fd,rated                                  (pu of rated field current)
//! heating (I > I_pu):   dA/dt = I² − I_pu²
//! cooling (I ≤ I_pu):   dA/dt = −K_cool A                    (A ≥ 0: I²t accumulator [pu²·s])
//! inactive:             V_OEL = 0,  dV_OEL/dt = 0
//! active:               dV_OEL/dt = K_i (I_lim − I),  non-windup in [V_OEL,min, 0]
//! activation:           A ≥ A_max while heating               (I²t capacity exhausted)
//! release:              V_OEL back at 0 and still rising (I < I_lim: the AVR asks for less)
//! ```
//!
//! `A_max ≈ (I_2² − I_pu²) t_2` for a point (I_2, t_2) of the field's short-time capability curve
//! (e.g. 1.2 × rated for 20 s with I_pu = 1.05: A_max ≈ 6.7 pu²·s). While active the integrator
//! drives I to I_lim (≤ I_pu, so the accumulator cools meanwhile); when the voltage recovers and
//! I falls below I_lim, V_OEL ramps back to 0 at the same rate K_i (I_lim − I) and the limiter
//! releases there, with the thermal memory A kept (a new overload after a short pause trips it
//! sooner).
//!
//! **Tuning.** The loop gain is about `K_i·K_AVR/I_fd,rated` (through the AVR's DC gain and the
//! field's T'_d): with SEXS K = 100 and I_fd,rated ≈ 1.5, K_i ≈ 0.002–0.005 keeps it near 0.1/s;
//! ten times more makes the loop oscillate (the AVR's ceiling and lead-lag wind up while the
//! limiter integrates). The release is as slow as the approach: V_OEL returns to 0 at
//! K_i·(I_lim − I), so a unit whose voltage recovers can run under-excited for a while.
//!
//! **Discrete logic.** Three switches, all as discrete modes located by the integrator (event
//! functions positive while the mode holds), so that the right-hand side is smooth within every
//! step:
//!
//! * heating/cooling: `g0 = I − I_pu` (heating) or `I_pu − I` (cooling);
//! * inactive → active: `g1 = max(A_max − A, I_pu − I)`;
//! * active: the two non-windup guards of [`NonWindup`] on V_OEL in [V_OEL,min, 0]; reaching the
//!   upper limit 0 while pushing upwards is the release.
//!
//! **Initialisation.** Requires `I0 ≤ I_pu` (a unit already above pickup is not in steady state:
//! an init error). Then `A = 0`, `V_OEL = 0`, inactive, cooling: every derivative is exactly
//! zero and the output is 0, so the OEL is inert until the field current exceeds the pickup for
//! long enough.

use crate::block::{guard, Block, InitPoint, Io, ModelError, Port, PortInit};
use crate::models::limiter::{LimitMode, NonWindup};
use crate::sens::{Scalar, D};
use crate::{block_common, param_set};
use crate::registry::{ModelInfo, Role};

/// The registry entry ([`crate::registry`]): name, role, `.dyr` record.
pub const MODEL: ModelInfo = ModelInfo {
    name: "oel",
    role: Role::Other,
    summary: "inverse-time over-excitation limiter, summing-point type (extension, §12.4)",
    reference: "models.md §12.4",
    make: || Box::new(Oel::default()),
    dyr: None,
};

param_set! {
    /// Over-excitation limiter parameters.
    pub struct OelParams {
        ifd_rated: ("IFDRATED", "pu", 2.5, (1.5, 4.0), "rated field current, as X_adI_fd"),
        i_pickup: ("IPU", "pu", 1.05, (1.01, 1.6), "pickup current, pu of rated"),
        i_limit: ("ILIM", "pu", 1.0, (0.95, 1.1), "current the limiter regulates to when active, pu of rated (<= i_pickup)"),
        a_max: ("AMAX", "pu2s", 6.7, (0.02, 30.0), "I²t capacity A_max ≈ (I_2² − I_pu²) t_2"),
        k_cool: ("KCOOL", "1/s", 0.05, (0.0, 0.2), "cooling rate of the accumulator below pickup"),
        k_i: ("KI", "pu/s", 0.005, (0.002, 0.2), "integral gain of the limiter [pu V_OEL per pu current per s]"),
        voel_min: ("VOELMIN", "pu", -0.2, (-0.5, -0.02), "lower limit of the limiter output"),
    }
}

mod port {
    pub const XADIFD: usize = 0;
    pub const VOEL: usize = 1;
}

const PORTS: &[Port] = &[
    Port::input("xadifd", PortInit::Needs, "field current X_ad I_fd [pu]"),
    Port::output(
        "voel",
        PortInit::Gives,
        "limiter output V_OEL (<= 0), added to the AVR error [pu]",
    ),
];

/// Over-excitation limiter block.
#[derive(Debug, Clone, Default)]
pub struct Oel {
    pub p: OelParams,
    heating: bool,
    active: bool,
    limit: NonWindup,
    /// The parameters on dual numbers, after [`Block::seed_dual`].
    dual: Option<OelParams<D>>,
}

impl Oel {
    /// Field current in pu of rated.
    #[inline(always)]
    fn current(&self, io: &Io) -> f64 {
        io.get(port::XADIFD) / self.p.ifd_rated
    }

    /// Unconstrained dV_OEL/dt while active.
    #[inline(always)]
    fn integrator_rate(&self, i: f64) -> f64 {
        rate(&self.p, i)
    }

    /// `dA/dt` and `dV_OEL/dt` in the current modes, at field current `i` [pu of rated].
    #[inline(always)]
    fn rates<S: Scalar>(&self, p: &OelParams<S>, x: &[S], i: S) -> (S, S) {
        let da = if self.heating {
            i * i - p.i_pickup * p.i_pickup
        } else {
            -p.k_cool * x[0]
        };
        let dv = if self.active {
            self.limit.derivative(rate(p, i))
        } else {
            S::cst(0.0)
        };
        (da, dv)
    }

    /// The three guards in the current modes (see the module documentation).
    #[inline]
    fn guards<S: Scalar>(&self, p: &OelParams<S>, x: &[S], i: S, g: &mut [S]) {
        g[0] = if self.heating {
            i - p.i_pickup
        } else {
            p.i_pickup - i
        };
        if self.active {
            self.limit
                .events(x[1], rate(p, i), p.voel_min, S::cst(0.0), &mut g[1..3]);
        } else {
            g[1] = (p.a_max - x[0]).max_s(p.i_pickup - i);
            g[2] = S::cst(1.0);
        }
    }

    /// Whether the limiter is active (for tests and traces).
    pub fn is_active(&self) -> bool {
        self.active
    }
}

impl Block for Oel {
    block_common!();

    fn model(&self) -> &'static str {
        "oel"
    }
    fn ports(&self) -> &'static [Port] {
        PORTS
    }
    fn state_names(&self) -> &'static [&'static str] {
        &["a", "v_oel"]
    }
    fn validate(&self) -> Result<(), ModelError> {
        let p = &self.p;
        guard::positive("ifd_rated", p.ifd_rated)?;
        guard::positive("i_pickup", p.i_pickup)?;
        guard::positive("i_limit", p.i_limit)?;
        guard::greater_eq("i_pickup", p.i_pickup, "i_limit", p.i_limit)?;
        guard::positive("a_max", p.a_max)?;
        guard::non_negative("k_cool", p.k_cool)?;
        guard::positive("k_i", p.k_i)?;
        guard::greater("0", 0.0, "voel_min", p.voel_min)
            .map_err(|_| ModelError::param("voel_min", format!("must be < 0 (got {})", p.voel_min)))
    }

    fn init(&mut self, _op: &InitPoint, x: &mut [f64], io: &mut Io) -> Result<(), ModelError> {
        self.validate()?;
        let i0 = self.current(io);
        if !(i0 <= self.p.i_pickup) {
            return Err(ModelError::Init(format!(
                "oel: initial field current {i0:.4} pu of rated (X_adI_fd0 = {:.4}) is above the pickup I_PU = {}: the limiter would not start in steady state",
                io.get(port::XADIFD),
                self.p.i_pickup
            )));
        }
        x[0] = 0.0;
        x[1] = 0.0;
        self.heating = false;
        self.active = false;
        self.limit = NonWindup::default();
        io.set(port::VOEL, 0.0);
        Ok(())
    }

    #[inline]
    fn outputs(&self, _t: f64, x: &[f64], io: &mut Io) {
        io.set(port::VOEL, x[1].clamp(self.p.voel_min, 0.0));
    }

    #[inline]
    fn derivatives(&self, _t: f64, x: &[f64], io: &Io, dx: &mut [f64]) {
        (dx[0], dx[1]) = self.rates(&self.p, x, self.current(io));
    }

    fn seed_dual(&mut self, lanes: &[Option<usize>], _consts: &[D]) -> bool {
        self.dual = Some(self.p.lift_dual(lanes));
        true
    }

    fn outputs_dual(&self, _t: f64, x: &[D], io: &mut Io<D>) {
        if let Some(p) = &self.dual {
            io.set(port::VOEL, self.limit.output(x[1], p.voel_min, D::cst(0.0)));
        }
    }

    fn derivatives_dual(&self, _t: f64, x: &[D], io: &Io<D>, dx: &mut [D]) {
        if let Some(p) = &self.dual {
            (dx[0], dx[1]) = self.rates(p, x, io.get(port::XADIFD) / p.ifd_rated);
        }
    }

    /// V_OEL pinned at a limit takes its derivatives; inactive, it is 0 whatever the
    /// parameters (the release's reset).
    fn pin_dual(&self, x: &mut [D], _io: &Io<D>) {
        if let Some(p) = &self.dual {
            if self.active {
                self.limit.pin(&mut x[1], p.voel_min, D::cst(0.0));
            } else {
                x[1] = D::cst(0.0);
            }
        }
    }

    fn events_dual(&self, x: &[D], io: &Io<D>, g: &mut [D]) -> bool {
        match &self.dual {
            Some(p) => {
                self.guards(p, x, io.get(port::XADIFD) / p.ifd_rated, g);
                true
            }
            None => false,
        }
    }

    fn n_events(&self) -> usize {
        3
    }
    fn events(&self, x: &[f64], io: &Io, g: &mut [f64]) {
        self.guards(&self.p, x, self.current(io), g);
    }
    fn update_modes(&mut self, x: &mut [f64], io: &Io) -> bool {
        let p = self.p.clone();
        let i = self.current(io);
        let old = (self.heating, self.active, self.limit, x[0], x[1]);
        // Switch where the current mode's guard is ≤ 0, as the integrator located it: the
        // located crossing may sit exactly on I = I_pu, and a cooling mode kept there would
        // leave its guard at 0, whose later fall below 0 the driver cannot see (a guard must
        // go from > 0 to ≤ 0): the overload would never heat the accumulator.
        self.heating = if self.heating {
            i > p.i_pickup
        } else {
            i >= p.i_pickup
        };
        // The crossing is located to ~1e-12 s: accept an accumulator a hair short of A_max.
        if !self.active && self.heating && x[0] >= p.a_max * (1.0 - 1e-9) {
            self.active = true;
            self.limit = NonWindup::default();
        }
        if self.active {
            self.limit
                .update(&mut x[1], self.integrator_rate(i), p.voel_min, 0.0);
            if self.limit.mode == LimitMode::AtMax {
                // Wound back to 0 and still rising: release.
                self.active = false;
                self.limit = NonWindup::default();
                x[1] = 0.0;
            }
        }
        old != (self.heating, self.active, self.limit, x[0], x[1])
    }
}

/// The limiter's unconstrained integrator rate `K_i (I_lim − I)`.
#[inline(always)]
fn rate<S: Scalar>(p: &OelParams<S>, i: S) -> S {
    p.k_i * (p.i_limit - i)
}
