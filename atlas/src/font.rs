//! A 5×7 bitmap font of `A–Z` and `0–9`, enough to label checkerboard cells so that rotations and
//! mirrorings of a texture are visible on a render (most of these glyphs are not symmetric).

/// Glyph width and height in font pixels.
pub(crate) const GLYPH: (u32, u32) = (5, 7);

/// The rows of `c` (top first, bit 4 = leftmost column), or `None` for an unsupported character.
pub(crate) fn glyph(c: char) -> Option<[u8; 7]> {
    let rows: [&str; 7] = match c.to_ascii_uppercase() {
        'A' => ["01110", "10001", "10001", "11111", "10001", "10001", "10001"],
        'B' => ["11110", "10001", "10001", "11110", "10001", "10001", "11110"],
        'C' => ["01110", "10001", "10000", "10000", "10000", "10001", "01110"],
        'D' => ["11110", "10001", "10001", "10001", "10001", "10001", "11110"],
        'E' => ["11111", "10000", "10000", "11110", "10000", "10000", "11111"],
        'F' => ["11111", "10000", "10000", "11110", "10000", "10000", "10000"],
        'G' => ["01110", "10001", "10000", "10111", "10001", "10001", "01111"],
        'H' => ["10001", "10001", "10001", "11111", "10001", "10001", "10001"],
        'I' => ["01110", "00100", "00100", "00100", "00100", "00100", "01110"],
        'J' => ["00111", "00010", "00010", "00010", "00010", "10010", "01100"],
        'K' => ["10001", "10010", "10100", "11000", "10100", "10010", "10001"],
        'L' => ["10000", "10000", "10000", "10000", "10000", "10000", "11111"],
        'M' => ["10001", "11011", "10101", "10101", "10001", "10001", "10001"],
        'N' => ["10001", "10001", "11001", "10101", "10011", "10001", "10001"],
        'O' => ["01110", "10001", "10001", "10001", "10001", "10001", "01110"],
        'P' => ["11110", "10001", "10001", "11110", "10000", "10000", "10000"],
        'Q' => ["01110", "10001", "10001", "10001", "10101", "10010", "01101"],
        'R' => ["11110", "10001", "10001", "11110", "10100", "10010", "10001"],
        'S' => ["01111", "10000", "10000", "01110", "00001", "00001", "11110"],
        'T' => ["11111", "00100", "00100", "00100", "00100", "00100", "00100"],
        'U' => ["10001", "10001", "10001", "10001", "10001", "10001", "01110"],
        'V' => ["10001", "10001", "10001", "10001", "10001", "01010", "00100"],
        'W' => ["10001", "10001", "10001", "10101", "10101", "10101", "01010"],
        'X' => ["10001", "10001", "01010", "00100", "01010", "10001", "10001"],
        'Y' => ["10001", "10001", "10001", "01010", "00100", "00100", "00100"],
        'Z' => ["11111", "00001", "00010", "00100", "01000", "10000", "11111"],
        '0' => ["01110", "10001", "10011", "10101", "11001", "10001", "01110"],
        '1' => ["00100", "01100", "00100", "00100", "00100", "00100", "01110"],
        '2' => ["01110", "10001", "00001", "00010", "00100", "01000", "11111"],
        '3' => ["11111", "00010", "00100", "00010", "00001", "10001", "01110"],
        '4' => ["00010", "00110", "01010", "10010", "11111", "00010", "00010"],
        '5' => ["11111", "10000", "11110", "00001", "00001", "10001", "01110"],
        '6' => ["00110", "01000", "10000", "11110", "10001", "10001", "01110"],
        '7' => ["11111", "00001", "00010", "00100", "01000", "01000", "01000"],
        '8' => ["01110", "10001", "10001", "01110", "10001", "10001", "01110"],
        '9' => ["01110", "10001", "10001", "01111", "00001", "00010", "01100"],
        _ => return None,
    };
    Some(rows.map(|r| u8::from_str_radix(r, 2).expect("glyph rows are binary")))
}

/// Calls `plot(x, y)` for every lit pixel of `text` drawn with its top-left corner at `(x0, y0)`,
/// each font pixel a `scale × scale` block, one blank font column between glyphs. Unsupported
/// characters leave a blank.
pub(crate) fn draw_text(text: &str, x0: u32, y0: u32, scale: u32, mut plot: impl FnMut(u32, u32)) {
    for (i, c) in text.chars().enumerate() {
        let Some(rows) = glyph(c) else { continue };
        let gx = x0 + i as u32 * (GLYPH.0 + 1) * scale;
        for (r, bits) in rows.iter().enumerate() {
            for col in 0..GLYPH.0 {
                if bits >> (GLYPH.0 - 1 - col) & 1 == 1 {
                    for dy in 0..scale {
                        for dx in 0..scale {
                            plot(gx + col * scale + dx, y0 + r as u32 * scale + dy);
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
    fn every_label_character_has_a_distinct_glyph() {
        let chars: Vec<char> = ('A'..='Z').chain('0'..='9').collect();
        let glyphs: Vec<[u8; 7]> = chars.iter().map(|&c| glyph(c).unwrap()).collect();
        for i in 0..glyphs.len() {
            assert!(glyphs[i].iter().all(|&r| r < 32));
            for j in i + 1..glyphs.len() {
                assert_ne!(glyphs[i], glyphs[j], "{} and {} look the same", chars[i], chars[j]);
            }
        }
        assert!(glyph('?').is_none());
    }

    #[test]
    fn draw_text_plots_scaled_glyphs() {
        let mut lit = Vec::new();
        draw_text("1", 10, 20, 2, |x, y| lit.push((x, y)));
        // '1' has 1 + 2 + 4·1 + 3 = 10 lit font pixels → 10 · 4 screen pixels.
        assert_eq!(lit.len(), 10 * 4);
        assert!(lit.contains(&(14, 20)) && lit.contains(&(15, 21)), "top of the stem");
    }
}
