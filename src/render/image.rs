//! [`Image`]: an 8-bit RGB raster with PNG output and side-by-side composition.

use std::path::Path;

use super::png;
use crate::{Error, Result};

/// An 8-bit RGB picture, row-major, top row first, 3 bytes per pixel.
///
/// `rgb.len()` is `width * height * 3` for every image this module makes; the fields are public
/// for cheap access, and the methods stay panic-free if a caller breaks that (missing pixels
/// read as `None` and are written black).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Image {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// The pixels: `rgb[3 * (y * width + x) + c]` is channel `c` of pixel (`x`, `y`).
    pub rgb: Vec<u8>,
}

impl Image {
    /// A `width` × `height` image filled with `background`.
    pub fn new(width: u32, height: u32, background: [u8; 3]) -> Image {
        let n = width as usize * height as usize;
        let mut rgb = Vec::with_capacity(n * 3);
        for _ in 0..n {
            rgb.extend_from_slice(&background);
        }
        Image { width, height, rgb }
    }

    /// Byte offset of pixel (`x`, `y`), or `None` outside the image.
    fn offset(&self, x: u32, y: u32) -> Option<usize> {
        if x >= self.width || y >= self.height {
            return None;
        }
        let i = 3 * (y as usize * self.width as usize + x as usize);
        (i + 3 <= self.rgb.len()).then_some(i)
    }

    /// The colour of pixel (`x`, `y`) (0, 0 is the top-left corner), or `None` outside.
    pub fn get(&self, x: u32, y: u32) -> Option<[u8; 3]> {
        let i = self.offset(x, y)?;
        Some([self.rgb[i], self.rgb[i + 1], self.rgb[i + 2]])
    }

    /// Sets pixel (`x`, `y`); does nothing outside the image.
    pub fn set(&mut self, x: u32, y: u32, color: [u8; 3]) {
        if let Some(i) = self.offset(x, y) {
            self.rgb[i..i + 3].copy_from_slice(&color);
        }
    }

    /// Mixes `color` into pixel (`x`, `y`) with opacity `alpha` (clamped to 0..=1); does nothing
    /// outside the image.
    pub fn blend(&mut self, x: u32, y: u32, color: [u8; 3], alpha: f32) {
        let a = alpha.clamp(0.0, 1.0);
        if !(a > 0.0) {
            return;
        }
        if let Some(i) = self.offset(x, y) {
            for (dst, &src) in self.rgb[i..i + 3].iter_mut().zip(&color) {
                let old = *dst as f32;
                *dst = (old + (src as f32 - old) * a).round() as u8;
            }
        }
    }

    /// The image as PNG bytes (8-bit RGB, stored deflate blocks; see [`png`]).
    pub fn to_png_bytes(&self) -> Vec<u8> {
        png::encode(self.width, self.height, &self.rgb)
    }

    /// Reads back a PNG written by [`Image::to_png_bytes`] (the subset [`png::decode`] reads).
    pub fn from_png_bytes(bytes: &[u8]) -> Result<Image> {
        let (width, height, rgb) = png::decode(bytes)?;
        Ok(Image { width, height, rgb })
    }

    /// Writes the image as a PNG file.
    ///
    /// The bytes go to a temporary file next to `path` (`.<name>.tmp-<pid>`), which is then
    /// renamed over `path`, so a reader never sees a half-written picture (a film player
    /// watching the folder, say). Failures, and an image with a zero dimension (which PNG
    /// cannot hold), are [`Error::Io`] naming `path`.
    pub fn save_png(&self, path: impl AsRef<Path>) -> Result<()> {
        let path = path.as_ref();
        let io = |source: std::io::Error| Error::Io {
            path: path.to_path_buf(),
            source,
        };
        if self.width == 0 || self.height == 0 {
            return Err(io(std::io::Error::new(
                std::io::ErrorKind::InvalidInput,
                format!(
                    "a PNG needs at least 1×1 pixels, this image is {}×{}",
                    self.width, self.height
                ),
            )));
        }
        let Some(name) = path.file_name() else {
            return Err(io(std::io::Error::new(
                std::io::ErrorKind::InvalidInput,
                "not a file path",
            )));
        };
        let mut tmp_name = std::ffi::OsString::from(".");
        tmp_name.push(name);
        tmp_name.push(format!(".tmp-{}", std::process::id()));
        let tmp = path.with_file_name(tmp_name);
        let result =
            std::fs::write(&tmp, self.to_png_bytes()).and_then(|()| std::fs::rename(&tmp, path));
        if let Err(e) = result {
            let _ = std::fs::remove_file(&tmp);
            return Err(io(e));
        }
        Ok(())
    }

    /// Reads a PNG file written by [`Image::save_png`] (see [`Image::from_png_bytes`]).
    pub fn load_png(path: impl AsRef<Path>) -> Result<Image> {
        let path = path.as_ref();
        let bytes = std::fs::read(path).map_err(|source| Error::Io {
            path: path.to_path_buf(),
            source,
        })?;
        Image::from_png_bytes(&bytes).map_err(|e| Error::input(format!("{}: {e}", path.display())))
    }

    /// Places `images` side by side, left to right, `gap` pixels apart, each centred
    /// vertically on a canvas as tall as the tallest, the rest filled with `background`
    /// (comparison panels: before/after, template/fit, ...). No images give a 0 × 0 image.
    pub fn hstack(images: &[Image], gap: u32, background: [u8; 3]) -> Image {
        if images.is_empty() {
            return Image::new(0, 0, background);
        }
        let width = images
            .iter()
            .fold(0u32, |w, im| w.saturating_add(im.width))
            .saturating_add(gap.saturating_mul(images.len() as u32 - 1));
        let height = images.iter().map(|im| im.height).max().unwrap_or(0);
        let mut out = Image::new(width, height, background);
        let mut x0 = 0u32;
        for im in images {
            let y0 = (height - im.height) / 2;
            let row = 3 * im.width as usize;
            for y in 0..im.height {
                let Some(src) = im.offset(0, y) else { continue };
                let Some(dst) = out.offset(x0, y0 + y) else {
                    continue;
                };
                let n = row.min(im.rgb.len() - src);
                out.rgb[dst..dst + n].copy_from_slice(&im.rgb[src..src + n]);
            }
            x0 += im.width + gap;
        }
        out
    }
}
