// SPDX-License-Identifier: MIT
//! A small raster plotter for the PNG charts the commands write (no plotting dependency): axes
//! with labelled ticks, polylines and a legend, text in a 5x7 bitmap font drawn here.

/// An RGB8 image being drawn on.
pub(crate) struct Canvas {
    pub(crate) width: u32,
    pub(crate) height: u32,
    pub(crate) rgb: Vec<u8>,
}

/// 5x7 glyphs, one byte per row (top first), bit 4 the leftmost column.
fn glyph(c: char) -> [u8; 7] {
    match c.to_ascii_uppercase() {
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
        '.' => [0, 0, 0, 0, 0, 0x0C, 0x0C],
        ',' => [0, 0, 0, 0, 0x0C, 0x04, 0x08],
        '-' => [0, 0, 0, 0x1F, 0, 0, 0],
        '+' => [0, 0x04, 0x04, 0x1F, 0x04, 0x04, 0],
        '%' => [0x18, 0x19, 0x02, 0x04, 0x08, 0x13, 0x03],
        '(' => [0x02, 0x04, 0x08, 0x08, 0x08, 0x04, 0x02],
        ')' => [0x08, 0x04, 0x02, 0x02, 0x02, 0x04, 0x08],
        '|' => [0x04; 7],
        '/' => [0x01, 0x01, 0x02, 0x04, 0x08, 0x10, 0x10],
        '>' => [0x08, 0x04, 0x02, 0x01, 0x02, 0x04, 0x08],
        '=' => [0, 0, 0x1F, 0, 0x1F, 0, 0],
        ':' => [0, 0x0C, 0x0C, 0, 0x0C, 0x0C, 0],
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
        'Y' => [0x11, 0x11, 0x0A, 0x04, 0x04, 0x04, 0x04],
        'Z' => [0x1F, 0x01, 0x02, 0x04, 0x08, 0x10, 0x1F],
        _ => [0; 7],
    }
}

/// Pixels per font pixel.
const FONT_SCALE: u32 = 2;
/// Width of one character cell, pixels.
pub(crate) const CHAR_W: u32 = 6 * FONT_SCALE;

impl Canvas {
    pub(crate) fn new(width: u32, height: u32, background: [u8; 3]) -> Self {
        Self { width, height, rgb: background.repeat((width * height) as usize) }
    }

    pub(crate) fn set(&mut self, x: i64, y: i64, c: [u8; 3]) {
        if x >= 0 && y >= 0 && (x as u32) < self.width && (y as u32) < self.height {
            let i = 3 * (y as usize * self.width as usize + x as usize);
            self.rgb[i..i + 3].copy_from_slice(&c);
        }
    }

    /// A line from (x0, y0) to (x1, y1), `thickness` pixels wide.
    pub(crate) fn line(&mut self, (x0, y0): (f64, f64), (x1, y1): (f64, f64), c: [u8; 3], thickness: i64) {
        let steps = ((x1 - x0).abs().max((y1 - y0).abs()).ceil() as i64).max(1);
        for s in 0..=steps {
            let t = s as f64 / steps as f64;
            let (x, y) = ((x0 + t * (x1 - x0)).round() as i64, (y0 + t * (y1 - y0)).round() as i64);
            for dy in 0..thickness {
                for dx in 0..thickness {
                    self.set(x + dx - thickness / 2, y + dy - thickness / 2, c);
                }
            }
        }
    }

    /// `text` with its top-left corner at (x, y).
    pub(crate) fn text(&mut self, x: i64, y: i64, text: &str, c: [u8; 3]) {
        for (i, ch) in text.chars().enumerate() {
            let rows = glyph(ch);
            for (r, bits) in rows.iter().enumerate() {
                for col in 0..5 {
                    if bits & (0x10 >> col) != 0 {
                        for sy in 0..FONT_SCALE {
                            for sx in 0..FONT_SCALE {
                                self.set(x + i as i64 * i64::from(CHAR_W) + i64::from(col * FONT_SCALE + sx), y + (r as u32 * FONT_SCALE + sy) as i64, c);
                            }
                        }
                    }
                }
            }
        }
    }
}

/// One series of a line chart.
pub(crate) struct Series<'a> {
    pub(crate) label: &'a str,
    pub(crate) color: [u8; 3],
    pub(crate) points: Vec<(f64, f64)>,
}

/// A "nice" tick step for a span: 1, 2 or 5 times a power of ten, about `ticks` of them.
fn tick_step(span: f64, ticks: f64) -> f64 {
    let raw = span / ticks;
    let p = 10f64.powf(raw.log10().floor());
    [1.0, 2.0, 5.0, 10.0].into_iter().map(|m| m * p).find(|s| *s >= raw).unwrap_or(10.0 * p)
}

fn label(v: f64, step: f64) -> String {
    if step >= 1.0 { format!("{v:.0}") } else if step >= 0.1 { format!("{v:.1}") } else { format!("{v:.2}") }
}

/// A line chart (x and y from 0) as PNG bytes.
pub(crate) fn line_chart_png(title: &str, x_label: &str, y_label: &str, series: &[Series<'_>]) -> anyhow::Result<Vec<u8>> {
    let (w, h) = (800u32, 500u32);
    let (left, right, top, bottom) = (80.0, 30.0, 50.0, 60.0);
    let mut c = Canvas::new(w, h, [255, 255, 255]);
    let finite = |v: &f64| v.is_finite();
    let x_max = series.iter().flat_map(|s| s.points.iter().map(|p| p.0)).filter(finite).fold(0.0f64, f64::max).max(1e-9);
    let y_max = series.iter().flat_map(|s| s.points.iter().map(|p| p.1)).filter(finite).fold(0.0f64, f64::max).max(1e-9) * 1.1;
    let y_min = series.iter().flat_map(|s| s.points.iter().map(|p| p.1)).filter(finite).fold(0.0f64, f64::min) * 1.1;
    let (pw, ph) = (f64::from(w) - left - right, f64::from(h) - top - bottom);
    let px = |x: f64| left + x / x_max * pw;
    let py = |y: f64| top + (y_max - y) / (y_max - y_min) * ph;
    let grey = [200, 200, 200];
    let black = [0, 0, 0];
    let xs = tick_step(x_max, 8.0);
    let mut x = 0.0;
    while x <= x_max + 1e-9 {
        c.line((px(x), top), (px(x), top + ph), grey, 1);
        let l = label(x, xs);
        c.text(px(x) as i64 - (l.len() as i64 * i64::from(CHAR_W)) / 2, (top + ph + 8.0) as i64, &l, black);
        x += xs;
    }
    let ys = tick_step(y_max - y_min, 6.0);
    let mut y = (y_min / ys).ceil() * ys;
    while y <= y_max + 1e-9 {
        c.line((left, py(y)), (left + pw, py(y)), if y.abs() < 1e-12 { [120, 120, 120] } else { grey }, 1);
        let l = label(y, ys);
        c.text(left as i64 - 8 - l.len() as i64 * i64::from(CHAR_W), py(y) as i64 - 7, &l, black);
        y += ys;
    }
    c.line((left, top), (left, top + ph), black, 2);
    c.line((left, top + ph), (left + pw, top + ph), black, 2);
    c.text(left as i64, 14, title, black);
    c.text((left + pw / 2.0) as i64 - (x_label.len() as i64 * i64::from(CHAR_W)) / 2, (top + ph + 32.0) as i64, x_label, black);
    c.text(8, (top - 22.0) as i64, y_label, black);
    for (i, s) in series.iter().enumerate() {
        let pts: Vec<(f64, f64)> = s.points.iter().copied().filter(|p| p.0.is_finite() && p.1.is_finite()).collect();
        for pair in pts.windows(2) {
            c.line((px(pair[0].0), py(pair[0].1)), (px(pair[1].0), py(pair[1].1)), s.color, 3);
        }
        for p in &pts {
            c.line((px(p.0) - 3.0, py(p.1)), (px(p.0) + 3.0, py(p.1)), s.color, 3);
        }
        let ly = top as i64 + 10 + 22 * i as i64;
        let lx = (left + pw) as i64 - 30 * i64::from(CHAR_W);
        c.line((lx as f64, ly as f64 + 7.0), (lx as f64 + 24.0, ly as f64 + 7.0), s.color, 4);
        c.text(lx + 32, ly, s.label, s.color);
    }
    let image = webfusion_core::ColorImage::new(w, h, c.rgb)?;
    Ok(webfusion_core::codec::png::encode_rgb8(&image)?)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ticks_are_round_numbers() {
        assert_eq!(tick_step(8.0, 8.0), 1.0);
        assert_eq!(tick_step(37.0, 6.0), 10.0);
        assert_eq!(tick_step(0.9, 6.0), 0.2);
    }

    #[test]
    fn a_chart_draws_its_series_and_text() {
        let s = [Series { label: "MEAN", color: [0, 0, 255], points: vec![(0.0, 1.0), (4.0, 10.0)] }];
        let png = line_chart_png("ERROR", "DEPTH (M)", "MM", &s).expect("a chart");
        let image = webfusion_core::codec::png::decode_rgb8(&png, 800, 500).expect("a PNG of the chart's size");
        let blue = image.rgb8.chunks(3).filter(|p| p == &[0, 0, 255]).count();
        let black = image.rgb8.chunks(3).filter(|p| p == &[0, 0, 0]).count();
        assert!(blue > 500, "the series is drawn: {blue} px");
        assert!(black > 1000, "axes and text are drawn: {black} px");
        let mut c = Canvas::new(20, 20, [0, 0, 0]);
        c.text(0, 0, "8", [255, 255, 255]);
        assert_eq!(c.rgb.chunks(3).filter(|p| p == &[255, 255, 255]).count(), 17 * 4, "'8' has 17 lit font pixels, each 2x2");
    }
}
