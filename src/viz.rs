//! Pictures for people: depth in colour, label images, side-by-side panels.

use image::{Rgb, RgbImage};

const INVALID: Rgb<u8> = Rgb([0, 0, 0]);

/// Depth in metres (0 = invalid) as turbo colours over [near, far].
pub fn depth_image(width: u32, height: u32, depth_m: impl Fn(usize) -> f64, near: f64, far: f64) -> RgbImage {
    RgbImage::from_fn(width, height, |u, v| {
        let d = depth_m((v * width + u) as usize);
        if !(d > 0.0) {
            return INVALID;
        }
        let c = colorous::TURBO.eval_continuous(((d - near) / (far - near)).clamp(0.0, 1.0));
        Rgb([c.r, c.g, c.b])
    })
}

/// Depth units of a frame as colours, the range taken from the frame's own 1st..99th percentile.
pub fn depth_units_image(width: u32, height: u32, units: &[u16], depth_scale: f64) -> RgbImage {
    let (near, far) = percentile_range(units.iter().filter(|&&d| d != 0).map(|&d| d as f64 * depth_scale));
    depth_image(width, height, |i| units[i] as f64 * depth_scale, near, far)
}

/// (1st, 99th) percentile of the values, or (0, 1) if there are none.
pub fn percentile_range(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let mut v: Vec<f64> = values.collect();
    if v.is_empty() {
        return (0.0, 1.0);
    }
    v.sort_by(f64::total_cmp);
    let at = |q: f64| v[((v.len() - 1) as f64 * q) as usize];
    let (lo, hi) = (at(0.01), at(0.99));
    if hi > lo { (lo, hi) } else { (lo, lo + 1e-3) }
}

/// A stable, well-spread colour for label or id `i` (0 = black).
pub fn label_colour(i: u32) -> Rgb<u8> {
    if i == 0 {
        return INVALID;
    }
    let c = colorous::SINEBOW.eval_continuous((i as f64 * 0.618_033_988_75).fract());
    Rgb([c.r, c.g, c.b])
}

pub fn label_image(width: u32, height: u32, labels: &[u16]) -> RgbImage {
    RgbImage::from_fn(width, height, |u, v| label_colour(labels[(v * width + u) as usize] as u32))
}

/// Images side by side, separated by a 4-pixel gap, on one canvas.
pub fn side_by_side(images: &[&RgbImage]) -> RgbImage {
    let gap = 4;
    let width = images.iter().map(|i| i.width()).sum::<u32>() + gap * (images.len() as u32).saturating_sub(1);
    let height = images.iter().map(|i| i.height()).max().unwrap_or(0);
    let mut out = RgbImage::from_pixel(width, height, Rgb([255, 255, 255]));
    let mut x = 0;
    for img in images {
        image::imageops::replace(&mut out, *img, x as i64, 0);
        x += img.width() + gap;
    }
    out
}

/// Unit normals as colours ((n + 1) / 2 per channel), black where there is none.
pub fn normal_image(width: u32, height: u32, normals: &[[f32; 3]]) -> RgbImage {
    RgbImage::from_fn(width, height, |u, v| {
        let n = normals[(v * width + u) as usize];
        if n == [0.0; 3] {
            return INVALID;
        }
        let c = |x: f32| ((x + 1.0) * 127.5).clamp(0.0, 255.0) as u8;
        Rgb([c(n[0]), c(n[1]), c(n[2])])
    })
}

/// A binary mask: white where set.
pub fn mask_image(width: u32, height: u32, mask: &[u8]) -> RgbImage {
    RgbImage::from_fn(width, height, |u, v| if mask[(v * width + u) as usize] != 0 { Rgb([255; 3]) } else { INVALID })
}

/// Draws a closed ring of pixel coordinates.
pub fn draw_ring(img: &mut RgbImage, ring: &[(f32, f32)], colour: Rgb<u8>) {
    for i in 0..ring.len() {
        let (a, b) = (ring[i], ring[(i + 1) % ring.len()]);
        imageproc::drawing::draw_line_segment_mut(img, a, b, colour);
    }
}

/// Dims an image towards grey, to draw over it.
pub fn dimmed(img: &RgbImage) -> RgbImage {
    let mut out = img.clone();
    out.pixels_mut().for_each(|p| p.0.iter_mut().for_each(|c| *c = (*c as u16 * 2 / 5 + 40) as u8));
    out
}
