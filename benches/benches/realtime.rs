//! The real-time budget: one full tracker frame (edge image of every view + resample +
//! propagate + sample + render + contour + likelihood + estimates) at 100, 400, 1600 and 6400
//! particles, 640×480 and 1280×720, one and three views, raster and analytic contours, on the
//! default rayon pool. Each configuration is also reported against the 33 ms budget of 30
//! frames/s in a table at the end.
//!
//! The frames are a rendered synthetic sequence (built-in motion generator) and the models are
//! trained on generator demonstrations, as in `actrack-cli bench`. Set `ACTRACK_REALTIME_QUICK=1`
//! to time only 400 particles at 640×480.

use std::sync::Mutex;
use std::time::{Duration, Instant};

use actrack::Session;
use actrack::bench::{BenchOptions, Prepared, prepare};
use actrack::config::Contour;
use actrack_render::ImageView;
use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};

const BUDGET_MS: f64 = 1000.0 / 30.0;
const FRAMES: usize = 24;

/// (name, mean ms per frame) of every configuration, for the budget table.
static RESULTS: Mutex<Vec<(String, f64)>> = Mutex::new(Vec::new());

fn realtime(c: &mut Criterion) {
    let quick = std::env::var_os("ACTRACK_REALTIME_QUICK").is_some();
    let sizes: &[(u32, u32)] = if quick {
        &[(640, 480)]
    } else {
        &[(640, 480), (1280, 720)]
    };
    let counts: &[usize] = if quick {
        &[400]
    } else {
        &[100, 400, 1600, 6400]
    };
    let mut group = c.benchmark_group("realtime");
    group
        .sample_size(10)
        .warm_up_time(Duration::from_millis(300))
        .measurement_time(Duration::from_secs(1));
    for &(w, h) in sizes {
        for views in [1usize, 3] {
            let base = BenchOptions {
                width: w,
                height: h,
                views,
                states: 20,
                ..BenchOptions::default()
            };
            let prep: Prepared = prepare(&base, FRAMES).expect("synthetic sequence");
            for contour in [Contour::Analytic, Contour::Raster] {
                for &particles in counts {
                    // The default configuration (what `track` runs) with this M and contour.
                    let mut config = base.config.clone();
                    config.filter.particles = particles;
                    config.observation.contour = contour;
                    let name = format!(
                        "{w}x{h}/{views}view/{}",
                        if contour == Contour::Raster {
                            "raster"
                        } else {
                            "analytic"
                        }
                    );
                    let mut session =
                        Session::new(&prep.model, &prep.scene, &config).expect("session");
                    let mut t = 0usize;
                    let mut total = Duration::ZERO;
                    let mut n = 0u64;
                    group.bench_with_input(
                        BenchmarkId::new(name.clone(), particles),
                        &particles,
                        |b, _| {
                            b.iter_custom(|iters| {
                                let start = Instant::now();
                                for _ in 0..iters {
                                    let frame = &prep.frames[t % prep.frames.len()];
                                    let views: Vec<ImageView<'_>> = frame
                                        .iter()
                                        .map(|i| {
                                            ImageView::rgb8(&i.data, i.width, i.height)
                                                .expect("frame")
                                        })
                                        .collect();
                                    session.step(t, &views).expect("step");
                                    t += 1;
                                }
                                let d = start.elapsed();
                                total += d;
                                n += iters;
                                d
                            });
                        },
                    );
                    if n > 0 {
                        let ms = total.as_secs_f64() * 1e3 / n as f64;
                        if let Ok(mut r) = RESULTS.lock() {
                            r.push((format!("{name}/{particles}"), ms));
                        }
                    }
                }
            }
        }
    }
    group.finish();
    if let Ok(r) = RESULTS.lock() {
        println!(
            "\nreal-time budget at 30 frames/s = {BUDGET_MS:.1} ms per frame ({} threads):",
            rayon::current_num_threads()
        );
        for (name, ms) in r.iter() {
            let verdict = if *ms <= BUDGET_MS { "ok  " } else { "over" };
            println!(
                "  {verdict} {name:<32} {ms:>9.3} ms  {:>6.1} % of budget",
                100.0 * ms / BUDGET_MS
            );
        }
    }
}

criterion_group!(benches, realtime);
criterion_main!(benches);
