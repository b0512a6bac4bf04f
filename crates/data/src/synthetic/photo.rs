//! Surface textures cut from real photographs: the edge, texture and shading statistics of real
//! scenes, which the procedural patterns lack.
//!
//! Design decision: a photo texture is still a deterministic function of the continuous
//! left-view point (the renderer's contract, see the module above): the photograph is mapped onto
//! the surface by a random similarity (scale, rotation, offset), sampled bilinearly and mirrored
//! at its borders, so both views see the same colour at corresponding points. The photographs of
//! a folder are decoded once per process and shared ([`PhotoLibrary::of_folder`]).

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, PoisonError};

use dgstereo_core::{Error, Result};

use crate::image::load_rgb;

/// The photographs of one folder, decoded (`CHW`, 0..255).
#[derive(Debug)]
pub struct PhotoLibrary {
    /// The images, in file-name order.
    pub photos: Vec<crate::image::RgbImage>,
}

/// File extensions read as photographs.
const EXTENSIONS: [&str; 4] = ["png", "jpg", "jpeg", "ppm"];

/// Smallest side of a photograph worth sampling.
const MIN_SIDE: usize = 16;

impl PhotoLibrary {
    /// The photographs of `dir` (`.png`, `.jpg`, `.jpeg`, `.ppm`), decoded once per process.
    ///
    /// # Errors
    /// The folder cannot be read, holds no photograph, or a photograph does not decode or is
    /// smaller than 16 pixels on a side (the message names the file).
    pub fn of_folder(dir: &Path) -> Result<Arc<Self>> {
        static LOADED: Mutex<Option<HashMap<PathBuf, Arc<PhotoLibrary>>>> = Mutex::new(None);
        let mut loaded = LOADED.lock().unwrap_or_else(PoisonError::into_inner);
        if let Some(library) = loaded.get_or_insert_with(HashMap::new).get(dir) {
            return Ok(library.clone());
        }
        let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
            .map_err(|e| Error::io(dir, e))?
            .filter_map(|entry| entry.ok().map(|e| e.path()))
            .filter(|p| {
                p.extension()
                    .and_then(|e| e.to_str())
                    .is_some_and(|e| EXTENSIONS.contains(&e.to_ascii_lowercase().as_str()))
            })
            .collect();
        files.sort();
        if files.is_empty() {
            return Err(Error::format(dir, "holds no photograph (.png, .jpg, .jpeg or .ppm) for photo textures"));
        }
        let mut photos = Vec::with_capacity(files.len());
        for file in &files {
            let photo = load_rgb(file)?;
            if photo.width.min(photo.height) < MIN_SIDE {
                return Err(Error::format(file, format!("a photo texture needs at least {MIN_SIDE} pixels on a side")));
            }
            photos.push(photo);
        }
        let library = Arc::new(Self { photos });
        loaded.get_or_insert_with(HashMap::new).insert(dir.to_path_buf(), library.clone());
        Ok(library)
    }
}

/// A photograph mapped onto a surface: left-view point `p` shows the photograph's pixel
/// `offset + scale · R(angle) · p`, mirrored at the photograph's borders.
#[derive(Clone, Debug)]
pub struct PhotoTexture {
    /// The library and the index of the photograph in it.
    pub library: Arc<PhotoLibrary>,
    /// Which photograph.
    pub index: usize,
    /// Photograph pixels per view pixel.
    pub scale: f64,
    /// Rotation in radians.
    pub angle: f64,
    /// Where the view's origin falls in the photograph.
    pub offset: [f64; 2],
}

impl PartialEq for PhotoTexture {
    fn eq(&self, other: &Self) -> bool {
        Arc::ptr_eq(&self.library, &other.library)
            && (self.index, self.scale, self.angle, self.offset)
                == (other.index, other.scale, other.angle, other.offset)
    }
}

/// `v` mirrored into `0..n - 1` (period `2(n - 1)`).
fn mirror(v: f64, n: usize) -> f64 {
    let last = (n - 1) as f64;
    let period = 2.0 * last;
    let m = v.rem_euclid(period);
    if m > last { period - m } else { m }
}

impl PhotoTexture {
    /// The colour at left-view point `(x, y)`, in 0..255.
    #[inline]
    pub fn at(&self, x: f64, y: f64) -> [f32; 3] {
        let photo = &self.library.photos[self.index];
        let (w, h) = (photo.width, photo.height);
        let (s, c) = self.angle.sin_cos();
        let u = mirror(self.offset[0] + self.scale * (c * x - s * y), w);
        let v = mirror(self.offset[1] + self.scale * (s * x + c * y), h);
        let (x0, y0) = ((u.floor() as usize).min(w - 1), (v.floor() as usize).min(h - 1));
        let (x1, y1) = ((x0 + 1).min(w - 1), (y0 + 1).min(h - 1));
        let (fx, fy) = ((u - x0 as f64) as f32, (v - y0 as f64) as f32);
        let plane = w * h;
        let mut out = [0.0f32; 3];
        for (ch, o) in out.iter_mut().enumerate() {
            let p = |xx: usize, yy: usize| photo.data[ch * plane + yy * w + xx];
            let top = p(x0, y0) + fx * (p(x1, y0) - p(x0, y0));
            let bottom = p(x0, y1) + fx * (p(x1, y1) - p(x0, y1));
            *o = top + fy * (bottom - top);
        }
        out
    }
}
