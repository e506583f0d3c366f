//! What the shading plots share: the embedded font, the channel colours, and drawing on an SVG
//! or a PNG backend chosen by the file's extension (PNG rendered into an RGB buffer and encoded
//! with `png`; plotters' own encoder would pull a second image crate).

use crate::image::ImageError;
use crate::{Error, Result};
use plotters::prelude::*;
use std::path::Path;
use std::sync::Once;

/// Embedded so plots need no system fonts (DejaVu Sans, see assets/DejaVuSans-LICENSE).
static FONT: &[u8] = include_bytes!("../../assets/DejaVuSans.ttf");
/// The family name the embedded font is registered under.
pub const FONT_NAME: &str = "sans-serif";

/// Register the embedded font with plotters (once).
pub fn register_font() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        // The embedded font is known good; a failure would only lose text, not the plot.
        let _ = plotters::style::register_font(FONT_NAME, FontStyle::Normal, FONT);
    });
}

/// Curve colours of the R, G and B channels.
pub const CURVE_RGB: [RGBColor; 3] = [
    RGBColor(120, 0, 0),
    RGBColor(0, 90, 10),
    RGBColor(0, 20, 120),
];

/// Draw with `$draw(root)` on an SVG or a PNG backend, chosen by the path's extension.
macro_rules! render {
    ($path:expr, $size:expr, $draw:expr) => {{
        $crate::shading::plotting::register_font();
        let path: &std::path::Path = $path;
        let size: (u32, u32) = $size;
        let plot_err = |e: String| {
            $crate::Error::from($crate::image::ImageError::Encoding {
                stage: format!("plot {}", path.display()),
                message: e,
            })
        };
        if path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("svg"))
        {
            let root = SVGBackend::new(path, size).into_drawing_area();
            $draw(&root).map_err(|e| plot_err(e.to_string()))?;
            root.present().map_err(|e| plot_err(e.to_string()))?;
            Ok(())
        } else {
            let mut buf = vec![0u8; size.0 as usize * size.1 as usize * 3];
            {
                let root = BitMapBackend::with_buffer(&mut buf, size).into_drawing_area();
                $draw(&root).map_err(|e| plot_err(e.to_string()))?;
                root.present().map_err(|e| plot_err(e.to_string()))?;
            }
            $crate::shading::plotting::write_png(path, size, &buf)
        }
    }};
}
pub(crate) use render;

/// Write an 8-bit RGB buffer as a PNG.
pub fn write_png(path: &Path, size: (u32, u32), rgb: &[u8]) -> Result<()> {
    let file = std::fs::File::create(path).map_err(|e| Error::io(path, e))?;
    let mut enc = png::Encoder::new(std::io::BufWriter::new(file), size.0, size.1);
    enc.set_color(png::ColorType::Rgb);
    enc.set_depth(png::BitDepth::Eight);
    let to_err = |e: png::EncodingError| ImageError::Encoding {
        stage: path.display().to_string(),
        message: e.to_string(),
    };
    let mut writer = enc.write_header().map_err(to_err)?;
    writer.write_image_data(rgb).map_err(to_err)?;
    writer.finish().map_err(to_err)?;
    Ok(())
}
