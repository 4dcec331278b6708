//! A minimal RGB raster canvas (filled convex polygons, thick lines, discs, 5x7 bitmap text) and
//! PNG output: enough to draw maps and plots with no graphics stack.

use std::io::Write;

pub type Rgb = [u8; 3];

pub struct Canvas {
    pub width: u32,
    pub height: u32,
    pub pixels: Vec<u8>,
}

impl Canvas {
    pub fn new(width: u32, height: u32, background: Rgb) -> Self {
        let mut pixels = Vec::with_capacity((width * height * 3) as usize);
        for _ in 0..width * height {
            pixels.extend_from_slice(&background);
        }
        Self {
            width,
            height,
            pixels,
        }
    }

    pub fn set(&mut self, x: i64, y: i64, c: Rgb) {
        if x < 0 || y < 0 || x >= i64::from(self.width) || y >= i64::from(self.height) {
            return;
        }
        let i = ((y as u32 * self.width + x as u32) * 3) as usize;
        self.pixels[i..i + 3].copy_from_slice(&c);
    }

    /// Pixel bounds of a box in floating coordinates, clipped to the canvas.
    fn bounds(&self, x0: f64, y0: f64, x1: f64, y1: f64) -> (i64, i64, i64, i64) {
        (
            x0.floor().max(0.0) as i64,
            y0.floor().max(0.0) as i64,
            x1.ceil().min(f64::from(self.width) - 1.0) as i64,
            y1.ceil().min(f64::from(self.height) - 1.0) as i64,
        )
    }

    /// Fills a convex polygon given in pixel coordinates (either winding).
    pub fn fill_convex(&mut self, pts: &[[f64; 2]], c: Rgb) {
        if pts.len() < 3 {
            return;
        }
        let (mut x0, mut y0, mut x1, mut y1) = (f64::MAX, f64::MAX, f64::MIN, f64::MIN);
        for p in pts {
            x0 = x0.min(p[0]);
            y0 = y0.min(p[1]);
            x1 = x1.max(p[0]);
            y1 = y1.max(p[1]);
        }
        let (bx0, by0, bx1, by1) = self.bounds(x0, y0, x1, y1);
        for y in by0..=by1 {
            for x in bx0..=bx1 {
                let q = [x as f64 + 0.5, y as f64 + 0.5];
                let mut pos = false;
                let mut neg = false;
                for i in 0..pts.len() {
                    let a = pts[i];
                    let b = pts[(i + 1) % pts.len()];
                    let cross = (b[0] - a[0]) * (q[1] - a[1]) - (b[1] - a[1]) * (q[0] - a[0]);
                    pos |= cross > 0.0;
                    neg |= cross < 0.0;
                }
                if !(pos && neg) {
                    self.set(x, y, c);
                }
            }
        }
    }

    pub fn polygon_outline(&mut self, pts: &[[f64; 2]], width: f64, c: Rgb) {
        for i in 0..pts.len() {
            self.line(pts[i], pts[(i + 1) % pts.len()], width, c);
        }
    }

    pub fn disc(&mut self, centre: [f64; 2], radius: f64, c: Rgb) {
        let (bx0, by0, bx1, by1) = self.bounds(
            centre[0] - radius,
            centre[1] - radius,
            centre[0] + radius,
            centre[1] + radius,
        );
        for y in by0..=by1 {
            for x in bx0..=bx1 {
                let dx = x as f64 + 0.5 - centre[0];
                let dy = y as f64 + 0.5 - centre[1];
                if dx * dx + dy * dy <= radius * radius {
                    self.set(x, y, c);
                }
            }
        }
    }

    /// A line segment `width` pixels thick with round caps.
    pub fn line(&mut self, a: [f64; 2], b: [f64; 2], width: f64, c: Rgb) {
        let r = width / 2.0;
        let (bx0, by0, bx1, by1) = self.bounds(
            a[0].min(b[0]) - r,
            a[1].min(b[1]) - r,
            a[0].max(b[0]) + r,
            a[1].max(b[1]) + r,
        );
        let d = [b[0] - a[0], b[1] - a[1]];
        let len2 = (d[0] * d[0] + d[1] * d[1]).max(1e-12);
        for y in by0..=by1 {
            for x in bx0..=bx1 {
                let q = [x as f64 + 0.5 - a[0], y as f64 + 0.5 - a[1]];
                let t = ((q[0] * d[0] + q[1] * d[1]) / len2).clamp(0.0, 1.0);
                let e = [q[0] - t * d[0], q[1] - t * d[1]];
                if e[0] * e[0] + e[1] * e[1] <= r * r {
                    self.set(x, y, c);
                }
            }
        }
    }

    /// A dashed polyline; the dash pattern continues across vertices.
    pub fn dashed_polyline(&mut self, pts: &[[f64; 2]], width: f64, dash: f64, c: Rgb) {
        let mut phase = 0.0;
        for w in pts.windows(2) {
            let (a, b) = (w[0], w[1]);
            let len = ((b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2)).sqrt();
            let mut s = 0.0;
            while s < len {
                let step = (dash - phase % dash).min(len - s);
                let on = ((phase / dash) as i64) % 2 == 0;
                if on {
                    let p = |t: f64| {
                        [
                            a[0] + (b[0] - a[0]) * t / len,
                            a[1] + (b[1] - a[1]) * t / len,
                        ]
                    };
                    self.line(p(s), p(s + step), width, c);
                }
                s += step;
                phase += step;
            }
        }
    }

    /// Draws `text` (upper-cased; unknown characters as blanks) with its top-left at (x, y).
    pub fn text(&mut self, x: f64, y: f64, text: &str, scale: u32, c: Rgb) {
        let s = f64::from(scale);
        for (k, ch) in text.chars().enumerate() {
            let rows = glyph(ch.to_ascii_uppercase());
            let ox = x + k as f64 * 6.0 * s;
            for (r, bits) in rows.iter().enumerate() {
                for col in 0..5 {
                    if bits >> (4 - col) & 1 == 1 {
                        for dy in 0..scale {
                            for dx in 0..scale {
                                self.set(
                                    (ox + f64::from(col * scale + dx)) as i64,
                                    (y + r as f64 * s + f64::from(dy)) as i64,
                                    c,
                                );
                            }
                        }
                    }
                }
            }
        }
    }

    pub fn text_width(text: &str, scale: u32) -> f64 {
        text.chars().count() as f64 * 6.0 * f64::from(scale)
    }

    pub fn write_png(&self, out: impl Write) -> Result<(), png::EncodingError> {
        let mut enc = png::Encoder::new(out, self.width, self.height);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        let mut w = enc.write_header()?;
        w.write_image_data(&self.pixels)?;
        w.finish()
    }
}

/// 5x7 glyphs, one byte per row, bit 4 = leftmost column.
fn glyph(c: char) -> [u8; 7] {
    match c {
        '0' => [0x0E, 0x11, 0x13, 0x15, 0x19, 0x11, 0x0E],
        '1' => [0x04, 0x0C, 0x04, 0x04, 0x04, 0x04, 0x0E],
        '2' => [0x0E, 0x11, 0x01, 0x02, 0x04, 0x08, 0x1F],
        '3' => [0x1F, 0x02, 0x04, 0x02, 0x01, 0x11, 0x0E],
        '4' => [0x02, 0x06, 0x0A, 0x12, 0x1F, 0x02, 0x02],
        '5' => [0x1F, 0x10, 0x1E, 0x01, 0x01, 0x11, 0x0E],
        '6' => [0x06, 0x08, 0x10, 0x1E, 0x11, 0x11, 0x0E],
        '7' => [0x1F, 0x01, 0x02, 0x04, 0x08, 0x08, 0x08],
        '8' => [0x0E, 0x11, 0x11, 0x0E, 0x11, 0x11, 0x0E],
        '9' => [0x0E, 0x11, 0x11, 0x0F, 0x01, 0x02, 0x0C],
        'A' => [0x0E, 0x11, 0x11, 0x1F, 0x11, 0x11, 0x11],
        'B' => [0x1E, 0x11, 0x11, 0x1E, 0x11, 0x11, 0x1E],
        'C' => [0x0E, 0x11, 0x10, 0x10, 0x10, 0x11, 0x0E],
        'D' => [0x1C, 0x12, 0x11, 0x11, 0x11, 0x12, 0x1C],
        'E' => [0x1F, 0x10, 0x10, 0x1E, 0x10, 0x10, 0x1F],
        'F' => [0x1F, 0x10, 0x10, 0x1E, 0x10, 0x10, 0x10],
        'G' => [0x0E, 0x11, 0x10, 0x17, 0x11, 0x11, 0x0F],
        'H' => [0x11, 0x11, 0x11, 0x1F, 0x11, 0x11, 0x11],
        'I' => [0x0E, 0x04, 0x04, 0x04, 0x04, 0x04, 0x0E],
        'J' => [0x07, 0x02, 0x02, 0x02, 0x02, 0x12, 0x0C],
        'K' => [0x11, 0x12, 0x14, 0x18, 0x14, 0x12, 0x11],
        'L' => [0x10, 0x10, 0x10, 0x10, 0x10, 0x10, 0x1F],
        'M' => [0x11, 0x1B, 0x15, 0x15, 0x11, 0x11, 0x11],
        'N' => [0x11, 0x11, 0x19, 0x15, 0x13, 0x11, 0x11],
        'O' => [0x0E, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0E],
        'P' => [0x1E, 0x11, 0x11, 0x1E, 0x10, 0x10, 0x10],
        'Q' => [0x0E, 0x11, 0x11, 0x11, 0x15, 0x12, 0x0D],
        'R' => [0x1E, 0x11, 0x11, 0x1E, 0x14, 0x12, 0x11],
        'S' => [0x0F, 0x10, 0x10, 0x0E, 0x01, 0x01, 0x1E],
        'T' => [0x1F, 0x04, 0x04, 0x04, 0x04, 0x04, 0x04],
        'U' => [0x11, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0E],
        'V' => [0x11, 0x11, 0x11, 0x11, 0x11, 0x0A, 0x04],
        'W' => [0x11, 0x11, 0x11, 0x15, 0x15, 0x15, 0x0A],
        'X' => [0x11, 0x11, 0x0A, 0x04, 0x0A, 0x11, 0x11],
        'Y' => [0x11, 0x11, 0x11, 0x0A, 0x04, 0x04, 0x04],
        'Z' => [0x1F, 0x01, 0x02, 0x04, 0x08, 0x10, 0x1F],
        '-' => [0x00, 0x00, 0x00, 0x1F, 0x00, 0x00, 0x00],
        '.' => [0x00, 0x00, 0x00, 0x00, 0x00, 0x0C, 0x0C],
        ',' => [0x00, 0x00, 0x00, 0x00, 0x0C, 0x04, 0x08],
        ':' => [0x00, 0x0C, 0x0C, 0x00, 0x0C, 0x0C, 0x00],
        '/' => [0x01, 0x01, 0x02, 0x04, 0x08, 0x10, 0x10],
        '(' => [0x02, 0x04, 0x08, 0x08, 0x08, 0x04, 0x02],
        ')' => [0x08, 0x04, 0x02, 0x02, 0x02, 0x04, 0x08],
        '_' => [0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x1F],
        '>' => [0x08, 0x04, 0x02, 0x01, 0x02, 0x04, 0x08],
        '\'' => [0x04, 0x04, 0x08, 0x00, 0x00, 0x00, 0x00],
        _ => [0; 7],
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shapes_cover_the_expected_pixels() {
        let mut c = Canvas::new(20, 20, [0, 0, 0]);
        c.fill_convex(
            &[[2.0, 2.0], [10.0, 2.0], [10.0, 10.0], [2.0, 10.0]],
            [255, 0, 0],
        );
        let at = |c: &Canvas, x: u32, y: u32| {
            let i = ((y * c.width + x) * 3) as usize;
            [c.pixels[i], c.pixels[i + 1], c.pixels[i + 2]]
        };
        assert_eq!(at(&c, 5, 5), [255, 0, 0]);
        assert_eq!(at(&c, 15, 15), [0, 0, 0]);
        c.line([0.0, 15.0], [19.0, 15.0], 2.0, [0, 255, 0]);
        assert_eq!(at(&c, 10, 15), [0, 255, 0]);
        assert_eq!(at(&c, 10, 18), [0, 0, 0]);
        let mut png = Vec::new();
        c.write_png(&mut png).expect("encode");
        assert_eq!(&png[1..4], b"PNG");
    }
}
