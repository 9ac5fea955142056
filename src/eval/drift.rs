//! The drift estimate frame by frame against the drift a synthetic walk injected: a CSV and a
//! plot (`polymap replay SEQ --drift-trace STEM`).

use std::path::Path;

use font8x8::legacy::BASIC_LEGACY;
use image::{Rgb, RgbImage};
use imageproc::drawing::{draw_filled_rect_mut, draw_line_segment_mut};
use imageproc::rect::Rect;

use crate::map::{MapUpdate, PolygonMap, drift};
use crate::sequence::Truth;

/// The drift after one frame: x, y, z (m) and yaw (rad), estimated with its standard
/// deviations, and injected where the truth says.
#[derive(Clone, Debug, PartialEq)]
pub struct DriftSample {
    pub frame: usize,
    pub estimated: [f64; 4],
    pub sigma: [f64; 4],
    pub injected: Option<[f64; 4]>,
    /// Directions the frame's planes measured (bits of `map::drift`).
    pub observed: u8,
    /// A step of the odometry was taken into the drift at this frame.
    pub step: bool,
}

/// The drift as components: the shift, then the turn about z.
fn components(t: &nalgebra::Isometry3<f64>) -> [f64; 4] {
    let v = t.translation.vector;
    [v.x, v.y, v.z, t.rotation.euler_angles().2]
}

pub fn sample(frame: usize, map: &PolygonMap, update: &MapUpdate, truth: Option<&Truth>) -> DriftSample {
    let d = &map.drift;
    DriftSample {
        frame,
        estimated: components(&d.transform()),
        sigma: d.sigmas(),
        injected: truth.map(|t| components(&t.drift_at(frame))),
        observed: update.registration.as_ref().map_or(0, |r| r.observed),
        step: update.odometry_step,
    }
}

pub fn write_csv(samples: &[DriftSample], path: &Path) -> std::io::Result<()> {
    let mut text = String::from(
        "frame,x_mm,y_mm,z_mm,yaw_deg,sigma_x_mm,sigma_y_mm,sigma_z_mm,sigma_yaw_deg,\
         injected_x_mm,injected_y_mm,injected_z_mm,injected_yaw_deg,observed,step\n",
    );
    let scaled = |v: [f64; 4]| [v[0] * 1e3, v[1] * 1e3, v[2] * 1e3, v[3].to_degrees()];
    for s in samples {
        let [x, y, z, yaw] = scaled(s.estimated);
        let [sx, sy, sz, syaw] = scaled(s.sigma);
        let injected = s.injected.map_or(",,,".into(), |v| {
            let [a, b, c, d] = scaled(v);
            format!("{a:.3},{b:.3},{c:.3},{d:.4}")
        });
        let observed: String = [(drift::X, 'x'), (drift::Y, 'y'), (drift::Z, 'z'), (drift::YAW, 'w')]
            .iter()
            .filter(|(bit, _)| s.observed & bit != 0)
            .map(|(_, c)| *c)
            .collect();
        text += &format!(
            "{},{x:.3},{y:.3},{z:.3},{yaw:.4},{sx:.3},{sy:.3},{sz:.3},{syaw:.4},{injected},{observed},{}\n",
            s.frame,
            u8::from(s.step)
        );
    }
    std::fs::write(path, text)
}

const PANEL_W: u32 = 720;
const PANEL_H: u32 = 170;
const MARGIN_L: u32 = 70;
const MARGIN_T: u32 = 22;
const MARGIN_B: u32 = 14;

/// Four panels, x, y and z in mm and yaw in degrees over the frames: injected drift black,
/// the estimate blue with its 2-sigma band light blue, steps of the odometry taken in red.
pub fn plot(samples: &[DriftSample], title: &str) -> RgbImage {
    let mut img = RgbImage::from_pixel(PANEL_W, PANEL_H * 4 + 20, Rgb([255, 255, 255]));
    text(&mut img, 8, 4, title, Rgb([0, 0, 0]));
    let names = ["x (mm)", "y (mm)", "z (mm)", "yaw (deg)"];
    let scale = [1e3, 1e3, 1e3, 180.0 / std::f64::consts::PI];
    let n = samples.len().max(2) - 1;
    for (p, name) in names.iter().enumerate() {
        let top = 20 + PANEL_H * p as u32;
        let value = |v: f64| v * scale[p];
        let mut lo = f64::INFINITY;
        let mut hi = f64::NEG_INFINITY;
        for s in samples {
            let e = value(s.estimated[p]);
            let b = 2.0 * value(s.sigma[p]);
            for v in [e - b, e + b].into_iter().chain(s.injected.map(|t| value(t[p]))) {
                lo = lo.min(v);
                hi = hi.max(v);
            }
        }
        if !(hi - lo > 1e-9) {
            (lo, hi) = (lo.min(0.0) - 1.0, hi.max(0.0) + 1.0);
        }
        let (x0, x1) = (MARGIN_L as f32, (PANEL_W - 10) as f32);
        let (y0, y1) = ((top + MARGIN_T) as f32, (top + PANEL_H - MARGIN_B) as f32);
        let px = |k: usize| x0 + (x1 - x0) * k as f32 / n as f32;
        let py = |v: f64| y1 - (y1 - y0) * ((v - lo) / (hi - lo)) as f32;
        for s in samples.iter().filter(|s| s.step) {
            draw_line_segment_mut(&mut img, (px(s.frame), y0), (px(s.frame), y1), Rgb([230, 60, 60]));
        }
        for (k, s) in samples.iter().enumerate() {
            let (e, b) = (value(s.estimated[p]), 2.0 * value(s.sigma[p]));
            let (a, z) = (py(e + b).max(y0), py(e - b).min(y1));
            let w = ((x1 - x0) / n as f32).ceil().max(1.0) as u32;
            if z > a {
                draw_filled_rect_mut(
                    &mut img,
                    Rect::at(px(k) as i32, a as i32).of_size(w, (z - a).max(1.0) as u32),
                    Rgb([205, 222, 245]),
                );
            }
        }
        let axis = Rgb([120, 120, 120]);
        draw_line_segment_mut(&mut img, (x0, y0), (x0, y1), axis);
        draw_line_segment_mut(&mut img, (x0, y1), (x1, y1), axis);
        if lo < 0.0 && hi > 0.0 {
            draw_line_segment_mut(&mut img, (x0, py(0.0)), (x1, py(0.0)), Rgb([220, 220, 220]));
        }
        for w in samples.windows(2) {
            let (a, b) = (&w[0], &w[1]);
            if let (Some(ta), Some(tb)) = (a.injected, b.injected) {
                draw_line_segment_mut(
                    &mut img,
                    (px(a.frame), py(value(ta[p]))),
                    (px(b.frame), py(value(tb[p]))),
                    Rgb([0, 0, 0]),
                );
            }
            let (ea, eb) = (value(a.estimated[p]), value(b.estimated[p]));
            draw_line_segment_mut(&mut img, (px(a.frame), py(ea)), (px(b.frame), py(eb)), Rgb([30, 90, 220]));
        }
        text(&mut img, 8, top + 4, name, Rgb([0, 0, 0]));
        text(&mut img, 4, top + MARGIN_T, &format!("{hi:.1}"), axis);
        text(&mut img, 4, top + PANEL_H - MARGIN_B - 8, &format!("{lo:.1}"), axis);
        text(&mut img, PANEL_W - 120, top + 4, &format!("frames 0-{n}"), axis);
    }
    img
}

/// Draws `s` in 8 x 8 glyphs with its top left at (x, y).
fn text(img: &mut RgbImage, x: u32, y: u32, s: &str, colour: Rgb<u8>) {
    for (i, c) in s.chars().enumerate() {
        let Some(glyph) = BASIC_LEGACY.get(c as usize) else { continue };
        for (row, bits) in glyph.iter().enumerate() {
            for col in 0..8 {
                let (px, py) = (x + 8 * i as u32 + col, y + row as u32);
                if bits & (1 << col) != 0 && px < img.width() && py < img.height() {
                    img.put_pixel(px, py, colour);
                }
            }
        }
    }
}
