//! A top-down picture of the map: polygons filled by label (higher ones over lower ones),
//! outlines black, foothold insets white, and the truth's tread outlines yellow when known.

use image::{Rgb, RgbImage};

use super::{Label, MapSnapshot};
use crate::ring::fill_rings;
use crate::sequence::Truth;
use crate::viz::draw_ring;

/// Largest side of the picture, pixels.
const MAX_SIDE: f64 = 1600.0;
const BACKGROUND: Rgb<u8> = Rgb([30, 30, 30]);

pub fn label_colour(label: Label, step: Option<u32>) -> Rgb<u8> {
    match label {
        Label::Floor => Rgb([130, 130, 130]),
        // Neighbouring treads alternate shades so that each one's outline reads.
        Label::Tread if step.unwrap_or(0).is_multiple_of(2) => Rgb([70, 130, 230]),
        Label::Tread => Rgb([40, 90, 180]),
        Label::Landing => Rgb([46, 180, 100]),
        Label::Riser => Rgb([220, 80, 60]),
        Label::Wall => Rgb([140, 70, 170]),
        Label::Slope => Rgb([230, 190, 20]),
    }
}

pub fn top_down(map: &MapSnapshot, truth: Option<&Truth>) -> RgbImage {
    let truth_rings: Vec<&Vec<[f64; 3]>> = truth
        .map(|t| t.polygons.iter().filter(|p| p.step.is_some() && p.label != "riser").map(|p| &p.boundary).collect())
        .unwrap_or_default();
    let all = map.polygons.iter().flat_map(|p| p.boundary.iter()).chain(truth_rings.iter().flat_map(|r| r.iter()));
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for p in all {
        for k in 0..2 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    if !(lo[0] < hi[0] && lo[1] < hi[1]) {
        return RgbImage::from_pixel(64, 64, BACKGROUND);
    }
    let margin = 0.1;
    let scale = (MAX_SIDE / (hi[0] - lo[0] + 2.0 * margin).max(hi[1] - lo[1] + 2.0 * margin)).min(400.0);
    // At least a pixel each way: a map kilometres long and a metre wide is one pixel high.
    let side = |extent: f64| (((extent + 2.0 * margin) * scale) as u32).max(1);
    let (w, h) = (side(hi[0] - lo[0]), side(hi[1] - lo[1]));
    let to_px = |p: &[f64; 3]| [(p[0] - lo[0] + margin) * scale, (hi[1] + margin - p[1]) * scale];
    let mut img = RgbImage::from_pixel(w, h, BACKGROUND);

    let mut order: Vec<_> = map.polygons.iter().collect();
    order.sort_by(|a, b| a.centroid[2].total_cmp(&b.centroid[2]));
    for p in &order {
        let rings: Vec<Vec<[f64; 2]>> =
            std::iter::once(&p.boundary).chain(&p.holes).map(|r| r.iter().map(to_px).collect()).collect();
        let colour = label_colour(p.label, p.step);
        for (i, inside) in fill_rings(&rings, w as usize, h as usize).into_iter().enumerate() {
            if inside {
                img.put_pixel(i as u32 % w, i as u32 / w, colour);
            }
        }
    }
    let ring_px = |r: &[[f64; 3]]| r.iter().map(&to_px).map(|[x, y]| (x as f32, y as f32)).collect::<Vec<_>>();
    for p in &order {
        for r in std::iter::once(&p.boundary).chain(&p.holes) {
            draw_ring(&mut img, &ring_px(r), Rgb([0, 0, 0]));
        }
        for inset in &p.insets {
            for r in std::iter::once(&inset.boundary).chain(&inset.holes) {
                draw_ring(&mut img, &ring_px(r), Rgb([235, 235, 235]));
            }
        }
    }
    for r in truth_rings {
        draw_ring(&mut img, &ring_px(r), Rgb([255, 220, 0]));
    }
    img
}
