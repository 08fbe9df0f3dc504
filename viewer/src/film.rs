//! Images to PNG files, written atomically (temporary file in the target directory,
//! fsync, rename), so a reader never sees a partial PNG.

use std::io::Write;
use std::path::{Path, PathBuf};

#[derive(Debug, thiserror::Error)]
#[error("{}: {message}", path.display())]
pub struct FilmError {
    pub path: PathBuf,
    pub message: String,
}

/// 8-bit RGB bytes of an image of linear values in 0..=1 (clamped, rounded).
pub fn to_rgb8(rgb: &[[f32; 3]]) -> Vec<u8> {
    rgb.iter()
        .flat_map(|c| c.map(|v| (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8))
        .collect()
}

/// PNG bytes of a `width`×`height` image.
pub fn encode_png(width: u32, height: u32, rgb: &[[f32; 3]]) -> Result<Vec<u8>, String> {
    if rgb.len() != width as usize * height as usize {
        return Err(format!(
            "expected {} pixels for {width}x{height}, found {}",
            width as usize * height as usize,
            rgb.len()
        ));
    }
    let img = image::RgbImage::from_raw(width, height, to_rgb8(rgb))
        .ok_or_else(|| "pixel buffer does not match the image size".to_string())?;
    let mut out = std::io::Cursor::new(Vec::new());
    img.write_to(&mut out, image::ImageFormat::Png)
        .map_err(|e| e.to_string())?;
    Ok(out.into_inner())
}

/// Writes the image as a PNG at `path`, atomically.
pub fn save_png(path: &Path, width: u32, height: u32, rgb: &[[f32; 3]]) -> Result<(), FilmError> {
    let err = |message: String| FilmError {
        path: path.to_path_buf(),
        message,
    };
    let bytes = encode_png(width, height, rgb).map_err(err)?;
    let name = path
        .file_name()
        .ok_or_else(|| err("expected a file name".into()))?;
    let mut tmp_name = std::ffi::OsString::from(".");
    tmp_name.push(name);
    tmp_name.push(format!(".tmp-{}", std::process::id()));
    let tmp = path.with_file_name(tmp_name);
    let result = (|| {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(&bytes)?;
        f.sync_all()?;
        std::fs::rename(&tmp, path)
    })();
    if let Err(e) = result {
        let _ = std::fs::remove_file(&tmp);
        return Err(err(e.to_string()));
    }
    Ok(())
}
