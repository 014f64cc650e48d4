//! A configuration in words, for the pages the experiments write (docs/results.md's
//! "Configurations"): generated from the [`TrackConfig`] itself, so that the page says what the
//! preset holds, not what it held when the page was last edited by hand.

use actrack::TrackConfig;
use actrack::config::{Contour, EdgeRegion, FloorSetting, Gradient, Median, ThetaPrior};

/// The video a configuration tracks, for the settings whose effect depends on it.
#[derive(Clone, Copy, Debug)]
pub struct Video {
    /// Frames per second (the centred median's latency in seconds).
    pub fps: f64,
    /// Frame width in pixels (whether `observation.max_width` shrinks the frames).
    pub width: u32,
}

/// The settings of `c` that shape a track, as an English list without a final full stop
/// ("3200 particles with analytic contours, …, and the pose reported as …"). Extensions that
/// are switched off are not named; the core choices (particles, contour, gradient, error,
/// dwell, resampling, θ prior, median) always are.
pub fn describe(c: &TrackConfig, video: Video) -> String {
    let (f, p, o) = (&c.filter, &c.prior, &c.observation);
    let mut items = Vec::new();
    items.push(format!(
        "{} particles with {} contours",
        f.particles,
        match o.contour {
            Contour::Analytic => "analytic",
            Contour::Raster => "raster",
        }
    ));
    items.push(
        match o.gradient {
            Gradient::Colour => "edge maps from the colour gradient",
            Gradient::Grey => "edge maps from the grey gradient",
        }
        .to_owned(),
    );
    if o.local_norm.enabled {
        items.push(format!(
            "the edge map divided by its local maximum over {} px windows (floor {})",
            2 * o.local_norm.radius + 1,
            num(f64::from(o.local_norm.floor))
        ));
    }
    items.push(
        if o.short_contour_penalty.enabled {
            "the short-contour penalty"
        } else {
            "SPEC's ε̄"
        }
        .to_owned(),
    );
    if o.foreground_gate.enabled {
        items.push(format!(
            "a causal foreground gate dilated by {} px",
            o.foreground_gate.radius
        ));
    }
    if o.edge_region == EdgeRegion::Particles {
        items.push("edge maps computed only where the particles' arms project".to_owned());
    }
    if o.max_width > 0 {
        let shrink = video.width.div_ceil(o.max_width);
        items.push(if shrink <= 1 {
            format!(
                "frames wider than {} px shrunk to fit (these videos are {} px wide)",
                o.max_width, video.width
            )
        } else {
            format!(
                "frames wider than {} px shrunk to fit (these {} px videos by {shrink})",
                o.max_width, video.width
            )
        });
    }
    match c.actor.fingertip_floor {
        FloorSetting::Off => {}
        FloorSetting::Table => items.push("the fingertip floor on the scene's table".to_owned()),
        FloorSetting::Height(z) => {
            items.push(format!("a fingertip floor {} m from the shoulder", num(z)));
        }
    }
    items.push(if f.max_stay < 1.0 {
        format!(
            "a cap of {} on the models' dwell{}",
            num(f.max_stay),
            if f.keep_last_dwell {
                " (last state kept)"
            } else {
                ""
            }
        )
    } else {
        "the models' own dwell times".to_owned()
    });
    if let [lo, hi] = f.speed_range[..] {
        items.push(format!(
            "particle speeds of {}–{} model transitions per frame",
            num(lo),
            num(hi)
        ));
    }
    items.push(if f.action_floor > 0.0 {
        format!(
            "{} % of the particles split evenly over the actions",
            num(100.0 * f.action_floor)
        )
    } else {
        "joint resampling".to_owned()
    });
    if f.action_switch > 0.0 {
        items.push(format!(
            "an action switch of {} per frame",
            num(f.action_switch)
        ));
    }
    items.push(
        match p.theta {
            ThetaPrior::Training => "each action's θ prior its training targets",
            ThetaPrior::Scene => "one θ region for every action",
        }
        .to_owned(),
    );
    if (p.height_scale - 1.0).abs() > 1e-12 {
        items.push(format!(
            "the models' heights scaled by {}",
            num(p.height_scale)
        ));
    }
    let w = c.output.median_window;
    items.push(match c.output.median {
        Median::Causal => format!("the pose reported as the causal {w}-frame median"),
        Median::Centred => {
            let h = w / 2;
            format!(
                "the pose reported as the centred {w}-frame median ({h} frames, {} s, of latency)",
                num(h as f64 / video.fps)
            )
        }
    });
    list(&items)
}

/// `a`, `a and b`, `a, b, and c`.
fn list(items: &[String]) -> String {
    match items {
        [] => String::new(),
        [one] => one.clone(),
        [a, b] => format!("{a} and {b}"),
        [init @ .., last] => format!("{}, and {last}", init.join(", ")),
    }
}

/// A number with at most three decimals and no trailing zeros (0.8, 90, 0.05).
fn num(x: f64) -> String {
    let s = format!("{x:.3}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s == "-0" {
        "0".to_owned()
    } else {
        s.to_owned()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const VIDEO: Video = Video {
        fps: 30.0,
        width: 640,
    };

    #[test]
    fn default_preset_in_words() {
        let c = TrackConfig::preset("default").unwrap();
        assert_eq!(
            describe(&c, VIDEO),
            "3200 particles with analytic contours, edge maps from the colour gradient, the \
             short-contour penalty, a causal foreground gate dilated by 2 px, edge maps \
             computed only where the particles' arms project, frames wider than 640 px shrunk \
             to fit (these videos are 640 px wide), the fingertip floor on the \
             scene's table, a cap of 0.8 on the models' dwell (last state kept), 90 % of the \
             particles split evenly over the actions, each action's θ prior its training \
             targets, and the pose reported as the centred 7-frame median (3 frames, 0.1 s, of \
             latency)"
        );
    }

    #[test]
    fn paper_preset_in_words() {
        let c = TrackConfig::preset("paper").unwrap();
        assert_eq!(
            describe(&c, VIDEO),
            "400 particles with raster contours, edge maps from the grey gradient, SPEC's ε̄, \
             the models' own dwell times, joint resampling, one θ region for every action, and \
             the pose reported as the causal 5-frame median"
        );
    }

    #[test]
    fn every_setting_that_is_on_is_named() {
        let mut c = TrackConfig::default();
        c.observation.local_norm.enabled = true;
        c.observation.max_width = 320;
        c.actor.fingertip_floor = FloorSetting::Height(-0.25);
        c.filter.keep_last_dwell = false;
        c.filter.speed_range = vec![0.5, 2.0];
        c.filter.action_switch = 0.01;
        c.prior.height_scale = 1.1;
        let s = describe(&c, VIDEO);
        for want in [
            "over 49 px windows (floor 0.1)",
            "(these 640 px videos by 2)",
            "a fingertip floor -0.25 m from the shoulder",
            "a cap of 0.8 on the models' dwell, ",
            "particle speeds of 0.5–2 model transitions per frame",
            "an action switch of 0.01 per frame",
            "the models' heights scaled by 1.1",
        ] {
            assert!(s.contains(want), "`{want}` not in: {s}");
        }
        c.actor.fingertip_floor = FloorSetting::Off;
        c.observation.foreground_gate.enabled = false;
        c.observation.max_width = 0;
        let s = describe(&c, VIDEO);
        for gone in ["floor on", "gate", "shrunk"] {
            assert!(!s.contains(gone), "`{gone}` in: {s}");
        }
    }

    #[test]
    fn lists_and_numbers() {
        let v = |s: &[&str]| s.iter().map(|&x| x.to_owned()).collect::<Vec<_>>();
        assert_eq!(list(&v(&["a"])), "a");
        assert_eq!(list(&v(&["a", "b"])), "a and b");
        assert_eq!(list(&v(&["a", "b", "c"])), "a, b, and c");
        assert_eq!(num(100.0 * 0.9), "90");
        assert_eq!(num(0.05), "0.05");
        assert_eq!(num(-0.0001), "0");
    }
}
