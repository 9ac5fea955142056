use super::growth::*;
use super::joins::*;
use super::runs::*;
use super::scan::*;
use super::*;
use crate::extract::cpu::components::{components_oracle, dense_from_roots};
use crate::extract::cpu::ransac::hash;
use crate::grid::{for_each_set, rows_around};
use nalgebra::{Rotation3, Vector3};

#[test]
fn regions_from_roots_are_the_densely_numbered_components() {
    // Masks of random specks and blobs, the roots as the shader leaves them; twice
    // each, so the kept numbers of the first pass must not leak into the second.
    let (w, h) = (61, 37);
    for seed in 0..8u32 {
        let mask: Vec<bool> =
            (0..w * h).map(|i| hash((i as u32 / 3) ^ seed.wrapping_mul(0x9e37_79b9)) % 100 < 25 + seed * 3).collect();
        let roots = Grid { width: w, height: h, data: components_oracle(w, h, |i| mask[i]) };
        let mut dense = roots.data.clone();
        let count = dense_from_roots(&mut dense);
        assert!(count > 5, "seed {seed}: {count} components");
        for min_pixels in [1, 4] {
            let want = Segmentation::from_labels(Grid { width: w, height: h, data: dense.clone() }, count, min_pixels);
            for pass in 0..2 {
                let got = Segmentation::from_roots(&roots.data, roots.width, min_pixels);
                assert_eq!(got.labels, want.labels, "seed {seed}, min {min_pixels}, pass {pass}: labels");
                assert_eq!(got.pixels, want.pixels, "seed {seed}, min {min_pixels}, pass {pass}: pixels");
            }
        }
    }
}

/// Growth's plane of one pixel, the oracle of `plane_row`: the label of the accepted region
/// around pixel i = (u, v) whose plane is nearest to the pixel's point, within `dist` (the
/// lowest label on a tie); None for none or an invalid pixel.
fn nearest_plane(
    nearby: &NearbyRegions,
    fits: &[Option<PlaneFit>],
    cloud: &Cloud,
    dist: f32,
    i: usize,
    u: usize,
    v: usize,
) -> Option<u32> {
    let p = cloud.point(i)?;
    let mut best: Option<(f64, u32)> = None;
    for &l in nearby.around(u, v) {
        let Some(fit) = &fits[l as usize - 1] else { continue };
        let e = fit.distance(&p);
        if e < dist as f64 && best.is_none_or(|(b, bl)| e < b || (e == b && l < bl)) {
            best = Some((e, l));
        }
    }
    best.map(|(_, l)| l)
}

/// Growth as its definition says it, the oracle: each wave a sweep of the whole image
/// that labels an unlabelled pixel when a 4-neighbour had its plane's label after the
/// wave before.
fn grow_by_sweeps(seg: &Segmentation, fits: &[Option<PlaneFit>], cloud: &Cloud, dist: f32, waves: u32) -> Vec<u32> {
    let (w, h) = (seg.labels.width, seg.labels.height);
    let accepted = vec![true; fits.len()];
    let nearby = NearbyRegions::new(seg, &accepted, waves as usize);
    let mut labels = seg.labels.data.clone();
    for _ in 0..waves {
        let before = labels.clone();
        for (i, label) in labels.iter_mut().enumerate() {
            let (u, v) = (i % w, i / w);
            let touching =
                [(u > 0, i.wrapping_sub(1)), (u + 1 < w, i + 1), (v > 0, i.wrapping_sub(w)), (v + 1 < h, i + w)];
            if before[i] == 0
                && let Some(l) = nearest_plane(&nearby, fits, cloud, dist, i, u, v)
                && touching.iter().any(|&(inside, j)| inside && before[j] == l)
            {
                *label = l;
            }
        }
    }
    labels
}

/// A w x h camera of focal length f pixels, centred, depth in millimetres.
fn centred_camera(w: usize, h: usize, f: f64) -> crate::types::Intrinsics {
    let (width, height) = (w as u32, h as u32);
    crate::types::Intrinsics { width, height, fx: f, fy: f, cx: w as f64 / 2.0, cy: h as f64 / 2.0, depth_scale: 0.001 }
}

/// Labels and pixel lists written from runs in parallel (`write_runs`, through
/// `from_labels`) and lists rebuilt from the labels (`pixels_from_labels`) are the
/// pixel-by-pixel ones, on 1, 2 and 16 threads, on an image of several tasks and bands.
#[test]
fn lists_and_labels_written_in_parallel_are_the_pixel_by_pixel_ones() {
    let (w, h, regions) = (300usize, 220usize, 7u32);
    let mut data = vec![0u32; w * h];
    let (mut i, mut k) = (0, 0u32);
    while i < data.len() {
        let end = (i + 1 + (hash(k) % 150) as usize).min(data.len());
        data[i..end].fill(hash(k ^ 0x77) % (regions + 1));
        (i, k) = (end, k + 1);
    }
    // Numbered in scan order, as `from_labels` wants them.
    let mut number = vec![0u32; regions as usize + 1];
    let mut count = 0;
    for l in data.iter_mut().filter(|l| **l != 0) {
        if number[*l as usize] == 0 {
            count += 1;
            number[*l as usize] = count;
        }
        *l = number[*l as usize];
    }
    let mut want = vec![Vec::new(); count as usize];
    for (i, &l) in data.iter().enumerate().filter(|(_, l)| **l != 0) {
        want[l as usize - 1].push(i as u32);
    }
    assert!(data.len() > 3 * MIN_WRITE_PIXELS && h > 3 * RUN_BAND_ROWS && count == regions);
    for threads in [1, 2, 16] {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| {
            let labels = Grid { width: w, height: h, data: data.clone() };
            let mut seg = Segmentation::from_labels(labels, count as usize, 1);
            assert_eq!(seg.labels.data, data, "{threads} threads");
            assert_eq!(seg.pixels, want, "{threads} threads");
            seg.pixels.iter_mut().for_each(|list| list.extend([7, 8, 9]));
            seg.pixels_from_labels();
            assert_eq!(seg.pixels, want, "{threads} threads, lists from the labels");
        });
    }
}

#[test]
fn growth_is_the_wave_by_wave_sweep() {
    // Three planes (1/depth linear in the pixel), noisy, with dropouts; regions are the
    // planes' pixels less a band along their borders and specks of no region. Growth
    // from them, 0 to 6 waves deep, with inlier distances that take most of the band
    // or little of it.
    let (w, h) = (90usize, 70usize);
    let intr = centred_camera(w, h, 60.0);
    let piece = |u: usize, v: usize| {
        if v > 40 + u / 6 {
            0
        } else if u < 50 {
            1
        } else {
            2
        }
    };
    let inverse_depth = [[0.45, 0.0, 0.004], [0.9, -0.002, 0.0], [0.2, 0.003, 0.001]];
    // An image of f(pixel index, u, v).
    fn image<T>(w: usize, h: usize, f: impl Fn(usize, usize, usize) -> T) -> Grid<T> {
        Grid { width: w, height: h, data: (0..w * h).map(|i| f(i, i % w, i / w)).collect() }
    }
    let depth = image(w, h, |i, u, v| {
        let [a, b, c] = inverse_depth[piece(u, v)];
        let noise = (hash(i as u32) % 1000) as f32 * 4e-6 - 2e-3;
        if hash(i as u32 ^ 0x55).is_multiple_of(53) { 0.0 } else { 1.0 / (a + b * u as f32 + c * v as f32) + noise }
    });
    let cloud = Cloud::new(&depth, &intr);
    // A pixel's region: its piece's, unless within 4 pixels of another piece or a speck.
    let labels = image(w, h, |i, u, v| {
        let near_other = (u.saturating_sub(4)..(u + 5).min(w))
            .any(|x| (v.saturating_sub(4)..(v + 5).min(h)).any(|y| piece(x, y) != piece(u, v)));
        if near_other || hash(i as u32 ^ 0xaa).is_multiple_of(40) { 0 } else { piece(u, v) as u32 + 1 }
    });
    for dist in [0.003f32, 0.02] {
        for waves in 0..=6 {
            let mut seg = Segmentation::from_labels(labels.clone(), 3, 1);
            assert_eq!(seg.pixels.len(), 3);
            let fits = super::super::cpu::ransac::fit_planes(&seg.points(&[0, 1, 2], &cloud), 32, 0.004);
            let want = grow_by_sweeps(&seg, &fits, &cloud, dist, waves);
            // On 2 and 16 threads, the links and the waves found by tasks of rows side by side.
            for threads in [2, 16] {
                let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
                let mut on_blocks = Segmentation::from_labels(labels.clone(), 3, 1);
                pool.install(|| on_blocks.grow(&fits, &[true; 3], &cloud, dist, waves));
                assert_eq!(on_blocks.labels.data, want, "{dist}, {waves} waves, {threads} threads");
            }
            rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap().install(|| {
                seg.grow(&fits, &[true; 3], &cloud, dist, waves);
            });
            assert_eq!(seg.labels.data, want, "inlier distance {dist}, {waves} waves");
            let grown = want.iter().zip(&labels.data).filter(|(a, b)| a != b).count();
            let left = want.iter().zip(&depth.data).filter(|&(&l, &z)| l == 0 && z != 0.0).count();
            // Some growth, and while the bands are not yet crossed, pixels left to grow into.
            assert!(waves == 0 || grown > 100, "{dist}, {waves} waves: grew {grown}");
            assert!(waves > 2 || left > 100, "{dist}, {waves} waves: left {left}");
            let listed: usize = seg.pixels.iter().map(Vec::len).sum();
            assert_eq!(listed, want.iter().filter(|&&l| l != 0).count(), "pixel lists follow the labels");
        }
    }
}

#[test]
fn merge_tail_sorts_as_a_full_sort_does() {
    // Ascending heads of every length to 40, tails of 0 to 9 values not in the head, in
    // hashed order (the fills) or ascending (a joined region's pixels).
    for n in 0..40u32 {
        for k in 0..10u32 {
            let all: Vec<u32> = (0..n + k).map(|i| i * 3 + hash(i * 7 + n) % 3).collect();
            let check = |ascending: bool| {
                let (mut head, mut tail) = (Vec::new(), Vec::new());
                for (i, &x) in all.iter().enumerate() {
                    if hash(i as u32 + 101 * n + 7 * k) % (n + k) < k { tail.push(x) } else { head.push(x) }
                }
                if !ascending {
                    tail.sort_by_key(|&x| hash(x));
                }
                let sorted = head.len();
                head.extend(tail);
                let mut want = head.clone();
                want.sort();
                merge_tail(&mut head, sorted);
                assert_eq!(head, want, "{n} + {k}, ascending tail {ascending}");
            };
            check(true);
            check(false);
        }
    }
}

#[test]
fn sampled_points_are_every_stride_th_pixel_s() {
    // Two regions side by side, one of 1200 pixels with dropouts, one of 40.
    let (w, h) = (50usize, 30usize);
    let intr = centred_camera(w, h, 40.0);
    let labels: Vec<u32> = (0..w * h)
        .map(|i| {
            if i % w < 40 {
                1
            } else if i / w < 4 {
                2
            } else {
                0
            }
        })
        .collect();
    let seg = Segmentation::from_labels(Grid { width: w, height: h, data: labels }, 2, 1);
    let depth = Grid {
        width: w,
        height: h,
        data: (0..w * h).map(|i| if hash(i as u32).is_multiple_of(9) { 0.0 } else { 1.0 + i as f32 * 1e-4 }).collect(),
    };
    let cloud = Cloud::new(&depth, &intr);
    let (all, sampled) = (seg.points(&[0, 1], &cloud), seg.sampled_points(&[0, 1], &cloud, 100));
    let every = |r: usize, k: usize| -> Vec<[f32; 3]> {
        seg.pixels[r].iter().step_by(k).filter_map(|&i| cloud.point(i as usize)).collect()
    };
    assert_eq!(seg.pixels[0].len(), 1200);
    assert_eq!(all.points[all.ranges[0].clone()], every(0, 1)[..], "all of the large region");
    // 1200 pixels to at most 100: every 12th.
    assert_eq!(sampled.points[sampled.ranges[0].clone()], every(0, 12)[..]);
    assert!(sampled.ranges[0].len() < 100 && sampled.ranges[0].len() > 80, "dropouts left out");
    // The small region whole, after the large one's sample.
    assert_eq!(sampled.points[sampled.ranges[1].clone()], every(1, 1)[..]);
    assert_eq!(sampled.ranges[1].start, sampled.ranges[0].end);
    // In parts of 100 pixels (cut inside rows and runs) on two threads, or in one.
    let pool = rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap();
    let parts = pool.install(|| seg.point_parts(0, &cloud, 100));
    assert_eq!(parts.len(), 12);
    assert_eq!(parts.concat(), every(0, 1), "the points in order, dropouts left out");
    assert_eq!(seg.point_parts(1, &cloud, 100), vec![every(1, 1)], "a small region one part");
}

#[test]
fn bounding_box_is_the_pixels_extent() {
    // Pixels of every density, rows with one pixel, many runs or whole, on widths with
    // rows long and short.
    for (w, h) in [(1, 4), (5, 3), (37, 29), (300, 7)] {
        for keep in [1, 2, 5, 40] {
            let pixels: Vec<u32> = (0..(w * h) as u32).filter(|&i| hash(i).is_multiple_of(keep)).collect();
            if pixels.is_empty() {
                continue;
            }
            let (us, vs) = (|| pixels.iter().map(|&i| i as usize % w), || pixels.iter().map(|&i| i as usize / w));
            let want = [us().min().unwrap(), vs().min().unwrap(), us().max().unwrap(), vs().max().unwrap()];
            assert_eq!(bounding_box(&pixels, w), want, "{w}x{h}, one pixel in {keep}");
        }
    }
}

#[test]
fn steps_between_regions_are_the_walks_back_along_rows_and_up_columns() {
    // Blobs of labels with gaps of 0 to 6 pixels between them, dropouts, and depth
    // steps; more rows than one block, so that blocks start below the top on 4 threads.
    let (w, h) = (53usize, 90usize);
    let data: Vec<u32> = (0..w * h)
        .map(|i| {
            let (u, v) = ((i % w) as u32, (i / w) as u32);
            if hash(u / 6 + 101 * (v / 3)).is_multiple_of(4) { 0 } else { 1 + hash(u / 11 + 7 * (v / 2)) % 5 }
        })
        .collect();
    let seg = Segmentation::from_labels(Grid { width: w, height: h, data: data.clone() }, 5, 1);
    let depth = Grid {
        width: w,
        height: h,
        data: (0..w * h)
            .map(|i| match hash(i as u32 ^ 0x5bd1) % 23 {
                0 => 0.0,
                1 => 2.0,
                _ => 1.0 + (i % w) as f32 * 1e-3,
            })
            .collect(),
    };
    let cloud = Cloud::new(&depth, &centred_camera(w, h, 40.0));
    let (ratio, max_gap) = (0.03f32, 4usize);
    // The oracle: from every labelled pixel, back along its row and up its column to the
    // nearest labelled pixel at most max_gap + 1 away; a pair where the two differ in
    // label and no depth step lies between them.
    let l = &seg.labels.data;
    let mut want = std::collections::BTreeMap::<(u32, u32), u32>::new();
    for j in (0..w * h).filter(|&j| l[j] != 0) {
        let (u, v) = (j % w, j / w);
        for (stride, room) in [(1, u), (w, v)] {
            let Some((i, px)) = (1..=room.min(max_gap + 1)).map(|k| (j - k * stride, k)).find(|&(i, _)| l[i] != 0)
            else {
                continue;
            };
            // No depth step: every pixel with a depth on the way within `ratio` per pixel of
            // the last one with a depth, both ends with one.
            let on_line: Vec<(usize, f32)> =
                (0..=px).map(|k| (k, depth.data[i + k * stride])).filter(|&(_, z)| z > 0.0).collect();
            let smooth = on_line
                .windows(2)
                .all(|p| (p[1].1 - p[0].1).abs() <= ratio * (p[1].0 - p[0].0) as f32 * p[1].1.min(p[0].1));
            let ends = on_line.first().is_some_and(|p| p.0 == 0) && on_line.last().is_some_and(|p| p.0 == px);
            if l[i] != l[j] && ends && smooth {
                *want.entry((l[i].min(l[j]), l[i].max(l[j]))).or_default() += 1;
            }
        }
    }
    let want: Vec<((u32, u32), u32)> = want.into_iter().collect();
    assert!(want.len() >= 5 && want.iter().any(|(_, n)| *n > 20), "pairs to find: {want:?}");
    for threads in [1, 4] {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().expect("a pool");
        assert_eq!(pool.install(|| seg.steps_between(&cloud, ratio, max_gap)), want, "{threads} threads");
    }
}

#[test]
fn row_scans_are_the_pixel_by_pixel_ones() {
    // Growth's links and wave on a row, and where rows enter a region.
    // Labels in blobs and specks, 0 between, on widths that leave every remainder of
    // the eight-byte words and of the vectors.
    for (w, h) in [(1, 1), (1, 5), (7, 3), (37, 29), (70, 11)] {
        let labels = Grid {
            width: w,
            height: h,
            data: (0..w * h)
                .map(|i| {
                    let (u, v) = ((i % w) as u32, (i / w) as u32);
                    if hash(u / 5 + 97 * (v / 4)).is_multiple_of(3) || hash(i as u32).is_multiple_of(11) {
                        1 + u / 9
                    } else {
                        0
                    }
                })
                .collect(),
        };
        let at = |u: isize, v: isize| {
            if u < 0 || v < 0 || u >= w as isize || v >= h as isize {
                0
            } else {
                labels.data[v as usize * w + u as usize]
            }
        };
        // Each unlabelled pixel's plane: a label near the pixel's own blob, or none (0,
        // as on every labelled pixel: `plane_image`).
        let plane = |u: isize, v: isize| {
            let k = hash((u * 31 + v * 7) as u32);
            let outside = u < 0 || v < 0 || u >= w as isize || v >= h as isize;
            if outside || at(u, v) != 0 || k.is_multiple_of(4) { 0 } else { 1 + (u as u32 + k % 3) / 9 }
        };
        let planes =
            Grid { width: w, height: h, data: (0..w * h).map(|i| plane((i % w) as isize, (i / w) as isize)).collect() };
        // Growth's links by their definition: a pixel with a plane joins at the first
        // wave when a 4-neighbour holds it, and then when a 4-neighbour of the same
        // plane has joined.
        let sides = [(-1, 0, SAME_LEFT), (1, 0, SAME_RIGHT), (0, -1, SAME_ABOVE), (0, 1, SAME_BELOW)];
        let mut want_links = Vec::new();
        for v in 0..h as isize {
            for u in 0..w as isize {
                let p = plane(u, v);
                let mut flags = 0;
                for &(du, dv, same) in &sides {
                    if p != 0 && at(u + du, v + dv) == p {
                        flags |= HELD_BESIDE;
                    }
                    if p != 0 && plane(u + du, v + dv) == p {
                        flags |= same;
                    }
                }
                want_links.push(flags);
            }
        }
        // A wave from some pixels joined, by its definition.
        let joined: Vec<u8> = (0..w * h).map(|i| u8::from(hash(i as u32 ^ 0x3c).is_multiple_of(3))).collect();
        let joined_at = |u: isize, v: isize| {
            let inside = u >= 0 && v >= 0 && u < w as isize && v < h as isize;
            inside && joined[v as usize * w + u as usize] == 1
        };
        let mut want_wave = Vec::new();
        for v in 0..h as isize {
            for u in 0..w as isize {
                let k = want_links[v as usize * w + u as usize];
                let brought = sides.iter().any(|&(du, dv, same)| k & same != 0 && joined_at(u + du, v + dv));
                want_wave.push(u8::from(joined_at(u, v) || brought));
            }
        }
        // Where a row enters a region (the creases' and joins' scan).
        let mut entries = Vec::new();
        for v in 0..h as isize {
            for u in 0..w as isize {
                let x = at(u, v);
                if x != 0 && u > 0 && at(u - 1, v) != x {
                    entries.push((u as usize, v as usize));
                }
            }
        }
        let (mut links, mut wave, mut got_entries) = (vec![0u8; w * h], vec![0u8; w * h], Vec::new());
        let mut mask = vec![0u8; w];
        for v in 0..h {
            let row = v * w..(v + 1) * w;
            let (labels_around, planes_around) = (rows_around(&labels.data, w, v), rows_around(&planes.data, w, v));
            join_links(labels_around, planes_around, [v > 0, v + 1 < h], &mut links[row.clone()]);
            let took = wave_row(rows_around(&joined, w, v), &want_links[row.clone()], &mut wave[row.clone()]);
            assert_eq!(took, want_wave[row.clone()] != joined[row], "{w} x {h}, row {v}");
            row_meetings(labels_around[1], Meeting::OtherLabel, &mut mask);
            for_each_set(&mask, |u| got_entries.push((u, v)));
        }
        assert_eq!(links, want_links, "{w} x {h}");
        assert_eq!(wave, want_wave, "{w} x {h}");
        assert_eq!(got_entries, entries, "{w} x {h}");
        // Every kind of link, pixels a wave brings in, and borders.
        let count = |flag: u8| want_links.iter().filter(|&&k| k & flag != 0).count();
        let brought = want_wave.iter().zip(&joined).filter(|(a, b)| a != b).count();
        let kinds = [HELD_BESIDE, SAME_LEFT, SAME_RIGHT, SAME_ABOVE, SAME_BELOW].map(count);
        assert!(
            w * h < 100 || (kinds.iter().all(|&n| n > 10) && brought > 10 && entries.len() > 20),
            "{w} x {h}: {kinds:?}, {brought}"
        );
    }
    // Any non-zero byte counts, in a word and in the tail.
    let mut set = Vec::new();
    for_each_set(&[0, 3, 0, 0, 0, 0, 0, 255, 9, 0, 128], |i| set.push(i));
    assert_eq!(set, [1, 7, 8, 10]);
}

/// `NearbyRegions` as its definition says it: an accepted region is around pixel (u, v) when
/// it holds a pixel in a cell at most margin / CELL_PX (rounded up) cells from the pixel's,
/// across and down; the labels ascend. Regions of every shape: an L whose box covers the
/// image, specks, a block, a run across a row's end into the next cell row, one not
/// accepted; an image of partial cells; margins within a cell and beyond.
#[test]
fn the_regions_around_a_pixel_are_those_with_a_pixel_a_cell_or_so_away() {
    let (w, h) = (100usize, 75usize);
    let label = |i: usize| {
        let (u, v) = (i % w, i / w);
        if v < 3 || (u < 3 && v > 40) {
            1
        } else if (31 * w + 96..32 * w + 12).contains(&i) {
            2
        } else if (40..50).contains(&u) && (20..28).contains(&v) {
            3
        } else if u > 60 && v > 50 && hash(i as u32).is_multiple_of(9) {
            4
        } else if (70..80).contains(&u) && (5..9).contains(&v) {
            5
        } else {
            0
        }
    };
    let data: Vec<u32> = (0..w * h).map(label).collect();
    let seg = Segmentation::from_labels(Grid { width: w, height: h, data }, 5, 0);
    let accepted = [true, true, true, true, false];
    for margin in [1, 16, 17, 40] {
        let nearby = NearbyRegions::new(&seg, &accepted, margin);
        let reach = margin.div_ceil(CELL_PX);
        let cell = |i: usize| ((i % w / CELL_PX) as isize, (i / w / CELL_PX) as isize);
        for i in 0..w * h {
            let (cu, cv) = cell(i);
            let want: Vec<u32> = (1..=5u32)
                .filter(|&l| accepted[l as usize - 1])
                .filter(|&l| {
                    seg.pixels[l as usize - 1].iter().any(|&j| {
                        let (ju, jv) = cell(j as usize);
                        (ju - cu).unsigned_abs() <= reach && (jv - cv).unsigned_abs() <= reach
                    })
                })
                .collect();
            assert_eq!(nearby.around(i % w, i / w), want, "margin {margin}, pixel ({}, {})", i % w, i / w);
        }
    }
}

/// A region's plane competes for pixels only near the region: a wall seen square-on, an
/// L-shaped region along two edges whose plane is the wall's exactly (nearest to every
/// point) and a square far from it whose plane is off by a fraction of the inlier
/// distance. The square grows its full waves; with the L's plane competing everywhere its
/// box reaches (as it once did), the square took nothing.
#[test]
fn a_far_region_s_plane_does_not_stop_a_region_growing_where_it_cannot_reach() {
    let (w, h, waves) = (128usize, 128usize, 4u32);
    let depth = Grid { width: w, height: h, data: vec![1.0f32; w * h] };
    let intr = centred_camera(w, h, 100.0);
    let cloud = Cloud::new(&depth, &intr);
    let in_square = |u: usize, v: usize| (90..110).contains(&u) && (90..110).contains(&v);
    let data: Vec<u32> = (0..w * h)
        .map(|i| match (i % w, i / w) {
            (u, v) if u < 4 || v < 4 => 1,
            (u, v) if in_square(u, v) => 2,
            _ => 0,
        })
        .collect();
    let mut seg = Segmentation::from_labels(Grid { width: w, height: h, data }, 2, 0);
    let plane =
        |normal: Vector3<f64>| PlaneFit { normal: normal.normalize(), offset: -1.0, inliers: 1, points: 1, rms: 0.0 };
    let fits = [Some(plane(Vector3::z())), Some(plane(Vector3::new(0.001, 0.0, 1.0)))];
    seg.grow(&fits, &[true, true], &cloud, 0.003, waves);
    // Manhattan distance from the square.
    let from_square = |u: usize, v: usize| u.abs_diff(u.clamp(90, 109)) + v.abs_diff(v.clamp(90, 109));
    for (i, &l) in seg.labels.data.iter().enumerate() {
        let (u, v) = (i % w, i / w);
        let want_square = from_square(u, v) <= waves as usize;
        assert_eq!(l == 2, want_square, "pixel ({u}, {v}): label {l}");
    }
}

/// Pieces of one face cut apart by stripes a few pixels wide (a structured-light scanner's
/// bands of bad depth leave such strips between edges), each strip fitted a plane of its own
/// that is far off the face's: the strips lie on the face's plane, so they join it, and the
/// face becomes one region; a real face beside it (a riser at a right angle) does not join.
#[test]
fn strips_on_a_face_s_plane_join_it_whatever_their_own_fits_say() {
    let (w, h) = (80usize, 40usize);
    let intr = centred_camera(w, h, 60.0);
    // The face: 1/depth linear in the pixel, left of u = 60; the riser beyond, at depth 1 / 0.9.
    let inverse_depth =
        |u: usize, v: usize| if u < 60 { 0.9 + 0.002 * (60.0 - u as f32) + 0.001 * v as f32 } else { 0.9 };
    let depth = Grid { width: w, height: h, data: (0..w * h).map(|i| 1.0 / inverse_depth(i % w, i / w)).collect() };
    let cloud = Cloud::new(&depth, &intr);
    // Regions: the face's left part (u < 30), strips 3 px wide with 1-px edges between them
    // up to u = 44, the face's right part to u = 58, the riser from u = 61.
    let region = |u: usize| match u {
        0..30 => 1,
        30..45 if (u - 30) % 4 != 3 => 2 + (u - 30) as u32 / 4,
        45..58 => 6,
        61.. => 7,
        _ => 0,
    };
    let data: Vec<u32> = (0..w * h).map(|i| region(i % w)).collect();
    let mut seg = Segmentation::from_labels(Grid { width: w, height: h, data }, 7, 0);
    let all: Vec<usize> = (0..7).collect();
    let mut fits = super::super::cpu::ransac::fit_planes(&seg.points(&all, &cloud), 32, 0.003);
    // The strips' own planes, as narrow fits on noisy depth come out: 30 deg off the face's.
    let face = fits[0].unwrap().normal;
    let tilted = (Rotation3::new(Vector3::y() * 30f64.to_radians()) * face).normalize();
    for f in &mut fits[1..5] {
        let f = f.as_mut().unwrap();
        let p = seg.points(&[0], &cloud).points[0];
        f.normal = tilted;
        f.offset = -tilted.dot(&Vector3::new(p[0] as f64, p[1] as f64, p[2] as f64));
    }
    assert!(fits[1].unwrap().normal.dot(&face) < JOIN_ANGLE_COS);
    let candidates = seg.join_candidates(&cloud, 0.03);
    let joins = seg.join_coplanar(candidates, &mut fits, &cloud, 0.003, 0.9);
    assert_eq!(joins, 5, "the four strips and the face's right part join its left part");
    let face_pixels = (0..w * h).filter(|&i| i % w < 58 && region(i % w) != 0).count();
    assert!(seg.pixels[0].len() >= face_pixels, "{} of {face_pixels}", seg.pixels[0].len());
    assert!(fits[6].is_some() && seg.pixels[6].len() == 19 * h, "the riser stays its own region");
}

/// A 80 x 40 view of two faces meeting at a crease down column 40: the left face square
/// to the camera at 1 m, the right one turned away by `turn_deg` about the crease. 1/depth
/// is linear in the pixel on a plane, so each face is exact: the depth, the camera and
/// the two planes.
fn two_faces(turn_deg: f64) -> (Grid<f32>, crate::types::Intrinsics, [Option<PlaneFit>; 2]) {
    let (w, h) = (80usize, 40usize);
    let intr = centred_camera(w, h, 60.0);
    // Along a row the right face's depth grows by tan(turn) of the width a pixel spans
    // (near the crease, where the depth is 1 m).
    let slope = (turn_deg.to_radians().tan() / 60.0) as f32;
    let inverse_depth = |u: usize| if u <= 40 { 1.0 } else { 1.0 - slope * (u as f32 - 40.0) };
    let depth = Grid { width: w, height: h, data: (0..w * h).map(|i| inverse_depth(i % w).recip()).collect() };
    let cloud = Cloud::new(&depth, &intr);
    let truth = regions_of(|u, _| if u <= 40 { 1 } else { 2 }, 2);
    let fits = super::super::cpu::ransac::fit_planes(&truth.points(&[0, 1], &cloud), 32, 0.001);
    (depth, intr, [fits[0], fits[1]])
}

/// Regions of an 80 x 40 image from a label per pixel.
fn regions_of(labels: impl Fn(usize, usize) -> u32, count: usize) -> Segmentation {
    let (w, h) = (80usize, 40usize);
    let data: Vec<u32> = (0..w * h).map(|i| labels(i % w, i / w)).collect();
    Segmentation::from_labels(Grid { width: w, height: h, data }, count, 0)
}

/// The left face's region ran ten columns past the crease (its edge line broke there):
/// those pixels lie nearer the right face's plane, and go back to it; the left face's own
/// pixels stay. Faces nearly one plane (5 deg) trade nothing: noise would choose there.
#[test]
fn a_region_that_ran_past_a_crease_gives_the_band_back_to_the_face_beyond() {
    let (depth, intr, fits) = two_faces(35.0);
    let cloud = Cloud::new(&depth, &intr);
    let ran_past = |u: usize, _| if u < 50 { 1 } else { 2 };
    let mut seg = regions_of(ran_past, 2);
    let moved = seg.settle_borders(&fits, &[true, true], &cloud, 0.2);
    assert_eq!(moved, 9 * 40, "columns 41..50, every row");
    for (i, &l) in seg.labels.data.iter().enumerate() {
        assert_eq!(l, if i % 80 <= 40 { 1 } else { 2 }, "pixel ({}, {})", i % 80, i / 80);
    }
    assert_eq!(seg.pixels[1].len(), 39 * 40, "the lists follow the labels");
    // Not accepted: no plane to move to, or from.
    let mut seg = regions_of(ran_past, 2);
    assert_eq!(seg.settle_borders(&fits, &[true, false], &cloud, 0.2), 0);
    let (depth, intr, fits) = two_faces(5.0);
    let cloud = Cloud::new(&depth, &intr);
    let mut seg = regions_of(ran_past, 2);
    assert_eq!(seg.settle_borders(&fits, &[true, true], &cloud, 0.2), 0, "5 deg apart: one surface's pieces");
}

/// A region joined to its far part by a bridge one pixel wide across its neighbour's face
/// keeps the bridge: every pixel of it lies on the neighbour's plane, but taking any would
/// cut the region in two.
#[test]
fn settling_borders_never_cuts_a_region_in_two() {
    let (depth, intr, fits) = two_faces(35.0);
    let cloud = Cloud::new(&depth, &intr);
    // The right face's region is columns 41..60 but for row 20, which the left face's
    // region holds across to its far part, columns 60.. (on the right face's plane too).
    let bridged = |u: usize, v: usize| if u <= 40 || v == 20 || u >= 60 { 1 } else { 2 };
    let mut seg = regions_of(bridged, 2);
    seg.settle_borders(&fits, &[true, true], &cloud, 0.2);
    assert!((41..60).all(|u| seg.labels.data[20 * 80 + u] == 1), "the bridge stays");
    let mut seen = vec![false; 80 * 40];
    let first = seg.pixels[0][0] as usize;
    let piece = crate::grid::flood(first, 80, 40, &mut seen, |j| seg.labels.data[j] == 1);
    assert_eq!(piece.len(), seg.pixels[0].len(), "the left face's region is one piece");
    // The far part's pixels beside the right face's region lie on its plane and go to it,
    // but for those that hold the far part to the bridge.
    assert!(seg.pixels[1].len() > 19 * 39, "{}", seg.pixels[1].len());
}

/// A region whose plane fits 41 of its 44 columns (over the inlier ratio) took in three
/// columns of the face beyond the crease: they are cut out as a region of their own. A
/// patch of its own face just beyond the inlier band (noise's tail, not a face turning
/// away) stays in it.
#[test]
fn a_second_face_a_region_took_in_is_cut_out_though_its_plane_fits_enough() {
    let (mut depth, intr, fits) = two_faces(35.0);
    // A 6 x 6 patch of the left face 3.5 mm off its plane, the band being 3 mm.
    for (u, v) in (10..16).flat_map(|u| (10..16).map(move |v| (u, v))) {
        depth.data[v * 80 + u] += 0.0035;
    }
    let cloud = Cloud::new(&depth, &intr);
    let mut seg = regions_of(|u, _| if u < 44 { 1 } else { 2 }, 2);
    let mut got = super::super::cpu::ransac::fit_planes(&seg.points(&[0, 1], &cloud), 32, 0.003);
    let left = got[0].expect("a plane");
    assert!(left.inlier_ratio() >= 0.9 && left.normal.dot(&fits[0].unwrap().normal) > 0.9999, "{left:?}");
    let leaks = seg.split_leaks(&mut got, &cloud, 0.003, 0.9, 30);
    assert_eq!(leaks, Leaks { split: vec![0], pieces: vec![2] });
    assert_eq!(got.len(), 3, "a fit, to come, for the new region");
    let cut: Vec<u32> = (0..40).flat_map(|v| (41..44).map(move |u| (v * 80 + u) as u32)).collect();
    assert_eq!(seg.pixels[2], cut);
    assert_eq!(seg.pixels[0].len(), 41 * 40, "the patch stays: {}", seg.pixels[0].len());
    assert!(seg.pixels[0].windows(2).all(|p| p[0] < p[1]));
}

/// What no region took: a 12 x 12 blob (a face the edges took whole) is seeded as a
/// region of its core (the ring the opening took is growth's to give back); the 4-pixel
/// band between two regions (what growth leaves along a crease) and a blob of dropouts
/// are not. A seed whose fit is rejected gives its pixels back.
#[test]
fn the_blobs_no_region_took_are_seeded_and_the_bands_between_faces_are_not() {
    let (w, h) = (80usize, 40usize);
    let band = |u: usize| (30..34).contains(&u);
    let blob = |u: usize, v: usize| (45..57).contains(&u) && (14..26).contains(&v);
    let dropouts = |u: usize, v: usize| (64..76).contains(&u) && (14..26).contains(&v);
    let mut seg = regions_of(
        |u, v| {
            if band(u) || blob(u, v) || dropouts(u, v) {
                0
            } else if u < 30 {
                1
            } else {
                2
            }
        },
        2,
    );
    let depth = Grid {
        width: w,
        height: h,
        data: (0..w * h).map(|i| if dropouts(i % w, i / w) { 0.0 } else { 1.0 }).collect(),
    };
    let cloud = Cloud::new(&depth, &centred_camera(w, h, 60.0));
    let seeds = seg.seed_leftovers(&cloud, 30);
    assert_eq!(seeds, vec![2], "one seed, after the two regions");
    let core: Vec<u32> = (0..(w * h) as u32)
        .filter(|&i| (46..56).contains(&(i as usize % w)) && (15..25).contains(&(i as usize / w)))
        .collect();
    assert_eq!(seg.pixels[2], core, "the blob's 10 x 10 core");
    for i in 0..w * h {
        let (u, v) = (i % w, i / w);
        if band(u) || dropouts(u, v) {
            assert_eq!(seg.labels.data[i], 0, "({u}, {v}) stays unlabelled");
        }
    }
    let mut fits = vec![None; 3];
    assert_eq!(seg.release_rejected(&seeds, &[true, true, false], &mut fits), 0, "no seed kept");
    assert!(seg.pixels[2].is_empty() && seg.labels.data.iter().all(|&l| l <= 2), "a rejected seed is released");
}
