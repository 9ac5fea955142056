//! Debug pictures of every stage of one frame.

use std::path::Path;

use image::{Rgb, RgbImage};
use nalgebra::Point3;

use super::{Extraction, Polygon};
use crate::types::Intrinsics;
use crate::viz;

/// Writes 1_depth, 2_smoothed, 3_normals, 4_edges, 5_regions and 6_polygons PNGs into
/// `dir` (2-4 only when the stages kept their images: `Extractor::keep_images` on the GPU).
pub fn write_stage_images(dir: &Path, frame: &Extraction, intr: &Intrinsics) -> image::ImageResult<()> {
    let (stages, polygons) = (&frame.stages, &frame.polygons.polygons);
    std::fs::create_dir_all(dir)?;
    let (w, h) = (intr.width, intr.height);
    let (near, far) = viz::percentile_range(frame.depth.data.iter().filter(|&&d| d > 0.0).map(|&d| d as f64));
    let depth = viz::depth_image(w, h, |i| frame.depth.data[i] as f64, near, far);
    depth.save(dir.join("1_depth.png"))?;
    if let Some(images) = &stages.images {
        viz::depth_image(w, h, |i| images.smoothed.data[i] as f64, near, far).save(dir.join("2_smoothed.png"))?;
        viz::normal_image(w, h, &images.normals.interleaved().data).save(dir.join("3_normals.png"))?;
        // Canny edges white, the rest of the closed boundary grey.
        RgbImage::from_fn(w, h, |u, v| {
            let i = (v * w + u) as usize;
            match (images.canny.data[i], images.boundary.data[i]) {
                (1, _) => Rgb([255, 255, 255]),
                (_, 1) => Rgb([110, 110, 110]),
                _ => Rgb([0, 0, 0]),
            }
        })
        .save(dir.join("4_edges.png"))?;
    }
    RgbImage::from_fn(w, h, |u, v| viz::label_colour(stages.labels.data[(v * w + u) as usize]))
        .save(dir.join("5_regions.png"))?;
    polygon_image(&depth, polygons, intr).save(dir.join("6_polygons.png"))
}

/// The polygons, filled in their id colours over the dimmed depth, outlined and with holes;
/// those not steppable only hatched (every third diagonal), so a glance tells them apart.
pub fn polygon_image(depth: &RgbImage, polygons: &[Polygon], intr: &Intrinsics) -> RgbImage {
    let mut img = viz::dimmed(depth);
    let pixel = |v: &[f64; 3]| {
        let (u, v) = intr.project(&Point3::new(v[0], v[1], v[2]));
        (u as f32, v as f32)
    };
    for p in polygons {
        let colour = viz::label_colour(p.id + 1);
        let ring: Vec<(f32, f32)> = p.boundary.iter().map(pixel).collect();
        // Filled the way eval scores it: pixel centres inside the outline and outside the holes.
        let inside = p.image_mask(intr);
        let width = intr.width as usize;
        let shown = |i: usize| p.footing.is_steppable() || (i % width + i / width).is_multiple_of(3);
        let filled = (img.pixels_mut().zip(&inside).enumerate()).filter(|&(i, (_, inside))| *inside && shown(i));
        for (_, (a, _)) in filled {
            for c in 0..3 {
                a.0[c] = ((a.0[c] as u16 + colour.0[c] as u16) / 2) as u8;
            }
        }
        viz::draw_ring(&mut img, &ring, colour);
        for hole in &p.holes {
            viz::draw_ring(&mut img, &hole.iter().map(pixel).collect::<Vec<_>>(), Rgb([255, 255, 255]));
        }
    }
    img
}
