//! The timeline plots under the 3D view, sharing the scrubber's time axis: per observer, when it
//! saw the wearer (joints in its image), its 2D keypoints, occlusion labels and the gate's mean;
//! each wrist's tracking; with ground truth, the error over time of the reconstruction and of
//! the ego-only overlay. Drawn from the scene's [`TimelineData`] (the worker's numbers; nothing
//! is recomputed here) into an RGBA image, one column of pixels per slice of frames.
//!
//! Pixels: `x` from the left edge (column `c` covers frames `c·F/W .. (c+1)·F/W`), `y` from the
//! top; [`PlotLayout`] says which rows lie where so the page can label them.

use egoexo_scene::{SceneData, TimelineData};
use serde::Serialize;

use crate::colors::{self, Rgba};

/// Height of an observer's strip, pixels: lanes for "in view", keypoints, (occlusion,) gate.
pub const OBSERVER_ROW_PX: u32 = 18;
/// Height of a wrist's tracking lane, pixels.
pub const WRIST_ROW_PX: u32 = 8;
/// Height of the error plot, pixels.
pub const ERROR_ROW_PX: u32 = 64;
/// Space between rows, pixels.
pub const ROW_GAP_PX: u32 = 3;

/// What a row of the plots shows.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum RowKind {
    Observer,
    Wrist,
    Error,
}

/// One row of the plots: its label and vertical extent, pixels from the top.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PlotRow {
    pub kind: RowKind,
    pub label: String,
    pub top: u32,
    pub height: u32,
    /// The index of the observer or device the row shows.
    pub index: usize,
}

/// Where every row lies, the total height, and the error plot's scale.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PlotLayout {
    pub rows: Vec<PlotRow>,
    pub height: u32,
    /// Top of the error plot's scale (its bottom is 0), cm.
    pub error_max_cm: f32,
}

impl PlotLayout {
    /// The rows `scene` has data for (none without a timeline).
    pub fn of(scene: &SceneData) -> Self {
        let mut rows = Vec::new();
        let mut top = 0;
        let mut push = |kind, label: String, height, index| {
            rows.push(PlotRow { kind, label, top, height, index });
            top += height + ROW_GAP_PX;
        };
        let Some(timeline) = &scene.timeline else {
            return Self { rows: Vec::new(), height: 0, error_max_cm: 0.0 };
        };
        for (i, o) in timeline.observers.iter().enumerate() {
            push(RowKind::Observer, o.id.clone(), OBSERVER_ROW_PX, i);
        }
        for (i, d) in scene.devices.iter().enumerate().filter(|(_, d)| d.name.ends_with("_wrist")) {
            push(RowKind::Wrist, d.name.replace('_', " "), WRIST_ROW_PX, i);
        }
        let mut error_max_cm = 0.0;
        if let Some(errors) = &timeline.errors {
            push(RowKind::Error, "error (cm)".into(), ERROR_ROW_PX, 0);
            error_max_cm = error_scale_cm(
                [Some(&errors.mpjpe_cm), errors.ego_only_mpjpe_cm.as_ref()].into_iter().flatten().map(Vec::as_slice),
            );
        }
        let height = top.saturating_sub(ROW_GAP_PX);
        Self { rows, height, error_max_cm }
    }
}

/// The error plot's top: the 98th percentile of the scored values rounded up to 5 cm (at
/// least 5), so one bad frame does not flatten the rest.
fn error_scale_cm<'a>(series: impl Iterator<Item = &'a [f32]>) -> f32 {
    let mut values: Vec<f32> = series.flatten().copied().filter(|v| v.is_finite() && *v >= 0.0).collect();
    if values.is_empty() {
        return 5.0;
    }
    values.sort_by(f32::total_cmp);
    let p98 = values[((values.len() - 1) as f32 * 0.98) as usize];
    ((p98 / 5.0).ceil() * 5.0).max(5.0)
}

/// The frames column `x` of `width` covers: `start..end` (never empty while there are frames).
pub fn column_frames(x: u32, width: u32, frames: usize) -> std::ops::Range<usize> {
    let width = width.max(1) as usize;
    let x = (x as usize).min(width - 1);
    let start = x * frames / width;
    let end = ((x + 1) * frames / width).max(start + 1).min(frames.max(start + 1));
    start..end
}

/// The frame under pixel column `x` of `width`: the one a click there seeks to.
pub fn frame_at(x: f32, width: f32, frames: usize) -> usize {
    if frames == 0 || !(x.is_finite() && width.is_finite() && width > 0.0) {
        return 0;
    }
    ((x / width).clamp(0.0, 1.0) * (frames - 1) as f32).round() as usize
}

/// Where frame `frame` sits on a plot `width` pixels wide (the inverse of [`frame_at`]): the
/// playhead's x, pixels from the left edge.
pub fn x_of_frame(frame: usize, width: f32, frames: usize) -> f32 {
    if frames < 2 || !(width.is_finite() && width > 0.0) {
        return 0.0;
    }
    frame.min(frames - 1) as f32 / (frames - 1) as f32 * width
}

/// The mean of `values[range]` that are defined (`>= 0`), or `None`.
fn mean_defined(values: &[f32], range: std::ops::Range<usize>) -> Option<f32> {
    let (sum, n) = values
        .get(range)
        .unwrap_or(&[])
        .iter()
        .filter(|v| v.is_finite() && **v >= 0.0)
        .fold((0.0, 0), |(s, n), v| (s + v, n + 1));
    (n > 0).then(|| sum / n as f32)
}

fn mean_u8(values: &[u8], range: std::ops::Range<usize>) -> f32 {
    let slice = values.get(range).unwrap_or(&[]);
    if slice.is_empty() { 0.0 } else { slice.iter().map(|&v| f32::from(v)).sum::<f32>() / slice.len() as f32 }
}

/// An RGBA image, rows top to bottom.
#[derive(Clone, Debug, PartialEq)]
pub struct RgbaImage {
    pub width: u32,
    pub height: u32,
    pub pixels: Vec<u8>,
}

impl RgbaImage {
    fn new(width: u32, height: u32, background: Rgba) -> Self {
        let px = to_bytes(background);
        Self { width, height, pixels: px.iter().copied().cycle().take(4 * (width * height) as usize).collect() }
    }

    /// Blends `colour` (straight alpha) over pixel `(x, y)`.
    fn blend(&mut self, x: u32, y: u32, colour: Rgba) {
        if x >= self.width || y >= self.height {
            return;
        }
        let i = 4 * (y * self.width + x) as usize;
        let a = colour[3].clamp(0.0, 1.0);
        for c in 0..3 {
            let over = colour[c].clamp(0.0, 1.0) * 255.0;
            self.pixels[i + c] = (f32::from(self.pixels[i + c]) * (1.0 - a) + over * a).round() as u8;
        }
        self.pixels[i + 3] = 255;
    }

    fn vertical(&mut self, x: u32, y0: u32, y1: u32, colour: Rgba) {
        for y in y0.min(y1)..=y0.max(y1) {
            self.blend(x, y, colour);
        }
    }

    /// The pixel at `(x, y)`.
    pub fn pixel(&self, x: u32, y: u32) -> [u8; 4] {
        let i = 4 * (y * self.width + x) as usize;
        [self.pixels[i], self.pixels[i + 1], self.pixels[i + 2], self.pixels[i + 3]]
    }
}

fn to_bytes(c: Rgba) -> [u8; 4] {
    c.map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8)
}

/// The plots' background (the page's panel colour).
pub const PLOT_BACKGROUND: Rgba = [0.106, 0.122, 0.149, 1.0];
/// A lane with nothing in it.
const LANE_EMPTY: Rgba = [0.16, 0.18, 0.21, 1.0];
/// "The wearer is in view" (scaled by the share of joints in the image).
const IN_VIEW: Rgba = [0.85, 0.87, 0.9, 1.0];
/// Frames with 2D keypoints (scaled by their count).
const KEYPOINTS: Rgba = [0.2, 0.52, 1.0, 1.0];
/// Occluded keypoints (labels).
const OCCLUDED: Rgba = [1.0, 0.35, 0.3, 1.0];
/// The reconstruction's error line.
const ERROR_LINE: Rgba = [0.95, 0.95, 0.95, 1.0];
/// Where the observers helped (ego-exo below ego-only) / hurt.
const HELPED: Rgba = [0.3, 0.85, 0.4, 0.35];
const HURT: Rgba = [1.0, 0.35, 0.3, 0.35];

/// Renders the plots of `scene` at `width` pixels wide (the height is the layout's).
pub fn render_plots(scene: &SceneData, layout: &PlotLayout, width: u32) -> RgbaImage {
    let width = width.clamp(1, 8192);
    let mut image = RgbaImage::new(width, layout.height.max(1), PLOT_BACKGROUND);
    let Some(timeline) = &scene.timeline else { return image };
    let frames = scene.frames;
    if frames == 0 {
        return image;
    }
    for row in &layout.rows {
        if row.kind == RowKind::Error {
            error_plot(&mut image, timeline, layout, row, frames);
            continue;
        }
        for x in 0..width {
            let range = column_frames(x, width, frames);
            match row.kind {
                RowKind::Observer => observer_column(&mut image, timeline, row, x, range),
                RowKind::Wrist => {
                    let device = &scene.devices[row.index];
                    let tracked = device.valid.get(range.clone()).unwrap_or(&[]);
                    let share = tracked.iter().filter(|&&v| v).count() as f32 / tracked.len().max(1) as f32;
                    let colour = colors::device_colour(&device.name);
                    image.vertical(x, row.top, row.top + row.height - 1, LANE_EMPTY);
                    if share > 0.0 {
                        image.vertical(x, row.top, row.top + row.height - 1, colors::with_alpha(colour, share));
                    }
                }
                RowKind::Error => {}
            }
        }
    }
    image
}

fn observer_column(
    image: &mut RgbaImage,
    timeline: &TimelineData,
    row: &PlotRow,
    x: u32,
    range: std::ops::Range<usize>,
) {
    let o = &timeline.observers[row.index];
    let lanes = if o.occluded.is_some() { 4 } else { 3 };
    let lane = row.height / lanes;
    let lane_rows = |i: u32| (row.top + i * lane, row.top + (i + 1) * lane - 2);
    for i in 0..lanes {
        let (a, b) = lane_rows(i);
        image.vertical(x, a, b, LANE_EMPTY);
    }
    let in_view = mean_u8(&o.joints_in_view, range.clone()) / 24.0;
    if in_view > 0.0 {
        let (a, b) = lane_rows(0);
        image.vertical(x, a, b, colors::with_alpha(IN_VIEW, 0.25 + 0.75 * in_view));
    }
    let keypoints = mean_u8(&o.keypoints, range.clone()) / 13.0;
    if keypoints > 0.0 {
        let (a, b) = lane_rows(1);
        image.vertical(x, a, b, colors::with_alpha(KEYPOINTS, 0.25 + 0.75 * keypoints));
    }
    let mut next = 2;
    if let Some(occluded) = &o.occluded {
        let share = mean_u8(occluded, range.clone()) / 13.0;
        if share > 0.0 {
            let (a, b) = lane_rows(2);
            image.vertical(x, a, b, colors::with_alpha(OCCLUDED, 0.25 + 0.75 * share));
        }
        next = 3;
    }
    if let Some(gate) = mean_defined(&o.gate_mean, range) {
        let (a, b) = lane_rows(next);
        image.vertical(x, a, b, colors::gate_colour(gate));
    }
}

/// The error plot: grid lines every 5 cm (10 above 30 cm), the band between the two methods'
/// MPJPE (green where the observers helped, red where they hurt), the reconstruction's L-PE
/// (dim), the ego-only MPJPE (violet) and the reconstruction's MPJPE (white) as lines joined
/// column to column.
fn error_plot(image: &mut RgbaImage, timeline: &TimelineData, layout: &PlotLayout, row: &PlotRow, frames: usize) {
    let Some(errors) = &timeline.errors else { return };
    let width = image.width;
    let bottom = row.top + row.height - 1;
    let y_of = |cm: f32| {
        let t = (cm / layout.error_max_cm.max(1e-3)).clamp(0.0, 1.0);
        bottom - (t * (row.height - 1) as f32).round() as u32
    };
    let series = |values: Option<&Vec<f32>>| -> Vec<Option<u32>> {
        (0..width).map(|x| values.and_then(|v| mean_defined(v, column_frames(x, width, frames))).map(y_of)).collect()
    };
    let ego_exo = series(Some(&errors.mpjpe_cm));
    let ego_only = series(errors.ego_only_mpjpe_cm.as_ref());
    let lower = series(Some(&errors.lower_cm));
    let step = if layout.error_max_cm > 30.0 { 10.0 } else { 5.0 };
    for x in 0..width {
        let mut cm = step;
        while cm < layout.error_max_cm {
            image.blend(x, y_of(cm), [1.0, 1.0, 1.0, 0.08]);
            cm += step;
        }
        image.blend(x, bottom, [1.0, 1.0, 1.0, 0.2]);
        if let (Some(a), Some(b)) = (ego_exo[x as usize], ego_only[x as usize]) {
            // y grows downwards: ego-exo below ego-only on screen means a larger error.
            image.vertical(x, a, b, if a >= b { HELPED } else { HURT });
        }
    }
    for (values, colour) in
        [(&lower, colors::with_alpha(ERROR_LINE, 0.45)), (&ego_only, colors::EGO_ONLY), (&ego_exo, ERROR_LINE)]
    {
        for x in 0..width as usize {
            let Some(y) = values[x] else { continue };
            // Joined to the previous column's value, so the line reads as a line.
            let from = x.checked_sub(1).and_then(|p| values[p]).unwrap_or(y);
            image.vertical(x as u32, from, y, colour);
        }
    }
}

/// What the plots say at `frame`, for the hover text: the time, and per row its values.
pub fn describe_frame(scene: &SceneData, frame: usize) -> String {
    let frame = frame.min(scene.frames.saturating_sub(1));
    let mut parts = vec![format!("frame {} · {:.2} s", frame + 1, frame as f64 / f64::from(scene.fps.max(1e-3)))];
    let Some(timeline) = &scene.timeline else { return parts.join("\n") };
    for o in &timeline.observers {
        let in_view = o.joints_in_view.get(frame).copied().unwrap_or(0);
        let keypoints = o.keypoints.get(frame).copied().unwrap_or(0);
        let mut line = format!("{}: {in_view}/24 joints in view, {keypoints}/13 keypoints", o.id);
        if let Some(occluded) = o.occluded.as_ref().and_then(|v| v.get(frame)) {
            line.push_str(&format!(", {occluded} occluded"));
        }
        match o.gate_mean.get(frame).filter(|g| **g >= 0.0) {
            Some(g) => line.push_str(&format!(", gate {g:.2}")),
            None => line.push_str(", no rays"),
        }
        parts.push(line);
    }
    for d in scene.devices.iter().filter(|d| d.name.ends_with("_wrist")) {
        let tracked = d.valid.get(frame).copied().unwrap_or(false);
        parts.push(format!("{}: {}", d.name.replace('_', " "), if tracked { "tracked" } else { "not tracked" }));
    }
    if let Some(e) = &timeline.errors {
        let value = |v: Option<&Vec<f32>>| v.and_then(|v| v.get(frame)).filter(|v| **v >= 0.0).copied();
        match value(Some(&e.mpjpe_cm)) {
            Some(m) => {
                let mut line = format!("MPJPE {m:.1} cm");
                if let Some(l) = value(Some(&e.lower_cm)) {
                    line.push_str(&format!(" (L-PE {l:.1})"));
                }
                if let Some(o) = value(e.ego_only_mpjpe_cm.as_ref()) {
                    line.push_str(&format!(" · ego-only {o:.1} cm"));
                }
                parts.push(line);
            }
            None => parts.push("not scored".into()),
        }
    }
    parts.join("\n")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::example::example_scene;
    use egoexo_scene::{ErrorTimeline, ObserverTimeline};
    #[cfg(target_arch = "wasm32")]
    use wasm_bindgen_test::wasm_bindgen_test as test;

    /// The example scene with a timeline: observer 1 sees the wearer in the first half only
    /// (gate 1 there); the reconstruction's error is 4 cm, the ego-only's 8 cm, except frames
    /// 90.. where ego-exo is worse (12 cm).
    fn scene_with_timeline(frames: usize) -> SceneData {
        let mut scene = example_scene(frames);
        let half = frames / 2;
        scene.timeline = Some(TimelineData {
            observers: vec![ObserverTimeline {
                id: "observer-1".into(),
                joints_in_view: (0..frames).map(|f| if f < half { 24 } else { 0 }).collect(),
                keypoints: (0..frames).map(|f| if f < half { 13 } else { 0 }).collect(),
                occluded: None,
                gate_mean: (0..frames).map(|f| if f < half { 1.0 } else { -1.0 }).collect(),
            }],
            errors: Some(ErrorTimeline {
                mpjpe_cm: (0..frames).map(|f| if f >= 90 { 12.0 } else { 4.0 }).collect(),
                lower_cm: vec![6.0; frames],
                ego_only_mpjpe_cm: Some(vec![8.0; frames]),
                ego_only_lower_cm: Some(vec![9.0; frames]),
            }),
        });
        scene.devices[1].valid[10..20].fill(false);
        scene.check().unwrap();
        scene
    }

    #[test]
    fn the_layout_has_a_row_per_observer_and_wrist_and_the_errors() {
        let scene = scene_with_timeline(120);
        let layout = PlotLayout::of(&scene);
        let kinds: Vec<_> = layout.rows.iter().map(|r| (r.kind, r.label.as_str())).collect();
        assert_eq!(
            kinds,
            [
                (RowKind::Observer, "observer-1"),
                (RowKind::Wrist, "left wrist"),
                (RowKind::Wrist, "right wrist"),
                (RowKind::Error, "error (cm)")
            ]
        );
        assert_eq!(layout.height, OBSERVER_ROW_PX + 2 * WRIST_ROW_PX + ERROR_ROW_PX + 3 * ROW_GAP_PX);
        // 12 cm at the 98th percentile → a 15 cm scale.
        assert_eq!(layout.error_max_cm, 15.0);
        let mut old = scene.clone();
        old.timeline = None;
        assert!(PlotLayout::of(&old).rows.is_empty());
    }

    #[test]
    fn the_image_shows_where_the_observer_saw_the_wearer_and_where_it_helped() {
        let scene = scene_with_timeline(120);
        let layout = PlotLayout::of(&scene);
        let width = 240;
        let image = render_plots(&scene, &layout, width);
        assert_eq!(image.pixels.len(), (4 * width * layout.height) as usize);
        let observer = &layout.rows[0];
        let gate_lane_y = observer.top + 2 * (observer.height / 3);
        // Seen (first half): the gate lane is green; unseen: empty.
        let seen = image.pixel(30, gate_lane_y);
        assert!(seen[1] > 150 && seen[0] < 120, "{seen:?}");
        assert_eq!(image.pixel(200, gate_lane_y), to_bytes(LANE_EMPTY));
        assert_eq!(image.pixel(200, observer.top), to_bytes(LANE_EMPTY));
        assert_ne!(image.pixel(30, observer.top), to_bytes(LANE_EMPTY));
        // The left wrist's gap (frames 10..20 → columns 20..40) is empty.
        let wrist = &layout.rows[1];
        assert_eq!(image.pixel(30, wrist.top + 2), to_bytes(LANE_EMPTY));
        assert_ne!(image.pixel(60, wrist.top + 2), to_bytes(LANE_EMPTY));
        // Errors: green between the lines where ego-exo is better, red after frame 90.
        let error = &layout.rows[3];
        let y = |cm: f32| error.top + error.height - 1 - (cm / 15.0 * (error.height - 1) as f32).round() as u32;
        let helped = image.pixel(40, y(6.0));
        assert!(helped[1] > helped[0] + 20, "{helped:?}");
        let hurt = image.pixel(220, y(10.0));
        assert!(hurt[0] > hurt[1] + 20, "{hurt:?}");
        assert_eq!(image.pixel(40, y(4.0)), to_bytes(ERROR_LINE));
    }

    #[test]
    fn columns_cover_every_frame_once_and_clicks_map_to_frames() {
        for (frames, width) in [(10usize, 100u32), (1161, 800), (108_000, 1000), (1, 5)] {
            let mut next = 0;
            for x in 0..width {
                let r = column_frames(x, width, frames);
                assert!(r.start <= next && r.end > r.start && r.end <= frames.max(1));
                next = next.max(r.end);
            }
            assert_eq!(next, frames.max(1));
        }
        assert_eq!(frame_at(0.0, 800.0, 1161), 0);
        assert_eq!(frame_at(800.0, 800.0, 1161), 1160);
        assert_eq!(frame_at(400.0, 800.0, 1161), 580);
        assert_eq!(frame_at(-5.0, 800.0, 1161), 0);
        assert_eq!(frame_at(f32::NAN, 800.0, 1161), 0);
        assert_eq!(frame_at(3.0, 800.0, 0), 0);
        for frame in [0, 1, 580, 1160] {
            assert_eq!(frame_at(x_of_frame(frame, 800.0, 1161), 800.0, 1161), frame);
        }
        assert_eq!(x_of_frame(5, 800.0, 1), 0.0);
    }

    #[test]
    fn hover_text_gives_the_values_at_the_frame() {
        let scene = scene_with_timeline(120);
        let seen = describe_frame(&scene, 10);
        assert!(seen.contains("observer-1: 24/24 joints in view, 13/13 keypoints, gate 1.00"), "{seen}");
        assert!(seen.contains("left wrist: not tracked"), "{seen}");
        assert!(seen.contains("MPJPE 4.0 cm (L-PE 6.0) · ego-only 8.0 cm"), "{seen}");
        let unseen = describe_frame(&scene, 100);
        assert!(unseen.contains("0/24 joints in view, 0/13 keypoints, no rays"), "{unseen}");
        assert!(describe_frame(&scene, 10_000).starts_with("frame 120 ·"));
    }
}
