//! Runs the plausibility layer over every case of a practice set (default ../shared/practice)
//! and prints the findings: a clean record set should give none.
//! `cargo run --release -p itaipu-calib --example plausibility_check -- [ROOT]`

use std::path::PathBuf;

use itaipu_calib::practice::{case_dirs, PracticeCase};
use itaipu_dynamics::plausibility::check_event;

fn main() {
    let root = std::env::args()
        .nth(1)
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from("../shared/practice"));
    let dirs = case_dirs(&root).unwrap_or_else(|e| panic!("{e}"));
    let mut total = 0;
    for d in dirs {
        let case = match PracticeCase::load(&d) {
            Ok(c) => c,
            Err(e) => {
                println!("{}: {e}", d.display());
                continue;
            }
        };
        let f = check_event(&case.event, Some(case.unit.machine_mva));
        total += f.len();
        for x in &f {
            println!("{}: {x}", case.name);
        }
    }
    println!("{total} finding(s)");
}
