//! Borders: where two regions meet, each pixel goes to the nearer of their planes. A
//! crease whose edge line broke lets one region run past it onto its neighbour's face, as
//! far as that face stays within the inlier distance of its plane (at a 35 deg crease, a
//! band a centimetre wide); growth cannot give the band back, as it takes only pixels
//! that no region holds.

use super::Segmentation;
use super::joins::JOIN_ANGLE_COS;
use crate::extract::cloud::Cloud;
use crate::extract::cpu::ransac::PlaneFit;
use crate::grid::for_each_set;

impl Segmentation {
    /// Moves pixels between touching accepted regions (`accepted[r]`) whose planes are
    /// more than a join's angle apart (closer planes are one surface's pieces, or so
    /// nearly parallel that noise would choose): a pixel goes to a 4-neighbour's region
    /// when its point lies nearer that region's plane than its own, and within `dist` of
    /// it, unless that would cut its own region in two around it (`keeps_connected`).
    /// Wave by wave from the borders, in scan order within a wave; every move brings a
    /// pixel nearer its region's plane, so the waves end. Returns how many pixels moved.
    pub fn settle_borders(&mut self, fits: &[Option<PlaneFit>], accepted: &[bool], cloud: &Cloud, dist: f32) -> usize {
        let (w, h) = (self.labels.width, self.labels.height);
        let plane = |l: u32| (l != 0).then(|| fits[l as usize - 1].filter(|_| accepted[l as usize - 1])).flatten();
        let neighbours = |i: usize| {
            let (u, v) = (i % w, i / w);
            [(u > 0).then(|| i - 1), (u + 1 < w).then(|| i + 1), (v > 0).then(|| i - w), (v + 1 < h).then(|| i + w)]
                .into_iter()
                .flatten()
        };
        // The region pixel i moves to, if any.
        let nearer = |labels: &[u32], i: usize| -> Option<u32> {
            let own = plane(labels[i])?;
            let p = cloud.point(i)?;
            let mut best = (own.distance(&p), None);
            for l in neighbours(i).map(|j| labels[j]).filter(|&l| l != labels[i]) {
                let Some(other) = plane(l).filter(|o| o.normal.dot(&own.normal).abs() < JOIN_ANGLE_COS) else {
                    continue;
                };
                let d = other.distance(&p);
                if d < dist as f64 && d < best.0 {
                    best = (d, Some(l));
                }
            }
            best.1.filter(|_| keeps_connected(labels, w, h, i))
        };
        let labels = &mut self.labels.data;
        let mut wave = border_pixels(labels, w);
        wave.retain(|&i| plane(labels[i as usize]).is_some());
        let (mut queued, mut moved) = (vec![false; w * h], Vec::new());
        let mut total = 0;
        while !wave.is_empty() {
            for &i in &wave {
                if let Some(l) = nearer(labels, i as usize) {
                    labels[i as usize] = l;
                    moved.push(i);
                }
            }
            total += moved.len();
            // The next wave: the neighbours of what moved.
            wave.clear();
            for i in moved.drain(..) {
                for j in neighbours(i as usize) {
                    if !queued[j] && labels[j] != 0 {
                        queued[j] = true;
                        wave.push(j as u32);
                    }
                }
            }
            wave.iter().for_each(|&j| queued[j as usize] = false);
            wave.sort_unstable();
        }
        if total > 0 {
            self.pixels_from_labels();
        }
        total
    }
}

/// The pixels of a `w`-wide label image with a 4-neighbour in another region (0 is none),
/// ascending: marked a whole row at a time with comparisons that vectorise, then visited
/// by `for_each_set`.
fn border_pixels(labels: &[u32], w: usize) -> Vec<u32> {
    let mut beside = vec![0u8; labels.len()];
    let differ = |a: &u32, b: &u32| u8::from((a != b) & (*a != 0) & (*b != 0));
    for (row, marks) in labels.chunks_exact(w).zip(beside.chunks_exact_mut(w)) {
        let pairs = || row.iter().zip(&row[1..]);
        marks.iter_mut().zip(pairs()).for_each(|(m, (a, b))| *m |= differ(a, b));
        marks[1..].iter_mut().zip(pairs()).for_each(|(m, (a, b))| *m |= differ(a, b));
    }
    let mut across = vec![0u8; w];
    for v in 1..labels.len() / w {
        let pairs = labels[(v - 1) * w..v * w].iter().zip(&labels[v * w..(v + 1) * w]);
        across.iter_mut().zip(pairs).for_each(|(d, (a, b))| *d = differ(a, b));
        for row in [v - 1, v] {
            beside[row * w..(row + 1) * w].iter_mut().zip(&across).for_each(|(m, d)| *m |= d);
        }
    }
    let mut out = Vec::new();
    for_each_set(&beside, |i| out.push(i as u32));
    out
}

/// Whether pixel i's region stays in one piece around it without it: the pixels of its
/// label among its 8 neighbours make at most one 8-connected group (Yokoi's connectivity
/// number, "Topological properties in digitized binary pictures", 1973, is 0 or 1).
fn keeps_connected(labels: &[u32], w: usize, h: usize, i: usize) -> bool {
    let (u, v, label) = ((i % w) as i64, (i / w) as i64, labels[i]);
    let other = |du: i64, dv: i64| {
        let (x, y) = (u + du, v + dv);
        !(x >= 0 && y >= 0 && x < w as i64 && y < h as i64 && labels[(y * w as i64 + x) as usize] == label)
    };
    // Not the region's: E, NE, N, NW, W, SW, S, SE, the 4-neighbours at even places.
    let ring =
        [other(1, 0), other(1, -1), other(0, -1), other(-1, -1), other(-1, 0), other(-1, 1), other(0, 1), other(1, 1)];
    let not = |k: usize| ring[k % 8];
    [0, 2, 4, 6].into_iter().filter(|&k| not(k) && !(not(k + 1) && not(k + 2))).count() <= 1
}
