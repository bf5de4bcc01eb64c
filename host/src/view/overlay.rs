//! The viewer's panel: lines of 8x8 bitmap text (the `font8x8` crate) on a
//! darkened box in the window's top-left corner. Drawn on the presented
//! pixels only, never on the image `S` saves.

use font8x8::UnicodeFonts;

/// Pixel height of a line (8 of glyph, 2 of spacing).
pub const LINE: usize = 10;
pub const WHITE: u32 = 0x00ff_ffff;
pub const RED: u32 = 0x00ff_6060;
pub const YELLOW: u32 = 0x00ff_e070;

/// Draws `lines` (text and colour) into a `width`-pixel-wide buffer of
/// 0x00RRGGBB pixels, on a box that halves what is behind it; returns the
/// box's size (width, height) in pixels. Characters the font lacks are
/// drawn as `?`; what does not fit is clipped.
pub fn draw(buffer: &mut [u32], width: usize, lines: &[(String, u32)]) -> (usize, usize) {
    if width == 0 || lines.is_empty() {
        return (0, 0);
    }
    let height = buffer.len() / width;
    let chars = lines.iter().map(|(t, _)| t.chars().count()).max().unwrap_or(0);
    let (box_w, box_h) = ((chars * 8 + 8).min(width), (lines.len() * LINE + 6).min(height));
    for y in 0..box_h {
        for p in &mut buffer[y * width..y * width + box_w] {
            *p = (*p >> 1) & 0x007f_7f7f;
        }
    }
    for (row, (text, colour)) in lines.iter().enumerate() {
        let top = 4 + row * LINE;
        for (col, c) in text.chars().enumerate() {
            let glyph = font8x8::BASIC_FONTS.get(c).or_else(|| font8x8::BASIC_FONTS.get('?')).unwrap_or([0; 8]);
            let left = 4 + col * 8;
            for (dy, bits) in glyph.iter().enumerate() {
                for dx in 0..8 {
                    let (x, y) = (left + dx, top + dy);
                    if bits & (1 << dx) != 0 && x < box_w && y < box_h {
                        buffer[y * width + x] = *colour;
                    }
                }
            }
        }
    }
    (box_w, box_h)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn text_lands_inside_its_box_and_the_rest_is_untouched() {
        let (w, h) = (64, 40);
        let mut buf = vec![0x0080_8080u32; w * h];
        let (bw, bh) = draw(&mut buf, w, &[("Hi".into(), WHITE), ("?".into(), RED)]);
        assert_eq!((bw, bh), (2 * 8 + 8, 2 * LINE + 6));
        assert!(buf.contains(&WHITE) && buf.contains(&RED));
        for y in 0..h {
            for x in 0..w {
                let p = buf[y * w + x];
                if x >= bw || y >= bh {
                    assert_eq!(p, 0x0080_8080, "outside the box at ({x}, {y})");
                } else {
                    assert!(p == 0x0040_4040 || p == WHITE || p == RED, "inside: darkened or text, got {p:06x}");
                }
            }
        }
    }

    #[test]
    fn a_panel_wider_than_the_window_is_clipped() {
        let mut buf = vec![0u32; 16 * 4];
        let (bw, bh) = draw(&mut buf, 16, &[("a long line of text".into(), WHITE)]);
        assert_eq!((bw, bh), (16, 4));
    }
}
