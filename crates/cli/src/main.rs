//! `itaipu-calib`: see the library crate for the commands.
fn main() -> std::process::ExitCode {
    std::process::ExitCode::from(itaipu_calib_cli::run(std::env::args_os()))
}
