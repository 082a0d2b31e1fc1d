//! Read-back images: PNG output and the pixel counts of the crack test.

use std::path::Path;

use anyhow::{Context as _, Result};

use crate::vk::CLEAR_RGBA;

/// The crack test's flag colour: back faces are drawn pure red, unlit.
pub const FLAG_RGBA: [u8; 4] = [255, 0, 0, 255];

/// Pixels of exactly the flag colour.
pub fn count_flagged(rgba: &[u8]) -> u64 {
    rgba.chunks_exact(4).filter(|p| *p == FLAG_RGBA).count() as u64
}

/// Pixels that are not background (within one step of the clear colour per channel).
pub fn count_model(rgba: &[u8]) -> u64 {
    let bg = CLEAR_RGBA.map(|c| (c * 255.0).round() as i32);
    rgba.chunks_exact(4).filter(|p| (0..4).any(|k| (p[k] as i32 - bg[k]).abs() > 1)).count() as u64
}

/// Writes RGBA8 pixels (rows from the top) as a PNG.
pub fn write_png(path: &Path, width: u32, height: u32, rgba: &[u8]) -> Result<()> {
    let file = std::fs::File::create(path).with_context(|| format!("cannot create {}", path.display()))?;
    let mut encoder = png::Encoder::new(std::io::BufWriter::new(file), width, height);
    encoder.set_color(png::ColorType::Rgba);
    encoder.set_depth(png::BitDepth::Eight);
    let mut writer = encoder.write_header()?;
    writer.write_image_data(rgba)?;
    writer.finish()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_flag_and_model_pixels() {
        let bg = CLEAR_RGBA.map(|c| (c * 255.0).round() as u8);
        let mut img = Vec::new();
        img.extend_from_slice(&bg);
        img.extend_from_slice(&FLAG_RGBA);
        img.extend_from_slice(&[200, 190, 170, 255]);
        img.extend_from_slice(&[254, 0, 0, 255]);
        assert_eq!(count_flagged(&img), 1);
        assert_eq!(count_model(&img), 3);
    }
}
