//! Screen-space-error LOD selection (seed 000 §5, eqs. 17–19).
//!
//! A level with geometric error μ (world units) seen at view depth d projects to
//! ε = H·μ / (2·d·tan(θ/2)) pixels (eq. 18; H the viewport height in pixels, θ the vertical
//! field of view). The coarsest level with ε < λ is drawn (λ = 4 px by default). Instead of
//! evaluating ε per frame, each level's switch distance δ = H·μ / (2·λ·tan(θ/2)) (eq. 19) is
//! precomputed and compared with d. A hysteresis band and a minimum dwell time keep a slow
//! dolly from flickering between two levels; switching to a finer level is never delayed, so
//! the drawn error stays below λ.

use nalgebra::{Point3, Vector3};
use serde::{Deserialize, Serialize};

/// The seed's default pixel threshold λ.
pub const DEFAULT_PIXEL_THRESHOLD: f64 = 4.0;

/// What the projected error depends on: the viewport's height and vertical field of view.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Viewport {
    pub height_px: f64,
    pub fov_y_rad: f64,
}

impl Viewport {
    /// H / (2·tan(θ/2)): pixels per world unit at unit depth.
    fn pixels_per_unit_at_unit_depth(&self) -> f64 {
        self.height_px / (2.0 * (0.5 * self.fov_y_rad).tan())
    }
}

/// View-space depth of an object's centre (eq. 17): d = (C − V)·D/|D|, with V the eye and D
/// the view direction.
pub fn view_depth(
    centre_world: &Point3<f64>,
    eye_world: &Point3<f64>,
    view_direction_world: &Vector3<f64>,
) -> f64 {
    let norm = view_direction_world.norm();
    if norm <= 0.0 || !norm.is_finite() {
        return f64::NAN;
    }
    (centre_world - eye_world).dot(view_direction_world) / norm
}

/// Projected error in pixels of a level with world error `error_world` at depth `depth`
/// (eq. 18). Infinite at or behind the eye.
pub fn projected_error_px(error_world: f64, depth: f64, viewport: &Viewport) -> f64 {
    if depth.is_nan() || depth <= 0.0 {
        return f64::INFINITY;
    }
    error_world * viewport.pixels_per_unit_at_unit_depth() / depth
}

/// Depth from which a level with world error `error_world` projects to less than
/// `threshold_px` (eq. 19).
pub fn switch_distance(error_world: f64, viewport: &Viewport, threshold_px: f64) -> f64 {
    error_world * viewport.pixels_per_unit_at_unit_depth() / threshold_px
}

/// Selection settings.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct SelectionOptions {
    /// λ, pixels.
    pub threshold_px: f64,
    /// A coarser level is taken only beyond (1 + hysteresis)·δ.
    pub hysteresis: f64,
    /// A coarser level is taken only this long after the previous switch, seconds.
    pub min_dwell_s: f64,
}

impl Default for SelectionOptions {
    fn default() -> Self {
        Self {
            threshold_px: DEFAULT_PIXEL_THRESHOLD,
            hysteresis: 0.1,
            min_dwell_s: 1.0,
        }
    }
}

/// Precomputed switch distances of one LOD chain (finest level first).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LodSelector {
    /// δ_i per level; non-decreasing (a coarser level never becomes usable nearer than a
    /// finer one), δ_0 = 0.
    pub switch_distances: Vec<f64>,
    pub options: SelectionOptions,
}

/// Per-instance selection state (the level drawn and when it last changed).
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct LodState {
    pub level: usize,
    pub last_switch_s: Option<f64>,
    pub switches: usize,
}

impl LodSelector {
    /// From each level's world error μ_i (finest first; the finest is drawn at any depth).
    /// Errors that are not finite make their level unusable.
    pub fn new(errors_world: &[f64], viewport: &Viewport, options: SelectionOptions) -> Self {
        let mut switch_distances = Vec::with_capacity(errors_world.len());
        let mut floor = 0.0f64;
        for (i, &mu) in errors_world.iter().enumerate() {
            let delta = if i == 0 {
                0.0
            } else if mu.is_finite() && mu >= 0.0 {
                switch_distance(mu, viewport, options.threshold_px)
            } else {
                f64::INFINITY
            };
            floor = floor.max(delta);
            switch_distances.push(floor);
        }
        Self {
            switch_distances,
            options,
        }
    }

    /// The coarsest level whose projected error is below λ at `depth`, with no hysteresis.
    pub fn coarsest_acceptable(&self, depth: f64) -> usize {
        if depth.is_nan() {
            return 0;
        }
        self.switch_distances
            .iter()
            .rposition(|&delta| depth >= delta)
            .unwrap_or(0)
    }

    /// The level to draw at `depth` and time `time_s`, updating `state`. A finer level is
    /// taken at once when the current one's error would reach λ; a coarser one only beyond
    /// the hysteresis band and after the dwell time.
    pub fn select(&self, state: &mut LodState, depth: f64, time_s: f64) -> usize {
        let last = self.switch_distances.len().saturating_sub(1);
        let current = state.level.min(last);
        let acceptable = self.coarsest_acceptable(depth);
        let next = if acceptable < current {
            acceptable
        } else {
            let banded = self
                .switch_distances
                .iter()
                .rposition(|&delta| depth >= delta * (1.0 + self.options.hysteresis))
                .unwrap_or(0);
            let dwelt = state
                .last_switch_s
                .is_none_or(|t| time_s - t >= self.options.min_dwell_s);
            if banded > current && dwelt {
                banded
            } else {
                current
            }
        };
        if next != state.level {
            state.level = next;
            state.last_switch_s = Some(time_s);
            state.switches += 1;
        }
        next
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn full_hd() -> Viewport {
        Viewport {
            height_px: 1080.0,
            fov_y_rad: 60f64.to_radians(),
        }
    }

    #[test]
    fn the_seeds_worked_example() {
        // H = 1080 px, θ = 60°, μ = 0.1 m: 4.68 px at 20 m, 3.74 px at 25 m, δ = 23.38 m.
        let viewport = full_hd();
        assert!((projected_error_px(0.1, 20.0, &viewport) - 4.677).abs() < 1e-3);
        assert!((projected_error_px(0.1, 25.0, &viewport) - 3.741).abs() < 1e-3);
        let delta = switch_distance(0.1, &viewport, 4.0);
        assert!((delta - 23.383).abs() < 1e-3, "{delta}");
        assert!((projected_error_px(0.1, delta, &viewport) - 4.0).abs() < 1e-9);
    }

    #[test]
    fn view_depth_projects_onto_the_view_direction() {
        let eye = Point3::new(1.0, 2.0, 3.0);
        let d = view_depth(
            &Point3::new(1.0, 12.0, 8.0),
            &eye,
            &Vector3::new(0.0, 2.0, 0.0),
        );
        assert!((d - 10.0).abs() < 1e-12);
        assert!(view_depth(&eye, &eye, &Vector3::zeros()).is_nan());
        assert_eq!(projected_error_px(0.1, -1.0, &full_hd()), f64::INFINITY);
    }

    #[test]
    fn selection_takes_the_coarsest_level_under_the_threshold() {
        let selector = LodSelector::new(&[0.0, 0.01, 0.05, 0.2], &full_hd(), Default::default());
        let deltas = &selector.switch_distances;
        assert_eq!(deltas[0], 0.0);
        assert!(deltas.windows(2).all(|w| w[0] <= w[1]));
        assert_eq!(selector.coarsest_acceptable(0.5), 0);
        assert_eq!(selector.coarsest_acceptable(deltas[2] + 1e-9), 2);
        assert_eq!(selector.coarsest_acceptable(1e9), 3);
        // A level with a bad error is never chosen, nor anything before it becomes unusable.
        let broken = LodSelector::new(&[0.0, f64::NAN, 0.05], &full_hd(), Default::default());
        assert_eq!(broken.switch_distances[1], f64::INFINITY);
        assert_eq!(broken.coarsest_acceptable(1e9), 0);
    }

    proptest! {
        /// On any camera path the drawn level's projected error stays below λ, and a
        /// coarser level is only ever taken a dwell time after the previous switch.
        #[test]
        fn error_bound_and_dwell_on_any_path(
            start in 0.5f64..40.0,
            steps in prop::collection::vec(-3.0f64..3.0, 50..400),
        ) {
            let errors = [0.0, 0.002, 0.008, 0.03, 0.1];
            let viewport = full_hd();
            let selector = LodSelector::new(&errors, &viewport, Default::default());
            let mut state = LodState::default();
            let dt = 1.0 / 30.0;
            let mut depth = start;
            let mut last_switch: Option<f64> = None;
            for (i, speed) in steps.iter().enumerate() {
                let time = i as f64 * dt;
                depth = (depth + speed * dt).max(0.3);
                let before = state.level;
                let level = selector.select(&mut state, depth, time);
                prop_assert!(projected_error_px(errors[level], depth, &viewport) <= 4.0 + 1e-9);
                if level > before {
                    prop_assert!(last_switch.is_none_or(|t| time - t >= 1.0 - 1e-9));
                }
                if level != before {
                    last_switch = Some(time);
                }
            }
        }

        /// A slow dolly (constant speed up to 0.5 m/s, towards or away) switches at most
        /// once in any one-second window.
        #[test]
        fn a_slow_dolly_switches_at_most_once_per_second(
            start in 0.3f64..30.0,
            speed in -0.5f64..0.5,
        ) {
            let errors = [0.0, 0.002, 0.008, 0.03, 0.1];
            let selector = LodSelector::new(&errors, &full_hd(), Default::default());
            let mut state = LodState::default();
            let mut times = Vec::new();
            for frame in 0..1800 {
                let time = frame as f64 / 30.0;
                let depth = (start + speed * time).max(0.3);
                let before = state.level;
                if selector.select(&mut state, depth, time) != before {
                    times.push(time);
                }
            }
            // The first frame may jump straight to the right level from level 0.
            let later: Vec<f64> = times.into_iter().filter(|&t| t > 0.0).collect();
            prop_assert!(later.windows(2).all(|w| w[1] - w[0] >= 1.0), "{later:?}");
        }
    }

    #[test]
    fn a_camera_hovering_at_a_threshold_does_not_flicker() {
        let errors = [0.0, 0.01, 0.04];
        let viewport = full_hd();
        let selector = LodSelector::new(&errors, &viewport, Default::default());
        let delta = selector.switch_distances[1];
        let mut state = LodState::default();
        // Ten seconds oscillating ±3 % around δ_1 at 30 fps.
        for frame in 0..300 {
            let time = frame as f64 / 30.0;
            let depth = delta * (1.0 + 0.03 * (time * 6.0).sin());
            selector.select(&mut state, depth, time);
        }
        // Each time the camera comes nearer than δ_1 the finer level is required (error bound);
        // going back out stays inside the band, so the coarser level is never retaken.
        assert!(state.switches <= 1, "{state:?}");
        // Without hysteresis or dwell the same path would switch every crossing.
        let naive = LodSelector::new(
            &errors,
            &viewport,
            SelectionOptions {
                hysteresis: 0.0,
                min_dwell_s: 0.0,
                ..Default::default()
            },
        );
        let mut naive_state = LodState::default();
        for frame in 0..300 {
            let time = frame as f64 / 30.0;
            let depth = delta * (1.0 + 0.03 * (time * 6.0).sin());
            naive.select(&mut naive_state, depth, time);
        }
        assert!(naive_state.switches > 10, "{naive_state:?}");
    }
}
