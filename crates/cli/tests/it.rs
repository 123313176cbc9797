//! The integration tests of `itaipu-calib-cli`, one binary: each file beside this one is a
//! module.

mod crash;
mod docs;
mod first_hour;
mod interrupt;
mod table1;
