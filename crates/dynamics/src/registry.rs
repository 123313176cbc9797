//! The catalogue of block models by name, as written in unit files (`model = "GENSAE"`).

use crate::block::Block;
use crate::models::exciter::{esst1a::Esst1a, ieeet1::Ieeet1, sexs::Sexs, st5b::St5b};
use crate::models::extensions::{
    oel::Oel, pmu_measurement::PmuMeasurement, sexs_bus_fed::SexsBusFed,
    speed_deadband::SpeedDeadband, terminal_load::TerminalLoad, two_mass_shaft::TwoMassShaft,
};
use crate::models::governor::{constant_pm::ConstantPm, hygov::Hygov};
use crate::models::grid::GridEquivalent;
use crate::models::machine::{
    gencls::Gencls, genrou::Genrou, gensae::Gensae, gensal::Gensal, Machine,
};
use crate::models::pss::{ieeest::Ieeest, stab3::Stab3};

/// What a model is for; the unit file section it normally goes in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Role {
    Machine,
    Exciter,
    Pss,
    Governor,
    Other,
}

impl Role {
    pub fn section(self) -> &'static str {
        match self {
            Role::Machine => "machine",
            Role::Exciter => "exciter",
            Role::Pss => "pss",
            Role::Governor => "governor",
            Role::Other => "block",
        }
    }
}

/// One catalogue entry.
pub struct ModelInfo {
    pub name: &'static str,
    pub role: Role,
    pub summary: &'static str,
    make: fn() -> Box<dyn Block>,
}

impl ModelInfo {
    /// A new block with typical parameter values.
    pub fn create(&self) -> Box<dyn Block> {
        (self.make)()
    }
}

/// All models.
pub static MODELS: &[ModelInfo] = &[
    ModelInfo {
        name: "GENSAE",
        role: Role::Machine,
        summary: "salient-pole machine, exponential saturation on |ψ''| (both axes)",
        make: || Box::new(Machine::new(Gensae::default())),
    },
    ModelInfo {
        name: "GENSAL",
        role: Role::Machine,
        summary: "salient-pole machine, quadratic saturation on E'q (d-axis)",
        make: || Box::new(Machine::new(Gensal::default())),
    },
    ModelInfo {
        name: "GENROU",
        role: Role::Machine,
        summary: "round-rotor machine, quadratic saturation on |ψ''|",
        make: || Box::new(Machine::new(Genrou::default())),
    },
    ModelInfo {
        name: "GENCLS",
        role: Role::Machine,
        summary: "classical machine, constant E' behind X'd",
        make: || Box::new(Machine::new(Gencls::default())),
    },
    ModelInfo { name: "SEXS", role: Role::Exciter, summary: "simplified excitation system", make: || Box::new(Sexs::default()) },
    ModelInfo {
        name: "SEXS_bus_fed",
        role: Role::Exciter,
        summary: "SEXS with a bus-fed ceiling V_t·VRMAX − KC·X_adI_fd (extension, models.md §12.3)",
        make: || Box::new(SexsBusFed::default()),
    },
    ModelInfo {
        name: "ST5B",
        role: Role::Exciter,
        summary: "IEEE 421.5-2005 ST5B static exciter: bus-fed bridge, K_C commutation drop, UEL/OEL gates",
        make: || Box::new(St5b::default()),
    },
    ModelInfo {
        name: "IEEET1",
        role: Role::Exciter,
        summary: "IEEE type 1 DC exciter with rate feedback and quadratic saturation",
        make: || Box::new(Ieeet1::default()),
    },
    ModelInfo {
        name: "ESST1A",
        role: Role::Exciter,
        summary: "IEEE 421.5-2005 ST1A static exciter: bus-fed ceiling with K_C, field current limiter, UEL/VOS input codes",
        make: || Box::new(Esst1a::default()),
    },
    ModelInfo { name: "STAB3", role: Role::Pss, summary: "power-input stabiliser (PSS/E STAB3)", make: || Box::new(Stab3::default()) },
    ModelInfo { name: "IEEEST", role: Role::Pss, summary: "IEEE 1981 stabiliser", make: || Box::new(Ieeest::default()) },
    ModelInfo { name: "HYGOV", role: Role::Governor, summary: "hydro turbine-governor", make: || Box::new(Hygov::default()) },
    ModelInfo {
        name: "constant_pm",
        role: Role::Governor,
        summary: "constant mechanical power (no governor action)",
        make: || Box::new(ConstantPm::default()),
    },
    ModelInfo {
        name: "two_mass_shaft",
        role: Role::Other,
        summary: "turbine mass and elastic shaft between governor and machine (extension, §12.1)",
        make: || Box::new(TwoMassShaft::default()),
    },
    ModelInfo {
        name: "pmu_measurement",
        role: Role::Other,
        summary: "PMU effects on the recorded P and Q: channel skew, VT/CT phase error, ratio errors",
        make: || Box::new(PmuMeasurement::default()),
    },
    ModelInfo {
        name: "speed_deadband",
        role: Role::Other,
        summary: "intentional governor speed deadband, no-jump type (extension, §12.2)",
        make: || Box::new(SpeedDeadband::default()),
    },
    ModelInfo {
        name: "oel",
        role: Role::Other,
        summary: "inverse-time over-excitation limiter, summing-point type (extension, §12.4)",
        make: || Box::new(Oel::default()),
    },
    ModelInfo {
        name: "terminal_load",
        role: Role::Other,
        summary: "static voltage-dependent load between the machine and the measurement point (extension)",
        make: || Box::new(TerminalLoad::default()),
    },
    ModelInfo {
        name: "grid_equivalent",
        role: Role::Other,
        summary: "network seen from the terminal: Z_e = R_e + jX_e to an infinite bus (closed_loop playback only)",
        make: || Box::new(GridEquivalent::default()),
    },
];

/// Looks a model up by name (case-insensitive).
pub fn find(name: &str) -> Option<&'static ModelInfo> {
    MODELS.iter().find(|m| m.name.eq_ignore_ascii_case(name))
}

/// Names of all models, for error messages.
pub fn names() -> String {
    MODELS.iter().map(|m| m.name).collect::<Vec<_>>().join(", ")
}

/// What `models NAME` shows: a model of the library, or the diagram primitives
/// (`NAME = "diagram"`, any case).
pub enum Listing {
    Model(&'static ModelInfo),
    DiagramPrimitives,
}

/// The listing of `models NAME` (the command line's and Python's `models(name)`), or the
/// message naming every name it takes.
pub fn listing(name: &str) -> Result<Listing, String> {
    if name.eq_ignore_ascii_case("diagram") {
        return Ok(Listing::DiagramPrimitives);
    }
    find(name)
        .map(Listing::Model)
        .ok_or_else(|| format!("unknown model '{name}' (known: {}, diagram)", names()))
}
