//! Row-major pixel grids and their connected components, for extraction, the map's
//! clearing and the evaluation alike.

/// A row-major image of any pixel type.
#[derive(Clone, Debug, PartialEq)]
pub struct Grid<T> {
    pub width: usize,
    pub height: usize,
    pub data: Vec<T>,
}

/// A stretch of consecutive pixels along row `v`: indices `first..=last`, the row
/// starting at index `row_start`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Run {
    pub v: usize,
    pub row_start: usize,
    pub first: usize,
    pub last: usize,
}

impl Run {
    /// The columns of its first and last pixel.
    pub fn columns(&self) -> (usize, usize) {
        (self.first - self.row_start, self.last - self.row_start)
    }
}

/// The runs of an ascending list of pixel indices in an image `w` wide, in order. A
/// division per row, none per pixel: per pixel, it was most of the time of the loops
/// that walk a region's pixels by row and column.
pub fn runs(pixels: &[u32], w: usize) -> impl Iterator<Item = Run> + '_ {
    debug_assert!(pixels.windows(2).all(|p| p[0] < p[1]), "ascending pixels");
    let (mut k, mut v, mut row_start) = (0, usize::MAX, 0);
    std::iter::from_fn(move || {
        let first = *pixels.get(k)? as usize;
        if v == usize::MAX || first >= row_start + w {
            (v, row_start) = (first / w, first / w * w);
        }
        let mut end = k + 1;
        while end < pixels.len() && pixels[end] as usize == first + (end - k) && (pixels[end] as usize) < row_start + w
        {
            end += 1;
        }
        let last = first + (end - k) - 1;
        k = end;
        Some(Run { v, row_start, first, last })
    })
}

/// Calls `f` with the index of every non-zero byte of `mask`, ascending; eight bytes at a
/// time, so stretches of zeros cost a test per eight. A scan whose work lies on a few
/// pixels of most rows (edges, region borders) marks them in a mask a whole row at a time,
/// with comparisons that vectorise, then visits only those.
pub fn for_each_set(mask: &[u8], mut f: impl FnMut(usize)) {
    let words = mask.chunks_exact(8);
    let tail = words.remainder();
    for (k, word) in words.enumerate() {
        let mut bits = u64::from_le_bytes(word.try_into().expect("eight bytes"));
        while bits != 0 {
            let byte = bits.trailing_zeros() as usize / 8;
            f(8 * k + byte);
            bits &= !(0xff << (8 * byte));
        }
    }
    let start = mask.len() - tail.len();
    for (j, &m) in tail.iter().enumerate() {
        if m != 0 {
            f(start + j);
        }
    }
}

/// The 8-connected set of pixels reachable from `start` through pixels where `inside`
/// holds, marking them in `seen`.
pub fn flood(start: usize, w: usize, h: usize, seen: &mut [bool], inside: impl Fn(usize) -> bool) -> Vec<u32> {
    let mut out = Vec::new();
    let mut stack = vec![start];
    seen[start] = true;
    while let Some(i) = stack.pop() {
        out.push(i as u32);
        let (u, v) = ((i % w) as isize, (i / w) as isize);
        for dv in -1..=1 {
            for du in -1..=1 {
                let (nu, nv) = (u + du, v + dv);
                if nu < 0 || nv < 0 || nu >= w as isize || nv >= h as isize {
                    continue;
                }
                let j = nv as usize * w + nu as usize;
                if !seen[j] && inside(j) {
                    seen[j] = true;
                    stack.push(j);
                }
            }
        }
    }
    out
}

/// A run of one component along a row: pixel indices `start..end`, component `label`
/// (numbered from 1 in the scan order of the components' first pixels).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ComponentRun {
    pub start: usize,
    pub end: usize,
    pub label: u32,
}

/// 8-connected components of the pixels where `inside` holds, as their runs along the
/// rows in scan order, and the number of components. Runs are joined by union-find with
/// the runs they touch in the row above, so the work grows with the runs, not pixels;
/// callers that need per-component sums or lists take them run by run too.
pub fn component_runs(inside: &[bool], w: usize, h: usize) -> (Vec<ComponentRun>, usize) {
    // Runs of row v, in scan order, and their union-find parents.
    let mut runs: Vec<ComponentRun> = Vec::new();
    let mut parent: Vec<u32> = Vec::new();
    fn root(parent: &mut [u32], mut r: u32) -> u32 {
        while parent[r as usize] != r {
            parent[r as usize] = parent[parent[r as usize] as usize];
            r = parent[r as usize];
        }
        r
    }
    let mut above = 0..0;
    for v in 0..h {
        let row = &inside[v * w..(v + 1) * w];
        let first = runs.len();
        let mut u = 0;
        while let Some(skip) = row[u..].iter().position(|&b| b) {
            let start = u + skip;
            u = start + row[start..].iter().position(|&b| !b).unwrap_or(w - start);
            let me = runs.len() as u32;
            runs.push(ComponentRun { start: v * w + start, end: v * w + u, label: 0 });
            parent.push(me);
            // Runs above touching columns start - 1 ..= u (diagonals included); both rows'
            // runs are in column order, so the first candidate only moves right. (None
            // above row 0: `above` is empty there.)
            let row_above = (v * w).wrapping_sub(w);
            let (reach_start, reach_end) = (row_above.wrapping_add(start), row_above.wrapping_add(u));
            while above.start < above.end && runs[above.start].end < reach_start {
                above.start += 1;
            }
            for k in above.clone() {
                if runs[k].start > reach_end {
                    break;
                }
                let (a, b) = (root(&mut parent, k as u32), root(&mut parent, me));
                // The older root stays root, so a component's root is its first run.
                parent[a.max(b) as usize] = a.min(b);
            }
        }
        above = first..runs.len();
    }
    let mut label_of_root = vec![0u32; runs.len()];
    let mut count = 0;
    for k in 0..runs.len() {
        let r = root(&mut parent, k as u32) as usize;
        if label_of_root[r] == 0 {
            count += 1;
            label_of_root[r] = count as u32;
        }
        runs[k].label = label_of_root[r];
    }
    (runs, count)
}

/// 8-connected components of the pixels where `inside` holds: a label per pixel (0
/// outside; components numbered from 1 in the scan order of their first pixel) and
/// the number of components (`component_runs`, painted).
pub fn label_components(inside: &[bool], w: usize, h: usize) -> (Vec<u32>, usize) {
    let (runs, count) = component_runs(inside, w, h);
    let mut labels = vec![0u32; w * h];
    for r in &runs {
        labels[r.start..r.end].fill(r.label);
    }
    (labels, count)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn runs_are_the_stretches_of_consecutive_pixels_within_each_row() {
        // Every 7th hash-picked pixel of a 13-wide image: runs that end at a row's end and
        // go on at the next row's start must split there.
        let (w, h) = (13usize, 11usize);
        let pixels: Vec<u32> =
            (0..(w * h) as u32).filter(|&i| !crate::extract::cpu::ransac::hash(i).is_multiple_of(7)).collect();
        let got: Vec<Run> = runs(&pixels, w).collect();
        let mut want: Vec<Run> = Vec::new();
        for &i in &pixels {
            let (i, v) = (i as usize, i as usize / w);
            match want.last_mut() {
                Some(r) if r.v == v && r.last + 1 == i => r.last = i,
                _ => want.push(Run { v, row_start: v * w, first: i, last: i }),
            }
        }
        assert_eq!(got, want);
        assert!(
            got.windows(2).any(|p| p[0].last + 1 == p[1].first && p[0].columns().1 == w - 1),
            "the pixels hold a stretch across a row's end, split there"
        );
        assert_eq!(runs(&[], w).count(), 0);
    }
}
