//! CPU cost of one filter step without an observation model, measured as process CPU time
//! (user + system, all threads) rather than wall time, so that it stays meaningful on a loaded
//! machine. Linux only (reads /proc/self/stat).
//!
//! `RAYON_NUM_THREADS=1 cargo run --release -p actrack-pf --example step_cost [particles] [steps]`

use std::time::Instant;

use actrack_pf::synthetic;
use actrack_pf::{ConstantObservation, Tracker, TrackerConfig};

/// utime + stime of this process in clock ticks (100 Hz on Linux).
fn cpu_ticks() -> Option<u64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // Fields after the parenthesised command name; utime and stime are fields 14 and 15.
    let rest = &stat[stat.rfind(')')? + 2..];
    let f: Vec<&str> = rest.split_whitespace().collect();
    Some(f.get(11)?.parse::<u64>().ok()? + f.get(12)?.parse::<u64>().ok()?)
}

fn main() {
    let mut args = std::env::args().skip(1);
    let particles: usize = args.next().and_then(|s| s.parse().ok()).unwrap_or(400);
    let steps: usize = args.next().and_then(|s| s.parse().ok()).unwrap_or(20_000);
    let Ok((models, names)) = synthetic::demo_models(3, 50) else {
        eprintln!("could not build the synthetic models");
        return;
    };
    let Ok(config) = TrackerConfig::builder(synthetic::table_region())
        .particles(particles)
        .seed(1)
        .build()
    else {
        eprintln!("invalid configuration");
        return;
    };
    let Ok(mut t) = Tracker::new(&models, names, config) else {
        eprintln!("could not build the tracker");
        return;
    };
    let obs = ConstantObservation(0.0);
    for _ in 0..10 {
        t.step(&obs);
    }
    let (Some(c0), w0) = (cpu_ticks(), Instant::now()) else {
        eprintln!("/proc/self/stat unavailable");
        return;
    };
    let mut sink = 0.0;
    for _ in 0..steps {
        sink += t.step(&obs).theta_mean[0];
    }
    let wall = w0.elapsed().as_secs_f64();
    let cpu = cpu_ticks().map_or(f64::NAN, |c1| (c1 - c0) as f64 / 100.0);
    println!(
        "{particles} particles, {steps} steps: CPU {:.1} µs/step, wall {:.1} µs/step (checksum {sink:.3})",
        cpu / steps as f64 * 1e6,
        wall / steps as f64 * 1e6
    );
}
