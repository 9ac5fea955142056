//! Row-major pixel grids and their connected components, for extraction, the map's
//! clearing and the evaluation alike.

/// A row-major image of any pixel type.
#[derive(Clone, Debug, PartialEq)]
pub struct Grid<T> {
    pub width: usize,
    pub height: usize,
    pub data: Vec<T>,
}

/// `rows` rows of `row_len` values, row v set to `init` and then handed to `fill(v, row)`,
/// the rows in parallel tasks of at least `min_rows`. A task sets its own rows, while
/// they are in its core's cache: `vec![init; n]` before the loop was a pass of its own
/// over the whole image, on one thread.
pub fn par_rows<T: bytemuck::Pod + Send + Sync>(
    row_len: usize,
    rows: usize,
    init: T,
    min_rows: usize,
    fill: impl Fn(usize, &mut [T]) + Send + Sync,
) -> Vec<T> {
    use rayon::prelude::*;
    let n = row_len * rows;
    let mut data: Vec<T> = Vec::with_capacity(n);
    // An init of one repeated byte (zero in every image, a byte mask's 1) is set by
    // memset, the C library's widest stores; `fill` is a loop of 16-byte stores here (this
    // generic code is compiled for the baseline CPU).
    // (A zero-sized init has no byte to repeat: it takes the fill.)
    let bytes = bytemuck::bytes_of(&init);
    let one_byte = bytes.first().copied().filter(|&b| bytes.iter().all(|&x| x == b));
    if row_len > 0 {
        let tasks = data.spare_capacity_mut()[..n].par_chunks_mut(row_len).enumerate().with_min_len(min_rows);
        tasks.for_each(|(v, row)| {
            if let Some(byte) = one_byte {
                // SAFETY: the row's own values, each set to init's bytes.
                unsafe { row.as_mut_ptr().write_bytes(byte, row.len()) };
            } else {
                row.fill(std::mem::MaybeUninit::new(init));
            }
            // SAFETY: every value of the row was just written, and MaybeUninit<T> has T's layout.
            let row = unsafe { &mut *(row as *mut [std::mem::MaybeUninit<T>] as *mut [T]) };
            fill(v, row);
        });
    }
    // SAFETY: the tasks above wrote all n values (none when row_len is 0, and then n is 0).
    unsafe { data.set_len(n) };
    data
}

/// Rows v - 1, v and v + 1 of an image `w` wide; beyond its top or bottom, row v stands in
/// (for a row loop that ORs, ANDs or compares with its neighbours, itself adds nothing).
pub fn rows_around<T>(data: &[T], w: usize, v: usize) -> [&[T]; 3] {
    let row = |v: usize| &data[v * w..(v + 1) * w];
    let last = data.len() / w - 1;
    [row(v.saturating_sub(1)), row(v), row((v + 1).min(last))]
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
/// that walk a region's pixels by row and column. A run's end is found by galloping
/// and bisection, a few reads however long the run.
pub fn runs(pixels: &[u32], w: usize) -> impl Iterator<Item = Run> + '_ {
    debug_assert!(pixels.windows(2).all(|p| p[0] < p[1]), "ascending pixels");
    let (mut k, mut v, mut row_start) = (0, usize::MAX, 0);
    std::iter::from_fn(move || {
        let first = *pixels.get(k)? as usize;
        if v == usize::MAX || first >= row_start + w {
            (v, row_start) = (first / w, first / w * w);
        }
        // pixels[k + j] is the run's j-th pixel up to the first gap or the row's end, and
        // never after (the pixels ascend strictly: once one is past first + j, every later
        // one is).
        let len =
            leading(|j| pixels.get(k + j).is_some_and(|&p| p as usize == first + j && (p as usize) < row_start + w));
        k += len;
        Some(Run { v, row_start, first, last: first + len - 1 })
    })
}

/// How many of j = 0, 1, 2, ... `holds`, given that it holds for 0 and, once it fails,
/// fails for every j after: by galloping then bisection, a few calls however many hold.
pub fn leading(holds: impl Fn(usize) -> bool) -> usize {
    let (mut yes, mut no) = (0, 1);
    while holds(no) {
        (yes, no) = (no, no * 2);
    }
    while no - yes > 1 {
        let mid = yes + (no - yes) / 2;
        if holds(mid) { yes = mid } else { no = mid }
    }
    no
}

/// The index of the first of `values` other than `value`, if one is: 64 bytes at a time
/// (sixteen labels, 64 flags), each block compared byte by byte with `value`'s bytes into
/// a word of bits (`differing_bits`), whose lowest set bit is the first byte that differs,
/// in the first value that does (a value is equal exactly when its bytes are). Label runs
/// are tens to hundreds of pixels long, and so are the runs of a region's inside; a search
/// value by value, or a block's test followed by one, took a step per value.
pub fn first_other<T: bytemuck::NoUninit + PartialEq>(values: &[T], value: T) -> Option<usize> {
    const { assert!(64 % size_of::<T>() == 0, "a value's size divides a block") };
    let size = size_of::<T>();
    let mut pattern = [0u8; 64];
    for copy in pattern.chunks_exact_mut(size) {
        copy.copy_from_slice(bytemuck::bytes_of(&value));
    }
    let blocks = bytemuck::cast_slice::<T, u8>(values).chunks_exact(64);
    let tail = blocks.len() * 64 / size;
    for (k, block) in blocks.enumerate() {
        let bits = differing_bits(block.try_into().expect("64 bytes"), &pattern);
        if bits != 0 {
            return Some((64 * k + bits.trailing_zeros() as usize) / size);
        }
    }
    values[tail..].iter().position(|x| *x != value).map(|j| tail + j)
}

/// Calls `f` with the index of every non-zero byte of `mask`, ascending. A scan whose work
/// lies on a few pixels of most rows (edges, region borders) marks them in a mask a whole
/// row at a time, with comparisons that vectorise, then visits only those. The mask is
/// read 64 bytes at a time into a word of bits, one per byte (`differing_bits` from 0),
/// and only the set bits are visited: tested eight bytes a word, the loop over the empty
/// words of a row was most of a scan's time.
pub fn for_each_set(mask: &[u8], mut f: impl FnMut(usize)) {
    let blocks = mask.chunks_exact(64);
    let tail = blocks.remainder();
    for (k, block) in blocks.enumerate() {
        let mut bits = differing_bits(block.try_into().expect("64 bytes"), &[0; 64]);
        while bits != 0 {
            f(64 * k + bits.trailing_zeros() as usize);
            bits &= bits - 1;
        }
    }
    let start = mask.len() - tail.len();
    for (j, &m) in tail.iter().enumerate() {
        if m != 0 {
            f(start + j);
        }
    }
}

/// Bit j set where byte j of `block` differs from byte j of `pattern`.
#[inline(always)]
fn differing_bits(block: &[u8; 64], pattern: &[u8; 64]) -> u64 {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{__m128i, _mm_cmpeq_epi8, _mm_loadu_si128, _mm_movemask_epi8};
        // SAFETY: SSE2 is part of x86-64; each load reads 16 of the arrays' 64 bytes.
        let equal_bits = |k: usize| unsafe {
            let load = |bytes: &[u8; 64]| _mm_loadu_si128(bytes.as_ptr().add(16 * k) as *const __m128i);
            _mm_movemask_epi8(_mm_cmpeq_epi8(load(block), load(pattern))) as u16 as u64
        };
        !(equal_bits(0) | equal_bits(1) << 16 | equal_bits(2) << 32 | equal_bits(3) << 48)
    }
    #[cfg(target_arch = "aarch64")]
    {
        use std::arch::aarch64::{vaddv_u8, vandq_u8, vceqq_u8, vget_high_u8, vget_low_u8, vld1q_u8};
        // Byte j of each 8 weighs 1 << j: the masked weights of 8 bytes add up to their bits.
        let weights: [u8; 16] = std::array::from_fn(|j| 1 << (j % 8));
        // SAFETY: each load reads 16 of the arrays' 64 bytes, or the 16 of `weights`.
        let equal_bits = |k: usize| unsafe {
            let load = |bytes: &[u8; 64]| vld1q_u8(bytes.as_ptr().add(16 * k));
            let bits = vandq_u8(vceqq_u8(load(block), load(pattern)), vld1q_u8(weights.as_ptr()));
            vaddv_u8(vget_low_u8(bits)) as u64 | (vaddv_u8(vget_high_u8(bits)) as u64) << 8
        };
        !(equal_bits(0) | equal_bits(1) << 16 | equal_bits(2) << 32 | equal_bits(3) << 48)
    }
    #[cfg(not(any(target_arch = "x86_64", target_arch = "aarch64")))]
    {
        block.iter().zip(pattern).enumerate().fold(0u64, |bits, (j, (b, p))| bits | u64::from(b != p) << j)
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
        while let Some(skip) = first_other(&row[u..], false) {
            let start = u + skip;
            u = start + first_other(&row[start..], true).unwrap_or(w - start);
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
    use crate::extract::cpu::ransac::hash;

    #[test]
    fn par_rows_sets_each_row_to_init_before_its_fill() {
        // The fill writes every third value of odd rows only: everything else must be init,
        // whether init is one repeated byte (set by memset) or not (value by value), on any pool.
        let fill = |v: usize, row: &mut [f32]| {
            if v % 2 == 1 {
                row.iter_mut().step_by(3).for_each(|x| *x += v as f32);
            }
        };
        for threads in [1, 2] {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            for init in [0.0f32, 1.5, -0.0] {
                // A freed block of the same size, NaN: the allocator hands it back, so a
                // value the init skipped is not a fresh page's zero.
                drop(std::hint::black_box(vec![f32::NAN; 35]));
                let data = pool.install(|| par_rows(7, 5, init, 2, fill));
                let want: Vec<f32> = (0..35)
                    .map(|i| {
                        let (v, u) = (i / 7, i % 7);
                        if v % 2 == 1 && u % 3 == 0 { init + v as f32 } else { init }
                    })
                    .collect();
                assert_eq!(
                    data.iter().map(|x| x.to_bits()).collect::<Vec<_>>(),
                    want.iter().map(|x| x.to_bits()).collect::<Vec<_>>(),
                    "init {init}, {threads} threads"
                );
            }
        }
        for init in [0u8, 1, 0xff] {
            drop(std::hint::black_box(vec![0x5au8; 35]));
            let data = par_rows(7, 5, init, 2, |v, row| row[v] ^= 0x80);
            let want: Vec<u8> = (0..35).map(|i| if i % 7 == i / 7 { init ^ 0x80 } else { init }).collect();
            assert_eq!(data, want, "byte init {init}");
        }
        assert!(par_rows(0, 3, 1u8, 1, |_, _| {}).is_empty());
        // A zero-sized value has no byte to repeat: every row is still handed to the fill.
        let values_filled = std::sync::atomic::AtomicUsize::new(0);
        let data = par_rows(4, 3, (), 1, |_, row| {
            values_filled.fetch_add(row.len(), std::sync::atomic::Ordering::Relaxed);
        });
        assert_eq!((data.len(), values_filled.into_inner()), (12, 12));
    }

    #[test]
    fn first_other_is_the_first_value_that_differs() {
        // Every length to three blocks and a remainder, the first other value at every place.
        for len in 0..52 {
            assert_eq!(first_other(&vec![7; len], 7), None);
            for at in 0..len {
                let mut values = vec![7; len];
                values[at] = 0;
                values[len - 1] = 1;
                assert_eq!(first_other(&values, 7), Some(at), "len {len}, other at {at}");
                // A label that differs in its top byte only.
                values[at] = 7 | 1 << 24;
                assert_eq!(first_other(&values, 7), Some(at), "len {len}, top byte at {at}");
            }
        }
        // Flags: blocks of 64, every length to three blocks and a remainder.
        for len in 0..200 {
            assert_eq!(first_other(&vec![true; len], true), None);
            for at in (0..len).step_by(7) {
                let mut flags = vec![false; len];
                flags[at] = true;
                assert_eq!(first_other(&flags, false), Some(at), "len {len}, flag at {at}");
            }
        }
    }

    #[test]
    fn for_each_set_visits_every_non_zero_byte_in_order() {
        // Every length to three blocks of 64 and a remainder; masks from empty to full,
        // with bytes of every value (a set top bit, a lone low bit) and runs across blocks.
        let mut drawn = 0u32;
        let mut next = move || {
            drawn += 1;
            hash(drawn)
        };
        for len in 0..200 {
            for density in [0u32, 1, 8, 50, 100] {
                let mask: Vec<u8> =
                    (0..len).map(|_| if next() % 100 < density { (next() % 255 + 1) as u8 } else { 0 }).collect();
                let want: Vec<usize> = (0..len).filter(|&i| mask[i] != 0).collect();
                let mut got = Vec::new();
                for_each_set(&mask, |i| got.push(i));
                assert_eq!(got, want, "len {len}, {density} % set");
            }
        }
    }

    #[test]
    fn components_are_the_8_connected_floods_numbered_in_scan_order() {
        // Random masks, sparse (many small components, joined by diagonals too) to dense
        // (one that spans the image); images narrower and wider than a block of 64 flags.
        for (w, h, percent) in [(37, 150, 35), (64, 97, 45), (130, 70, 60), (5, 200, 50), (100, 3, 40)] {
            let inside: Vec<bool> = (0..w * h).map(|i| hash(i as u32 ^ (w * h) as u32) % 100 < percent).collect();
            // The oracle: a flood from each pixel no flood has reached yet, in scan order.
            let (mut want, mut seen, mut count) = (vec![0u32; w * h], vec![false; w * h], 0);
            for i in 0..w * h {
                if inside[i] && !seen[i] {
                    count += 1;
                    for p in flood(i, w, h, &mut seen, |j| inside[j]) {
                        want[p as usize] = count as u32;
                    }
                }
            }
            assert!(count > 3, "{w} x {h}: {count} components");
            assert_eq!(label_components(&inside, w, h), (want, count), "{w} x {h}, {percent} %");
        }
    }

    #[test]
    fn runs_are_the_stretches_of_consecutive_pixels_within_each_row() {
        // Every 7th hash-picked pixel of a 13-wide image left out: runs that end at a row's
        // end and go on at the next row's start must split there. Then runs of every length
        // up to whole rows of 300 (one pixel in 97 left out) and whole images.
        for (w, h, gap) in [(13usize, 11usize, 7), (300, 9, 97), (300, 4, u32::MAX)] {
            let pixels: Vec<u32> = (0..(w * h) as u32).filter(|&i| !hash(i).is_multiple_of(gap)).collect();
            check_runs(&pixels, w);
        }
        assert_eq!(runs(&[], 13).count(), 0);
    }

    fn check_runs(pixels: &[u32], w: usize) {
        let got: Vec<Run> = runs(pixels, w).collect();
        let mut want: Vec<Run> = Vec::new();
        for &i in pixels {
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
    }
}
