//! Row-major pixel grids and their connected components, for extraction, the map's
//! clearing and the evaluation alike.

/// A row-major image of any pixel type.
#[derive(Clone, Debug, PartialEq)]
pub struct Grid<T> {
    pub width: usize,
    pub height: usize,
    pub data: Vec<T>,
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

/// 8-connected components of the pixels where `inside` holds: a label per pixel (0
/// outside; components numbered from 1 in the scan order of their first pixel) and
/// the number of components. Runs of pixels along rows are joined by union-find with
/// the runs they touch in the row above, so the work grows with the runs, not pixels.
pub fn label_components(inside: &[bool], w: usize, h: usize) -> (Vec<u32>, usize) {
    // Runs [start, end) of row v, in scan order, and their union-find parents.
    let mut runs: Vec<(usize, usize, usize)> = Vec::new();
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
        while u < w {
            if !row[u] {
                u += 1;
                continue;
            }
            let start = u;
            while u < w && row[u] {
                u += 1;
            }
            let me = runs.len() as u32;
            runs.push((v, start, u));
            parent.push(me);
            // Runs above touching columns start - 1 ..= u (diagonals included); both rows'
            // runs are in column order, so the first candidate only moves right.
            while above.start < above.end && runs[above.start].2 < start {
                above.start += 1;
            }
            for k in above.clone() {
                if runs[k].1 > u {
                    break;
                }
                let (a, b) = (root(&mut parent, k as u32), root(&mut parent, me));
                // The older root stays root, so a component's root is its first run.
                parent[a.max(b) as usize] = a.min(b);
            }
        }
        above = first..runs.len();
    }
    let mut labels = vec![0u32; w * h];
    let mut label_of_root = vec![0u32; runs.len()];
    let mut count = 0;
    for (k, &(v, s, e)) in runs.iter().enumerate() {
        let r = root(&mut parent, k as u32) as usize;
        if label_of_root[r] == 0 {
            count += 1;
            label_of_root[r] = count as u32;
        }
        labels[v * w + s..v * w + e].fill(label_of_root[r]);
    }
    (labels, count)
}
