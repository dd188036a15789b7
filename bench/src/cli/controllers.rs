//! `factory-bench controllers`: the cost of one control step for the Franka at N worlds, on the host and
//! on the device (`crate::franka::bench_controllers`).

use super::{print_report, Summary};
use crate::franka::{bench_controllers, ControllerBenchReport};
use anyhow::Result;

#[derive(clap::Args)]
pub struct ControllersArgs {
    /// Parallel worlds.
    #[arg(long, default_value_t = 128)]
    worlds: u32,
    /// Timed repetitions (the median is reported).
    #[arg(long, default_value_t = 50)]
    repeats: u32,
    /// Print one JSON object instead of text.
    #[arg(long)]
    json: bool,
}

/// Times the control step and prints the report.
pub fn run(a: &ControllersArgs) -> Result<()> {
    print_report(&bench_controllers(a.worlds, a.repeats)?, a.json, summary)
}

/// The median times per control step for a person.
pub fn summary(r: &ControllerBenchReport) -> Summary {
    let mut s = Summary::new(format!(
        "controllers: one control step for {} worlds, median of {} repeats [ms]",
        r.worlds, r.repeats
    ));
    s.row("host threads", r.threads).row("host arm batch", format!("{:.4}", r.arm_batch_ms));
    for (name, ms) in &r.controller_ms {
        s.row(format!("host {name}"), format!("{ms:.4}"));
    }
    s.row("device", &r.adapter).row("device dynamics", format!("{:.3}", r.device_dynamics_ms));
    for (name, ms) in &r.device_controller_ms {
        s.row(format!("device {name}"), format!("{ms:.4}"));
    }
    s
}
