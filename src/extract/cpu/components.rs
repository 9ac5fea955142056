//! 8-connected components: the CPU twin of shaders/components.wgsl (Canny's hysteresis,
//! `hysteresis`, is built on them).
//!
//! The fast loop is `grid::component_runs` (runs joined by union-find, scan-order
//! labels). The shader labels each pixel with its component's root + 1, the root being
//! the component's first pixel in scan order; `dense_from_roots` turns those into the
//! fast loop's labels pixel by pixel (the definition; the GPU twin's frames do it run by
//! run, `Segmentation::from_roots`), so both twins hand the same labels on. The oracles
//! mirror the shaders' passes line for line.

/// Root labels (root pixel + 1, 0 outside) renumbered in place 1, 2, ... in the scan
/// order of the roots, which are their components' first pixels: `label_components`'
/// labels. Returns the number of components.
pub fn dense_from_roots(labels: &mut [u32]) -> usize {
    let mut count = 0;
    for i in 0..labels.len() {
        let l = labels[i] as usize;
        labels[i] = if l == 0 {
            0
        } else if l - 1 == i {
            count += 1;
            count as u32
        } else {
            // The root comes earlier in the scan and is renumbered already.
            labels[l - 1]
        };
    }
    count
}

/// shaders/components.wgsl run one invocation at a time, pass by pass: root + 1 of each
/// pixel's component, 0 outside. `inside` is the shader's test on the mask.
pub fn components_oracle(w: usize, h: usize, inside: impl Fn(usize) -> bool) -> Vec<u32> {
    // Halving the path as it goes, with atomicMin's writes.
    fn find(parent: &mut [u32], start: u32) -> u32 {
        let mut r = start;
        let mut q = parent[r as usize];
        while q != r {
            let g = parent[q as usize];
            if g != q {
                parent[r as usize] = parent[r as usize].min(g);
            }
            r = g;
            q = parent[r as usize];
        }
        r
    }
    fn unite(parent: &mut [u32], first: u32, second: u32) {
        let (mut a, mut b) = (first, second);
        loop {
            a = find(parent, a);
            b = find(parent, b);
            if a == b {
                return;
            }
            // atomicMin, one invocation at a time.
            if a < b {
                let old = parent[b as usize];
                parent[b as usize] = old.min(a);
                if old == b {
                    return;
                }
                b = old;
            } else {
                let old = parent[a as usize];
                parent[a as usize] = old.min(b);
                if old == a {
                    return;
                }
                a = old;
            }
        }
    }
    // init
    let mut parent: Vec<u32> = (0..(w * h) as u32).collect();
    // merge
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            if !inside(i) {
                continue;
            }
            if x > 0 && inside(i - 1) {
                unite(&mut parent, i as u32, i as u32 - 1);
            }
            if y > 0 {
                let up = i - w;
                if x > 0 && inside(up - 1) {
                    unite(&mut parent, i as u32, up as u32 - 1);
                }
                if inside(up) {
                    unite(&mut parent, i as u32, up as u32);
                }
                if x + 1 < w && inside(up + 1) {
                    unite(&mut parent, i as u32, up as u32 + 1);
                }
            }
        }
    }
    // flatten
    (0..w * h).map(|i| if inside(i) { find(&mut parent, i as u32) + 1 } else { 0 }).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::extract::cpu::classify::classify;
    use crate::extract::cpu::gradient::normal_gradient;
    use crate::extract::cpu::test_frames::stair_normals;
    use crate::grid::label_components;

    /// Masks with every shape the unions must get right: snakes, spirals, diagonals only,
    /// one-pixel gaps, and a noisy frame's edge classes.
    fn masks() -> Vec<(usize, usize, Vec<bool>)> {
        let mut out = Vec::new();
        let (w, h) = (53, 41);
        // A snake: rows joined alternately at the right and left ends.
        let snake = |x: usize, y: usize| y.is_multiple_of(2) || x == if y % 4 == 1 { w - 1 } else { 0 };
        out.push((w, h, (0..w * h).map(|i| snake(i % w, i / w)).collect()));
        // Diagonal lines, connected only through corners.
        out.push((w, h, (0..w * h).map(|i| (i % w + i / w) % 7 == 0 || (i % w + 2 * w - i / w) % 11 == 0).collect()));
        // Pseudo-random noise at about half density.
        out.push((w, h, (0..w * h).map(|i| crate::extract::cpu::ransac::hash(i as u32) % 100 < 55).collect()));
        let n = stair_normals();
        let class = classify(&normal_gradient(&n), 0.05, 0.1);
        out.push((n.width, n.height, class.data.iter().map(|&c| c != 0).collect()));
        out
    }

    #[test]
    fn fast_labels_are_the_oracle_s_roots_renumbered() {
        let mut total = 0;
        for (k, (w, h, mask)) in masks().into_iter().enumerate() {
            let (fast, count) = label_components(&mask, w, h);
            let mut roots = components_oracle(w, h, |i| mask[i]);
            // Each label is its component's first pixel + 1.
            for (i, &l) in roots.iter().enumerate() {
                assert!(
                    l == 0 || (l as usize - 1 <= i && roots[l as usize - 1] == l),
                    "mask {k}, pixel {i}: root label {l}"
                );
            }
            assert_eq!(dense_from_roots(&mut roots), count, "mask {k}");
            assert_eq!(roots, fast, "mask {k}");
            assert!(count >= 1, "mask {k} has no component");
            total += count;
        }
        assert!(total > 100, "{total} components in all, a labelling worth comparing");
    }
}
