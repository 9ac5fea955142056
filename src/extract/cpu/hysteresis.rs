//! Canny's hysteresis: the CPU twin of shaders/hysteresis.wgsl. A weak edge pixel is kept
//! when its 8-connected component of edge pixels holds a strong one; the components are
//! `grid::component_runs`' (the GPU labels them with shaders/components.wgsl first).

use super::classify::classify;
use super::components::components_oracle;
use crate::extract::params::Gradient;
use crate::grid::{Grid, component_runs};

/// Hysteresis: 1 for strong pixels and the weak ones 8-connected to them through weak pixels.
pub fn hysteresis(class: &Grid<u8>) -> Grid<u8> {
    let (w, h) = (class.width, class.height);
    let candidate: Vec<bool> = class.data.iter().map(|&c| c != 0).collect();
    let (runs, count) = component_runs(&candidate, w, h);
    let mut strong = vec![false; count + 1];
    for r in &runs {
        strong[r.label as usize] |= class.data[r.start..r.end].contains(&2);
    }
    let mut out = vec![0u8; w * h];
    for r in runs.iter().filter(|r| strong[r.label as usize]) {
        out[r.start..r.end].fill(1);
    }
    Grid { width: w, height: h, data: out }
}

/// shaders/hysteresis.wgsl after components.wgsl, one invocation at a time.
pub fn hysteresis_oracle(class: &Grid<u8>) -> Grid<u8> {
    let labels = components_oracle(class.width, class.height, |i| class.data[i] != 0);
    // mark_strong
    let mut strong = vec![0u8; labels.len()];
    for (i, &c) in class.data.iter().enumerate() {
        if c == 2 {
            strong[labels[i] as usize - 1] = 1;
        }
    }
    // keep
    let data = labels.iter().map(|&l| if l != 0 { strong[l as usize - 1] } else { 0 }).collect();
    Grid { width: class.width, height: class.height, data }
}

/// Canny edges: 1 where the magnitude is a local maximum across the edge and joins a
/// pixel at or above `high` through pixels at or above `low` (8-connected).
pub fn canny(grad: &Gradient, low: f32, high: f32) -> Grid<u8> {
    hysteresis(&classify(grad, low, high))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::extract::cpu::classify::classify;
    use crate::extract::cpu::gradient::normal_gradient;
    use crate::extract::cpu::test_frames::stair_normals;

    #[test]
    fn fast_hysteresis_is_the_oracle() {
        let n = stair_normals();
        let class = classify(&normal_gradient(&n), 0.05, 0.1);
        let fast = hysteresis(&class);
        assert_eq!(fast, hysteresis_oracle(&class));
        // Some weak pixels are kept and some dropped, so both ways are compared.
        let weak = |keep: u8| class.data.iter().zip(&fast.data).filter(|&(&c, &e)| c == 1 && e == keep).count();
        assert!(weak(1) > 100 && weak(0) > 100, "weak kept {}, weak dropped {}", weak(1), weak(0));
    }
}
