//! What a real bronchoscope's video carries besides the image (`phantom --scope-overlay`): a
//! black border around an octagonal field of view and burnt-in on-screen text — a running time
//! code in the border and a coloured label across the image — and the `mask.png` a user would
//! draw for it (black over the border and over the text boxes).

use crate::image::Frame;

/// Glyphs of the on-screen text, 3 x 5 pixels, rows top to bottom, bit 2 = left column.
fn glyph(c: char) -> [u8; 5] {
    match c {
        '0' => [7, 5, 5, 5, 7],
        '1' => [2, 6, 2, 2, 7],
        '2' => [7, 1, 7, 4, 7],
        '3' => [7, 1, 7, 1, 7],
        '4' => [5, 5, 7, 1, 1],
        '5' => [7, 4, 7, 1, 7],
        '6' => [7, 4, 7, 5, 7],
        '7' => [7, 1, 1, 1, 1],
        '8' => [7, 5, 7, 5, 7],
        '9' => [7, 5, 7, 1, 7],
        ':' => [0, 2, 0, 2, 0],
        'B' => [6, 5, 6, 5, 6],
        'L' => [4, 4, 4, 4, 7],
        'R' => [6, 5, 6, 5, 5],
        _ => [0; 5],
    }
}

/// A rectangle of pixels: x, y of the top-left corner, width, height.
type Rect = [u32; 4];

/// The overlay of a `width` x `height` video.
pub struct ScopeOverlay {
    width: u32,
    height: u32,
    /// Row-major: true inside the octagonal field of view.
    field: Vec<bool>,
    /// Text scale (pixels per glyph pixel).
    scale: u32,
    /// Where the time code is written (in the top-left border).
    time_box: Rect,
    /// Where the label is written (across the lower part of the image).
    label_box: Rect,
}

/// The label burnt across the image.
const LABEL: &str = "RB1 L";

/// Linear colour of the label (bright green, below saturation: it would corrupt a texture).
const LABEL_RGB: [f32; 3] = [0.25, 0.85, 0.3];

impl ScopeOverlay {
    /// The overlay of a `width` x `height` video: an octagon inscribed in the frame with its
    /// diagonal sides cutting 22% of each corner's width.
    pub fn new(width: u32, height: u32) -> ScopeOverlay {
        let (w, h) = (width as f64, height as f64);
        let cut = 0.22 * w.min(h) + 0.15 * w.min(h);
        let mut field = vec![false; width as usize * height as usize];
        for y in 0..height {
            for x in 0..width {
                let (px, py) = (x as f64 + 0.5, y as f64 + 0.5);
                let (dx, dy) = (px.min(w - px), py.min(h - py));
                field[(y * width + x) as usize] = dx + dy > cut && dx > 0.02 * w && dy > 0.02 * h;
            }
        }
        let scale = (width.min(height) / 80).max(1);
        let text = |chars: u32| [chars * 4 * scale + scale, 7 * scale];
        let [tw, th] = text(8);
        let [lw, lh] = text(LABEL.len() as u32);
        ScopeOverlay {
            width,
            height,
            field,
            scale,
            time_box: [scale, scale, tw, th],
            label_box: [(width - lw) / 2, height * 7 / 10, lw, lh],
        }
    }

    /// Apply the overlay to frame `index` of a video at `fps` frames per second: black outside
    /// the field of view, the time code in the border, the label across the image.
    pub fn apply(&self, frame: &mut Frame, index: usize, fps: f64) {
        for (px, &inside) in frame.rgb.chunks_exact_mut(3).zip(&self.field) {
            if !inside {
                px.fill(0.0);
            }
        }
        let s = (index as f64 / fps) as u64;
        let time = format!("{:02}:{:02}:{:02}", s / 3600, (s / 60) % 60, s % 60);
        self.write(frame, &time, self.time_box, [1.0; 3]);
        self.write(frame, LABEL, self.label_box, LABEL_RGB);
    }

    /// The mask a user would draw: the field of view, without the text boxes.
    pub fn mask(&self) -> Frame {
        let mut m = Frame::new(self.width, self.height);
        for (px, &inside) in m.rgb.chunks_exact_mut(3).zip(&self.field) {
            px.fill(if inside { 1.0 } else { 0.0 });
        }
        for [x0, y0, bw, bh] in [self.time_box, self.label_box] {
            for y in y0..(y0 + bh).min(self.height) {
                for x in x0..(x0 + bw).min(self.width) {
                    m.set(x, y, [0.0; 3]);
                }
            }
        }
        m
    }

    /// Draw `text` into `frame` at the top-left corner of `at`, one glyph every 4 glyph pixels.
    fn write(&self, frame: &mut Frame, text: &str, at: Rect, rgb: [f32; 3]) {
        let s = self.scale;
        for (k, c) in text.chars().enumerate() {
            for (row, bits) in glyph(c).iter().enumerate() {
                for col in 0..3u32 {
                    if bits & (4 >> col) == 0 {
                        continue;
                    }
                    let (gx, gy) = (
                        at[0] + s * (4 * k as u32 + col) + s,
                        at[1] + s * row as u32 + s,
                    );
                    for y in gy..(gy + s).min(self.height) {
                        for x in gx..(gx + s).min(self.width) {
                            frame.set(x, y, rgb);
                        }
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_mask_hides_the_border_and_every_text_pixel() {
        let o = ScopeOverlay::new(160, 120);
        let mut f = Frame::new(160, 120);
        f.rgb.fill(0.4);
        o.apply(&mut f, 3725, 25.0);
        let mask = o.mask();
        let mut changed_inside = 0;
        for i in 0..160 * 120 {
            let px = &f.rgb[3 * i..3 * i + 3];
            let image = mask.rgb[3 * i] > 0.5;
            if px != [0.4, 0.4, 0.4] && image {
                changed_inside += 1;
            }
        }
        assert_eq!(changed_inside, 0, "text or border outside the mask's black");
        let share = mask.rgb.chunks_exact(3).filter(|p| p[0] > 0.5).count() as f64 / 19200.0;
        assert!(share > 0.6 && share < 0.9, "{share}");
        // The label crosses the field of view: it is over the image, not only in the border.
        let [x0, y0, w, _] = o.label_box;
        assert!(o.field[((y0 + 3) * 160 + x0 + w / 2) as usize]);
    }
}
