//! Who is who in an observer's image (issue: everyone in the session). A detector that sees
//! several people reports them without identity; each participant's coarse pose (EgoNet's,
//! from their own devices) projected into the same image says where that participant must be.
//! [`associate`] assigns each detection to at most one participant and each participant to at
//! most one detection, minimising the summed [`association_cost`] (Kuhn–Munkres); a detection
//! that matches nobody well enough — a bystander, or a participant whose pose is far off — is
//! left unassigned. The paper names tracklet association as future work; the ego-guided
//! region is what makes it a per-frame matching problem.
//!
//! Pixels in the observer image (centre of the top-left pixel at (0, 0)), COCO-17 order.

use glam::Vec2;
use pathfinding::kuhn_munkres::kuhn_munkres;
use pathfinding::matrix::Matrix;
use serde::{Deserialize, Serialize};

use crate::exo_keypoints::{COCO17_COUNT, COCO17_MIRROR, Keypoint2d};
use crate::region::BoundingBox;

/// How [`associate`] decides.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct AssociationOptions {
    /// A detection is assigned only below this cost ([`association_cost`]: mean keypoint
    /// distance over the expected box's diagonal).
    pub max_cost: f32,
    /// Keypoints both the detection and the expectation must have for a cost at all.
    pub min_common_keypoints: usize,
    /// Detected keypoints scoring below this are not compared.
    pub min_score: f32,
    /// A single keypoint's distance is capped at this many diagonals, so one wild keypoint
    /// does not outweigh a body that matches.
    pub max_keypoint_cost: f32,
}

impl Default for AssociationOptions {
    fn default() -> Self {
        Self { max_cost: 0.25, min_common_keypoints: 4, min_score: 0.2, max_keypoint_cost: 1.0 }
    }
}

/// How far `detection` lies from `expected` (a participant's joints projected into the
/// image): the mean keypoint distance over the diagonal of the expected keypoints' box, each
/// capped at `max_keypoint_cost`, the smaller of as detected and left–right exchanged (a
/// single-image detector confuses a person's back for their front). `None` when they share
/// fewer than `min_common_keypoints` keypoints.
pub fn association_cost(
    expected: &[Option<Vec2>; COCO17_COUNT],
    detection: &[Option<Keypoint2d>; COCO17_COUNT],
    options: &AssociationOptions,
) -> Option<f32> {
    let diagonal = BoundingBox::around(expected.iter().flatten().copied())?.diagonal().max(1.0);
    let cost = |mirrored: bool| {
        let (mut sum, mut n) = (0.0, 0);
        for (k, e) in expected.iter().enumerate() {
            let d = detection[if mirrored { COCO17_MIRROR[k] } else { k }];
            if let (Some(e), Some(d)) = (e, d.filter(|d| d.score >= options.min_score)) {
                sum += (d.pixel.distance(*e) / diagonal).min(options.max_keypoint_cost);
                n += 1;
            }
        }
        (n >= options.min_common_keypoints.max(1)).then(|| sum / n as f32)
    };
    match (cost(false), cost(true)) {
        (Some(a), Some(b)) => Some(a.min(b)),
        (a, b) => a.or(b),
    }
}

/// Assigns `detections` (one image's people, without identity) to participants whose joints
/// are `expected` in that image (`None`: not in view or no coarse pose this frame). Returns,
/// per detection, the participant's index or `None` (a bystander, or nobody close enough).
/// The assignment minimises the summed cost over one-to-one pairs, every pair below
/// `options.max_cost`.
pub fn associate(
    expected: &[Option<[Option<Vec2>; COCO17_COUNT]>],
    detections: &[[Option<Keypoint2d>; COCO17_COUNT]],
    options: &AssociationOptions,
) -> Vec<Option<usize>> {
    let mut assigned = vec![None; detections.len()];
    let participants: Vec<usize> = (0..expected.len()).filter(|&p| expected[p].is_some()).collect();
    if participants.is_empty() || detections.is_empty() {
        return assigned;
    }
    // Rows: participants in view. Columns: the detections, then one "nobody" per participant
    // (so rows ≤ columns, and leaving a participant unmatched costs `max_cost`). Kuhn–Munkres
    // maximises, on integers: weights are −cost in 1e-5 diagonals.
    const UNITS: f32 = 1e5;
    let unmatched = -(options.max_cost * UNITS) as i64;
    let impossible = unmatched * 4 - 1;
    let columns = detections.len() + participants.len();
    let rows: Vec<Vec<i64>> = participants
        .iter()
        .map(|&p| {
            let e = expected[p].as_ref().expect("filtered to participants with an expectation");
            let mut row: Vec<i64> = detections
                .iter()
                .map(|d| match association_cost(e, d, options) {
                    Some(c) if c < options.max_cost => -((c * UNITS) as i64),
                    _ => impossible,
                })
                .collect();
            row.resize(columns, unmatched);
            row
        })
        .collect();
    let Ok(weights) = Matrix::from_rows(rows) else { return assigned };
    let (_, columns_of_rows) = kuhn_munkres(&weights);
    for (row, &column) in columns_of_rows.iter().enumerate() {
        if column < detections.len() && weights[(row, column)] != impossible {
            assigned[column] = Some(participants[row]);
        }
    }
    assigned
}

#[cfg(test)]
mod tests {
    use proptest::prelude::*;

    use super::*;

    /// A standing person's 17 keypoints around `centre`, `height` pixels tall.
    fn person(centre: Vec2, height: f32) -> [Option<Vec2>; COCO17_COUNT] {
        let layout: [(f32, f32); COCO17_COUNT] = [
            (0.0, -0.45),
            (0.03, -0.47),
            (-0.03, -0.47),
            (0.06, -0.45),
            (-0.06, -0.45),
            (0.12, -0.3),
            (-0.12, -0.3),
            (0.16, -0.1),
            (-0.16, -0.1),
            (0.17, 0.08),
            (-0.17, 0.08),
            (0.08, 0.05),
            (-0.08, 0.05),
            (0.08, 0.28),
            (-0.08, 0.28),
            (0.08, 0.5),
            (-0.08, 0.5),
        ];
        layout.map(|(x, y)| Some(centre + Vec2::new(x, y) * height))
    }

    fn detected(points: [Option<Vec2>; COCO17_COUNT], offset: Vec2) -> [Option<Keypoint2d>; COCO17_COUNT] {
        points.map(|p| p.map(|pixel| Keypoint2d { pixel: pixel + offset, score: 0.9 }))
    }

    #[test]
    fn people_are_matched_and_a_bystander_is_left_out() {
        let a = person(Vec2::new(200.0, 300.0), 300.0);
        let b = person(Vec2::new(600.0, 320.0), 280.0);
        let bystander = person(Vec2::new(1000.0, 300.0), 250.0);
        let detections = [detected(bystander, Vec2::ZERO), detected(b, Vec2::new(8.0, -5.0)), detected(a, Vec2::ZERO)];
        let options = AssociationOptions::default();
        assert_eq!(associate(&[Some(a), Some(b)], &detections, &options), [None, Some(1), Some(0)]);
        // A participant out of view takes nobody's detection.
        assert_eq!(associate(&[None, Some(b)], &detections, &options), [None, Some(1), None]);
        // A person seen from behind (left and right exchanged) still matches.
        let mirrored: [Option<Keypoint2d>; COCO17_COUNT] =
            std::array::from_fn(|k| detected(a, Vec2::ZERO)[COCO17_MIRROR[k]]);
        assert!(association_cost(&a, &mirrored, &options).unwrap() < 1e-6);
    }

    #[test]
    fn too_few_common_keypoints_give_no_cost() {
        let a = person(Vec2::new(200.0, 300.0), 300.0);
        let mut d = detected(a, Vec2::ZERO);
        for k in d.iter_mut().skip(3) {
            *k = None;
        }
        assert_eq!(association_cost(&a, &d, &AssociationOptions::default()), None);
        assert_eq!(associate(&[Some(a)], &[d], &AssociationOptions::default()), [None]);
    }

    proptest! {
        /// Whatever the order of the detections, each participant's own (slightly noisy)
        /// detection is theirs, and people standing apart from every participant are not.
        #[test]
        fn each_participant_gets_their_own_detection(
            xs in proptest::collection::vec(0.0f32..4.0, 1..4),
            noise in -5.0f32..5.0,
            bystanders in 0usize..3,
            rotate in 0usize..6,
        ) {
            // Participants stand 400 px apart (side by side in the image); bystanders beyond.
            let participants: Vec<_> =
                xs.iter().enumerate().map(|(i, x)| person(Vec2::new(300.0 + 400.0 * i as f32 + x, 400.0), 300.0)).collect();
            let mut detections: Vec<(Option<usize>, _)> = participants
                .iter()
                .enumerate()
                .map(|(i, p)| (Some(i), detected(*p, Vec2::splat(noise))))
                .collect();
            for b in 0..bystanders {
                let x = 300.0 + 400.0 * (participants.len() + b) as f32;
                detections.push((None, detected(person(Vec2::new(x, 400.0), 280.0), Vec2::ZERO)));
            }
            let n = detections.len();
            detections.rotate_left(rotate % n);
            let expected: Vec<_> = participants.iter().map(|p| Some(*p)).collect();
            let only: Vec<_> = detections.iter().map(|(_, d)| *d).collect();
            let truth: Vec<_> = detections.iter().map(|(t, _)| *t).collect();
            prop_assert_eq!(associate(&expected, &only, &AssociationOptions::default()), truth);
        }
    }
}
