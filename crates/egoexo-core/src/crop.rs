//! Detector crops (paper § Ego-Guided Wearer Localization, the step after the region): the
//! square window of an observer image that a top-down 2D pose model sees, made from the region
//! the core proposes, and the one mapping between the model's input and the full image.
//!
//! Coordinates: full-image pixels with the centre of the top-left pixel at (0, 0) (the
//! pipeline's convention, as in [`crate::region`]), so the image spans `[-0.5, size − 0.5]`.
//! A window's normalised coordinates `u ∈ [0, 1]²` run from its left/top edge to its
//! right/bottom edge — how pose models such as MoveNet report keypoints (as `(y, x)`; callers
//! swap). Fisheye images are cropped as they are: the rays later unproject with the camera
//! model, so the crop needs no undistortion to be geometrically right.

use glam::Vec2;
use serde::{Deserialize, Serialize};

use crate::region::BoundingBox;

/// A square window of an image: `[min, min + side]` on both axes, in full-image pixels. It
/// may extend past the image; what lies outside is black in the crop.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct CropWindow {
    /// Top-left corner (the window's edge, not a pixel centre), full-image pixels.
    pub min: Vec2,
    /// Side length, full-image pixels (> 0).
    pub side: f32,
}

impl CropWindow {
    /// The square centred on `region` whose side is the region's longer side (the region
    /// already carries the proposal's margin), at least `min_side` pixels; `None` for a
    /// degenerate region (not finite).
    pub fn around(region: &BoundingBox, min_side: f32) -> Option<Self> {
        let size = region.size();
        let side = size.max_element().max(min_side).max(1.0);
        let centre = region.center();
        (centre.is_finite() && side.is_finite()).then(|| Self { min: centre - Vec2::splat(0.5 * side), side })
    }

    /// The full-image pixel at normalised window coordinates `u` (`(0, 0)` top-left edge,
    /// `(1, 1)` bottom-right edge).
    pub fn full_from_normalized(&self, u: Vec2) -> Vec2 {
        self.min + u * self.side
    }

    /// The normalised window coordinates of full-image pixel `p` (inverse of
    /// [`Self::full_from_normalized`]).
    pub fn normalized_from_full(&self, p: Vec2) -> Vec2 {
        (p - self.min) / self.side
    }

    /// Full-image pixels per model-input pixel for a model input of `size × size`.
    pub fn scale(&self, size: u32) -> f32 {
        self.side / size as f32
    }

    /// The window as a 2D-canvas `drawImage(image, sx, sy, sw, sh, dx, dy, dw, dh)` onto a
    /// black `size × size` canvas, for an image of `width × height`: the part of the window
    /// inside the image, and where it lands in the crop. Canvas coordinates put the image's
    /// top-left *edge* at (0, 0) (ours put that pixel's centre there: +0.5). `None` when the
    /// window misses the image (the crop is all black).
    pub fn canvas_draw(&self, width: u32, height: u32, size: u32) -> Option<CanvasDraw> {
        let min = self.min + Vec2::splat(0.5);
        let max = min + Vec2::splat(self.side);
        let source_min = min.max(Vec2::ZERO);
        let source_max = max.min(Vec2::new(width as f32, height as f32));
        let extent = source_max - source_min;
        if !(extent.x > 0.0 && extent.y > 0.0) || size == 0 {
            return None;
        }
        let to_crop = size as f32 / self.side;
        let dest_min = (source_min - min) * to_crop;
        Some(CanvasDraw {
            source: [source_min.x, source_min.y, extent.x, extent.y],
            dest: [dest_min.x, dest_min.y, extent.x * to_crop, extent.y * to_crop],
        })
    }
}

/// One `drawImage` call that makes a crop ([`CropWindow::canvas_draw`]): `[x, y, width,
/// height]` of the image (canvas pixels, edges at integers) and of the crop.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CanvasDraw {
    pub source: [f32; 4],
    pub dest: [f32; 4],
}

/// Resamples window `window` of an RGB image (`width × height`, 3 bytes per pixel, rows top
/// to bottom) into a `size × size` RGB image for a model: each output pixel averages
/// `n × n` bilinear samples spread over its footprint (`n` = the downscale, rounded up, at
/// most 4), so a large crop shrinks without aliasing; samples outside the image are black.
/// Returns `None` when `image` is not `width × height × 3` bytes or a size is 0.
pub fn resample_rgb(image: &[u8], width: u32, height: u32, window: &CropWindow, size: u32) -> Option<Vec<u8>> {
    let (w, h) = (width as usize, height as usize);
    if size == 0 || w == 0 || h == 0 || image.len() != w * h * 3 {
        return None;
    }
    let scale = window.scale(size);
    let taps = (scale.ceil() as usize).clamp(1, 4);
    let texel = |x: isize, y: isize, c: usize| -> f32 {
        if x < 0 || y < 0 || x as usize >= w || y as usize >= h {
            0.0
        } else {
            f32::from(image[(y as usize * w + x as usize) * 3 + c])
        }
    };
    let mut out = vec![0u8; size as usize * size as usize * 3];
    for j in 0..size as usize {
        for i in 0..size as usize {
            let mut acc = [0f32; 3];
            for ty in 0..taps {
                for tx in 0..taps {
                    // Sub-sample positions inside the output pixel, then into the full image.
                    let u = Vec2::new(
                        (i as f32 + (tx as f32 + 0.5) / taps as f32) / size as f32,
                        (j as f32 + (ty as f32 + 0.5) / taps as f32) / size as f32,
                    );
                    let p = window.full_from_normalized(u);
                    let (x0, y0) = (p.x.floor(), p.y.floor());
                    let (fx, fy) = (p.x - x0, p.y - y0);
                    let (x0, y0) = (x0 as isize, y0 as isize);
                    for c in 0..3 {
                        let top = texel(x0, y0, c) * (1.0 - fx) + texel(x0 + 1, y0, c) * fx;
                        let bottom = texel(x0, y0 + 1, c) * (1.0 - fx) + texel(x0 + 1, y0 + 1, c) * fx;
                        acc[c] += top * (1.0 - fy) + bottom * fy;
                    }
                }
            }
            let n = (taps * taps) as f32;
            for c in 0..3 {
                out[(j * size as usize + i) * 3 + c] = (acc[c] / n).round().clamp(0.0, 255.0) as u8;
            }
        }
    }
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    #[cfg(target_arch = "wasm32")]
    use wasm_bindgen_test::wasm_bindgen_test as test;

    fn bbox(x: f32, y: f32, w: f32, h: f32) -> BoundingBox {
        BoundingBox { min: Vec2::new(x, y), max: Vec2::new(x + w, y + h) }
    }

    proptest! {
        #[test]
        fn full_and_normalized_coordinates_are_inverse(
            x in -50f32..1500.0, y in -50f32..1500.0, w in 1f32..900.0, h in 1f32..900.0,
            px in -100f32..2000.0, py in -100f32..2000.0,
        ) {
            let window = CropWindow::around(&bbox(x, y, w, h), 0.0).unwrap();
            let p = Vec2::new(px, py);
            let back = window.full_from_normalized(window.normalized_from_full(p));
            prop_assert!((back - p).length() < 1e-3 * (1.0 + p.length()));
        }

        #[test]
        fn the_window_is_square_holds_the_region_and_shares_its_centre(
            x in -50f32..1500.0, y in -50f32..1500.0, w in 0f32..900.0, h in 0f32..900.0, min_side in 0f32..300.0,
        ) {
            let region = bbox(x, y, w, h);
            let window = CropWindow::around(&region, min_side).unwrap();
            prop_assert!(window.side >= w.max(h) - 1e-3 && window.side >= min_side - 1e-3);
            let lo = window.normalized_from_full(region.min);
            let hi = window.normalized_from_full(region.max);
            prop_assert!(lo.min_element() >= -1e-4 && hi.max_element() <= 1.0 + 1e-4);
            let centre = window.full_from_normalized(Vec2::splat(0.5));
            prop_assert!((centre - region.center()).length() < 1e-3 * (1.0 + centre.length()));
        }

        /// A bright dot in the image lands, in the crop, where the mapping says: the crop's
        /// brightest pixel maps back to within one model pixel of the dot.
        #[test]
        fn a_dot_in_the_image_is_where_the_mapping_puts_it_in_the_crop(
            dx in 20u32..140, dy in 20u32..100, side in 24f32..150.0, ox in -20f32..20.0, oy in -20f32..20.0,
        ) {
            let (w, h) = (160u32, 120u32);
            let mut image = vec![0u8; (w * h * 3) as usize];
            for c in 0..3 { image[((dy * w + dx) * 3) as usize + c] = 255; }
            let dot = Vec2::new(dx as f32, dy as f32);
            let region = bbox(dot.x + ox - side / 2.0, dot.y + oy - side / 2.0, side, side);
            let window = CropWindow::around(&region, 0.0).unwrap();
            let size = 32;
            let crop = resample_rgb(&image, w, h, &window, size).unwrap();
            let u = window.normalized_from_full(dot);
            prop_assume!(u.min_element() > 0.05 && u.max_element() < 0.95);
            let best = (0..size as usize * size as usize).max_by_key(|&i| crop[i * 3]).unwrap();
            prop_assert!(crop[best * 3] > 0);
            let centre = Vec2::new((best % size as usize) as f32 + 0.5, (best / size as usize) as f32 + 0.5) / size as f32;
            let found = window.full_from_normalized(centre);
            prop_assert!((found - dot).length() <= window.scale(size) * 1.5 + 1.0, "{found} vs {dot}");
        }
    }

    proptest! {
        /// The canvas draw and [`resample_rgb`] are the same mapping: both ends of the drawn
        /// source rectangle land, through the window's own mapping, on the ends of the drawn
        /// destination rectangle, and the source lies inside the image.
        #[test]
        fn the_canvas_draw_is_the_windows_mapping_clipped_to_the_image(
            x in -400f32..1500.0, y in -400f32..1500.0, side in 1f32..900.0,
            width in 16u32..1600, height in 16u32..1600, size in 16u32..256,
        ) {
            let window = CropWindow { min: Vec2::new(x, y), side };
            let Some(draw) = window.canvas_draw(width, height, size) else {
                // No overlap: the window lies wholly outside the image's edges.
                let (lo, hi) = (window.min + 0.5, window.min + 0.5 + side);
                prop_assert!(hi.x <= 0.0 || hi.y <= 0.0 || lo.x >= width as f32 || lo.y >= height as f32);
                return Ok(());
            };
            let [sx, sy, sw, sh] = draw.source;
            let [dx, dy, dw, dh] = draw.dest;
            prop_assert!(sx >= 0.0 && sy >= 0.0 && sw > 0.0 && sh > 0.0);
            prop_assert!(sx + sw <= width as f32 + 1e-3 && sy + sh <= height as f32 + 1e-3);
            for (canvas, crop) in [(Vec2::new(sx, sy), Vec2::new(dx, dy)), (Vec2::new(sx + sw, sy + sh), Vec2::new(dx + dw, dy + dh))] {
                // Canvas edge coordinates → ours (pixel centres) → the crop's normalised coordinates.
                let u = window.normalized_from_full(canvas - Vec2::splat(0.5));
                prop_assert!((u * size as f32 - crop).length() < 1e-2 * (1.0 + crop.length()), "{u} vs {crop}");
            }
            prop_assert!(dx >= -1e-3 && dy >= -1e-3 && dx + dw <= size as f32 + 1e-2 && dy + dh <= size as f32 + 1e-2);
        }
    }

    #[test]
    fn a_window_inside_the_image_is_drawn_whole() {
        let window = CropWindow { min: Vec2::new(99.5, 19.5), side: 200.0 };
        let draw = window.canvas_draw(640, 480, 192).unwrap();
        assert_eq!(draw.source, [100.0, 20.0, 200.0, 200.0]);
        assert_eq!(draw.dest, [0.0, 0.0, 192.0, 192.0]);
        let half_out = CropWindow { min: Vec2::new(-100.5, -0.5), side: 200.0 };
        let draw = half_out.canvas_draw(640, 480, 100).unwrap();
        assert_eq!(draw.source, [0.0, 0.0, 100.0, 200.0]);
        assert_eq!(draw.dest, [50.0, 0.0, 50.0, 100.0]);
        assert!(CropWindow { min: Vec2::new(700.0, 0.0), side: 50.0 }.canvas_draw(640, 480, 192).is_none());
    }

    #[test]
    fn a_uniform_image_stays_uniform_and_outside_is_black() {
        let (w, h) = (64u32, 48u32);
        let image = vec![200u8; (w * h * 3) as usize];
        let inside = CropWindow { min: Vec2::new(4.0, 4.0), side: 40.0 };
        assert!(resample_rgb(&image, w, h, &inside, 16).unwrap().iter().all(|&v| v == 200));
        let half_out = CropWindow { min: Vec2::new(-32.0, 0.0), side: 64.0 };
        let crop = resample_rgb(&image, w, h, &half_out, 16).unwrap();
        assert_eq!(crop[0], 0, "left half lies outside the image");
        assert_eq!(crop[(8 * 16 + 15) * 3], 200, "right half inside");
        assert!(resample_rgb(&image[1..], w, h, &inside, 16).is_none());
        assert!(resample_rgb(&image, w, h, &inside, 0).is_none());
    }

    #[test]
    fn degenerate_regions_give_no_window() {
        assert!(CropWindow::around(&bbox(f32::NAN, 0.0, 1.0, 1.0), 0.0).is_none());
        assert_eq!(CropWindow::around(&bbox(10.0, 10.0, 0.0, 0.0), 0.0).unwrap().side, 1.0);
    }
}
