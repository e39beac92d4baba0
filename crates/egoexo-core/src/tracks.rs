//! Temporal filtering of per-frame tracks that have gaps (a keypoint's ray over a window,
//! valid only on the frames where it was detected).
//!
//! Frames are equally spaced (the session timeline); `sigma_frames` is in frames.

use glam::Vec3;

/// Replaces every valid frame of `values` by the Gaussian-weighted mean (standard deviation
/// `sigma_frames`, truncated at 3σ) of the valid frames around it. Invalid frames are left
/// as they are and never contribute: no gap is bridged and nothing is extrapolated, so the
/// set of valid frames is unchanged. `sigma_frames <= 0` (or not finite) leaves the track
/// unchanged; a length mismatch between `values` and `valid` filters only the common prefix.
///
/// The weights are symmetric, so a track that is linear over the valid neighbourhood of a
/// frame keeps its value there; every output lies in the range of the inputs it averages.
pub fn smooth_track_over_valid_frames(values: &mut [Vec3], valid: &[bool], sigma_frames: f32) {
    if !(sigma_frames.is_finite() && sigma_frames > 0.0) {
        return;
    }
    let n = values.len().min(valid.len());
    let radius = (3.0 * sigma_frames).floor() as usize;
    let weights: Vec<f32> = (0..=radius).map(|d| (-0.5 * (d as f32 / sigma_frames).powi(2)).exp()).collect();
    let input = values[..n].to_vec();
    for t in (0..n).filter(|&t| valid[t]) {
        let (mut sum, mut total) = (Vec3::ZERO, 0.0f32);
        for s in t.saturating_sub(radius)..(t + radius + 1).min(n) {
            if valid[s] {
                let w = weights[t.abs_diff(s)];
                sum += w * input[s];
                total += w;
            }
        }
        values[t] = sum / total; // total ≥ 1: frame t itself is valid with weight 1
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn vec3() -> impl Strategy<Value = Vec3> {
        (-5.0f32..5.0, -5.0f32..5.0, -5.0f32..5.0).prop_map(|(x, y, z)| Vec3::new(x, y, z))
    }

    proptest! {
        #[test]
        fn invalid_frames_are_untouched_and_outputs_stay_in_range(
            track in prop::collection::vec((vec3(), any::<bool>()), 1..60),
            sigma in 0.3f32..4.0,
        ) {
            let (mut values, valid): (Vec<Vec3>, Vec<bool>) = track.into_iter().unzip();
            let before = values.clone();
            smooth_track_over_valid_frames(&mut values, &valid, sigma);
            let kept: Vec<Vec3> = before.iter().zip(&valid).filter(|(_, v)| **v).map(|(p, _)| *p).collect();
            for t in 0..values.len() {
                if !valid[t] {
                    prop_assert_eq!(values[t], before[t]);
                    continue;
                }
                prop_assert!(values[t].is_finite());
                for axis in 0..3 {
                    let lo = kept.iter().map(|p| p[axis]).fold(f32::INFINITY, f32::min);
                    let hi = kept.iter().map(|p| p[axis]).fold(f32::NEG_INFINITY, f32::max);
                    prop_assert!(values[t][axis] >= lo - 1e-4 && values[t][axis] <= hi + 1e-4);
                }
            }
        }

        #[test]
        fn constant_and_linear_tracks_are_kept(
            start in vec3(), step in vec3(), n in 8usize..60, sigma in 0.3f32..3.0,
        ) {
            let mut constant = vec![start; n];
            smooth_track_over_valid_frames(&mut constant, &vec![true; n], sigma);
            prop_assert!(constant.iter().all(|p| p.distance(start) < 1e-4));
            let line: Vec<Vec3> = (0..n).map(|t| start + step * t as f32 * 0.1).collect();
            let mut smoothed = line.clone();
            smooth_track_over_valid_frames(&mut smoothed, &vec![true; n], sigma);
            let r = (3.0 * sigma).floor() as usize;
            for t in r..n.saturating_sub(r) {
                prop_assert!(smoothed[t].distance(line[t]) < 1e-3, "frame {t}");
            }
        }
    }

    #[test]
    fn an_isolated_detection_is_not_pulled_towards_missing_frames() {
        let mut values = vec![Vec3::ZERO, Vec3::ONE, Vec3::ZERO];
        smooth_track_over_valid_frames(&mut values, &[false, true, false], 2.0);
        assert_eq!(values[1], Vec3::ONE);
    }

    #[test]
    fn frame_to_frame_noise_is_reduced() {
        // Alternating ±1 cm around a fixed point: the worst case for per-frame flicker.
        let mut values: Vec<Vec3> = (0..48).map(|t| Vec3::X * if t % 2 == 0 { 0.01 } else { -0.01 }).collect();
        smooth_track_over_valid_frames(&mut values, &[true; 48], 2.0);
        assert!(values[8..40].iter().all(|p| p.length() < 1e-4), "{:?}", &values[8..12]);
    }

    #[test]
    fn zero_or_invalid_sigma_leaves_the_track_unchanged() {
        let before: Vec<Vec3> = (0..10).map(|t| Vec3::splat(t as f32 * t as f32)).collect();
        for sigma in [0.0, -1.0, f32::NAN] {
            let mut values = before.clone();
            smooth_track_over_valid_frames(&mut values, &[true; 10], sigma);
            assert_eq!(values, before);
        }
    }
}
