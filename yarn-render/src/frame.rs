//! A drawn image on the CPU: [`Frame`], how much of it is yarn
//! ([`Frame::coverage`] against [`BACKGROUND`]) and writing it as PNG. This
//! room must not know how the image was drawn: nothing of wgpu, the camera
//! or the yarn.

use std::path::Path;

use crate::RenderError;

/// The background colour, RGBA; [`Frame::coverage`] counts every other
/// pixel as yarn.
pub const BACKGROUND: [u8; 4] = [242, 244, 248, 255];

/// A rendered RGBA image.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Frame {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Row-major RGBA, 8 bits a channel.
    pub rgba: Vec<u8>,
}

impl Frame {
    /// The fraction of pixels that are not background: how much of the frame
    /// the yarn covers.
    pub fn coverage(&self) -> f64 {
        let pixels = self.rgba.chunks_exact(4);
        let total = pixels.len().max(1);
        let yarn = pixels
            .filter(|pixel| pixel.iter().zip(BACKGROUND).any(|(&channel, background)| channel.abs_diff(background) > 8))
            .count();
        yarn as f64 / total as f64
    }

    /// Save as PNG.
    ///
    /// # Errors
    /// When the file cannot be written.
    pub fn save_png(&self, path: impl AsRef<Path>) -> Result<(), RenderError> {
        image::save_buffer(path, &self.rgba, self.width, self.height, image::ExtendedColorType::Rgba8)?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn coverage_counts_non_background_pixels() {
        let mut frame = Frame { width: 2, height: 2, rgba: BACKGROUND.repeat(4) };
        assert_eq!(frame.coverage(), 0.0);
        frame.rgba[4..8].copy_from_slice(&[200, 80, 60, 255]);
        assert_eq!(frame.coverage(), 0.25);
    }
}
