//! Model-extension blocks (`models.md` §12): candidate causes of a misfit that the calibrator can
//! fit, each a block wired into a unit by signal names without touching the base models.
//!
//! | block | wiring | what it adds |
//! |---|---|---|
//! | [`two_mass_shaft`] | governor `pm` → shaft → `p_shaft` → machine `pm` | turbine inertia and a torsional mode (§12.1) |
//! | [`speed_deadband`] | machine `speed` → `speed_db` → governor `speed` | intentional governor deadband (§12.2, type 1) |
//! | [`oel`] | machine `xadifd` → OEL → `voel` → exciter | inverse-time over-excitation limiter (§12.4) |
//! | [`sexs_bus_fed`] | replaces the exciter | SEXS whose ceiling follows V_t and X_adI_fd (§12.3) |
//! | [`terminal_load`] | none: drawn between the machine and the PMU | unmodelled station or feeder load |
//! | [`pmu_measurement`] | none: acts on the recorded P, Q | channel skew, VT/CT phase error, ratio errors (§12.5) |
//!
//! Each one starts in exact steady state and, with its "off" parameters (stiff shaft, zero
//! deadband, pickup or ceiling far away), reproduces the base unit.
crate::library! {
    sexs_bus_fed,
    two_mass_shaft,
    pmu_measurement,
    speed_deadband,
    oel,
    terminal_load,
}
