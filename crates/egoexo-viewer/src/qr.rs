//! A link as a QR code, shown beside it on the page (the Live panel's camera-page link), so a
//! phone joins a room by pointing its camera at the screen instead of typing a code.
//!
//! The symbol is drawn as SVG: one path of dark modules, one unit per module, inside the
//! 4-module quiet zone the standard asks for; the page's CSS gives it its size.

use std::fmt::Write as _;

use qrcode::{Color, EcLevel, QrCode};
use thiserror::Error;

/// Light modules around the symbol, in modules (ISO/IEC 18004's minimum).
pub const QUIET_ZONE: usize = 4;

/// Why a text has no QR code.
#[derive(Debug, Error, PartialEq, Eq)]
pub enum QrError {
    #[error("the link is too long for a QR code ({bytes} bytes; about 2,300 fit at error correction level M)")]
    TooLong { bytes: usize },
}

/// `text` (a link) as an SVG QR code: byte mode, error correction level M (15 % of the
/// symbol may be lost), the smallest version that holds it. `viewBox` is in modules, quiet
/// zone included; dark modules black on white whatever the page's theme, as scanners expect.
pub fn qr_svg(text: &str) -> Result<String, QrError> {
    let code = QrCode::with_error_correction_level(text.as_bytes(), EcLevel::M)
        .map_err(|_| QrError::TooLong { bytes: text.len() })?;
    let width = code.width();
    let size = width + 2 * QUIET_ZONE;
    let mut path = String::new();
    for (i, colour) in code.to_colors().into_iter().enumerate() {
        if colour == Color::Dark {
            let (x, y) = (i % width + QUIET_ZONE, i / width + QUIET_ZONE);
            // A String's `write!` cannot fail.
            let _ = write!(path, "M{x} {y}h1v1h-1z");
        }
    }
    Ok(format!(
        r##"<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {size} {size}" shape-rendering="crispEdges" role="img" aria-label="QR code of the link"><rect width="{size}" height="{size}" fill="#fff"/><path fill="#000" d="{path}"/></svg>"##
    ))
}

#[cfg(all(test, not(target_arch = "wasm32")))]
mod tests {
    use super::*;

    /// The dark modules of an SVG from [`qr_svg`] (its path read back) as a grey image,
    /// `scale` pixels a module, and its side in pixels.
    fn rasterise(svg: &str, scale: usize) -> (Vec<u8>, usize) {
        let size: usize = svg.split("viewBox=\"0 0 ").nth(1).unwrap().split(' ').next().unwrap().parse().unwrap();
        let path = svg.split(" d=\"").nth(1).unwrap().split('"').next().unwrap();
        let side = size * scale;
        let mut image = vec![255u8; side * side];
        for module in path.split('M').filter(|m| !m.is_empty()) {
            let xy = module.strip_suffix("h1v1h-1z").expect("one module per move");
            let (x, y) = xy.split_once(' ').unwrap();
            let (x, y): (usize, usize) = (x.parse().unwrap(), y.parse().unwrap());
            assert!((QUIET_ZONE..size - QUIET_ZONE).contains(&x) && (QUIET_ZONE..size - QUIET_ZONE).contains(&y));
            for py in y * scale..(y + 1) * scale {
                image[py * side + x * scale..py * side + (x + 1) * scale].fill(0);
            }
        }
        (image, side)
    }

    fn decode(svg: &str) -> String {
        let (image, side) = rasterise(svg, 4);
        let mut prepared = rqrr::PreparedImage::prepare_from_greyscale(side, side, |x, y| image[y * side + x]);
        let grids = prepared.detect_grids();
        assert_eq!(grids.len(), 1, "one symbol");
        grids[0].decode().expect("a readable symbol").1
    }

    #[test]
    fn a_camera_page_link_reads_back_from_its_svg() {
        let link = "https://egoexo.example.org/observe.html#live=r00m1d3nt1f13r.s3cr3tth4t1sl0ng3n0ugh";
        let svg = qr_svg(link).unwrap();
        assert!(svg.starts_with("<svg ") && svg.ends_with("</svg>"));
        assert_eq!(decode(&svg), link);
    }

    #[test]
    fn the_symbol_grows_with_the_link_and_keeps_its_quiet_zone() {
        let side = |text: &str| -> usize {
            let svg = qr_svg(text).unwrap();
            svg.split("viewBox=\"0 0 ").nth(1).unwrap().split(' ').next().unwrap().parse().unwrap()
        };
        // Version 1 is 21 modules; a link of a live room needs a larger version.
        assert_eq!(side("a"), 21 + 2 * QUIET_ZONE);
        let long = format!("https://host.example/observe.html#live={}.{}", "r".repeat(40), "s".repeat(43));
        assert!(side(&long) > side("https://h/"));
        assert_eq!(decode(&qr_svg(&long).unwrap()), long);
    }

    #[test]
    fn a_text_too_long_for_any_version_is_an_error() {
        let text = "x".repeat(5000);
        assert_eq!(qr_svg(&text), Err(QrError::TooLong { bytes: 5000 }));
    }
}
