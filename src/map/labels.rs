//! What each map polygon is: floor, tread, landing, riser, wall or slope, each tread's step
//! index, and the staircase's step height and tread depth.
//!
//! Tilt decides horizontal / slope / vertical. Horizontal polygons are grouped into height
//! levels; the lowest is the floor, the step height is the median gap between neighbouring
//! levels, and a horizontal polygon's step is its height over the floor in step heights.
//! The top level is a landing when it is deeper than a tread; so is any raised horizontal
//! surface off the step grid. A vertical polygon no taller
//! than a step, whose top is at a level, is that step's riser; any other is a wall.

use std::collections::BTreeSet;

use serde::{Deserialize, Serialize};

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Label {
    Floor,
    Tread,
    Landing,
    Riser,
    Wall,
    Slope,
}

impl Label {
    pub fn is_horizontal(self) -> bool {
        matches!(self, Label::Floor | Label::Tread | Label::Landing)
    }
}

/// What labelling needs of a polygon.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Facts {
    /// Angle of the plane to horizontal, degrees.
    pub tilt_deg: f64,
    /// World z of the centroid, m.
    pub height: f64,
    /// Lowest and highest world z of the outline, m.
    pub z_range: [f64; 2],
    /// Width of the smallest enclosing rectangle on the plane, m.
    pub depth: f64,
    /// World x, y of the centroid, m.
    pub xy: [f64; 2],
}

/// The staircase the labels found.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Stair {
    /// Steps up from the floor to the highest tread or landing.
    pub steps: u32,
    /// Median height between neighbouring levels, m.
    pub step_height: f64,
    /// Median horizontal distance between the centroids of consecutive treads, m.
    pub tread_depth: Option<f64>,
}

/// Two horizontal polygons closer in height than this are on one level, m.
const LEVEL_GAP: f64 = 0.03;
/// A level gap counts as a step within these heights, m (stairs for people and humanoids).
const STEP_RANGE: [f64; 2] = [0.05, 0.30];
/// A top level deeper than this many tread depths is a landing.
const LANDING_DEPTH_RATIO: f64 = 1.5;

fn median(mut v: Vec<f64>) -> Option<f64> {
    median_in_place(&mut v)
}

/// A polygon's label and, for treads, landings and risers, its step.
pub type Labelled = (Label, Option<u32>);

/// The map's polygons as labelling sees them, kept up to date as they change: their facts
/// in id order (as the map's scan would meet them), their labels, and the heights of the
/// horizontal ones sorted. Relabelling the map then reads three flat arrays and touches
/// only the polygons whose label changed, instead of walking every map polygon.
#[derive(Clone, Debug, Default)]
pub struct Table {
    ids: Vec<u64>,
    facts: Vec<Facts>,
    labels: Vec<Labelled>,
    heights: BTreeSet<(Height, u64)>,
    horizontal_max_tilt_deg: f64,
    vertical_min_tilt_deg: f64,
}

impl Table {
    pub fn new(horizontal_max_tilt_deg: f64, vertical_min_tilt_deg: f64) -> Table {
        Table { horizontal_max_tilt_deg, vertical_min_tilt_deg, ..Table::default() }
    }

    /// Polygon `id` has these facts now (new ones start as a slope without step).
    pub fn set(&mut self, id: u64, facts: Facts) {
        let k = match self.ids.binary_search(&id) {
            Ok(k) => {
                self.heights.remove(&(Height(self.facts[k].height), id));
                self.facts[k] = facts;
                k
            }
            Err(k) => {
                self.ids.insert(k, id);
                self.facts.insert(k, facts);
                self.labels.insert(k, (Label::Slope, None));
                k
            }
        };
        if self.facts[k].tilt_deg <= self.horizontal_max_tilt_deg {
            self.heights.insert((Height(facts.height), id));
        }
    }

    pub fn remove(&mut self, id: u64) {
        if let Ok(k) = self.ids.binary_search(&id) {
            self.heights.remove(&(Height(self.facts[k].height), id));
            self.ids.remove(k);
            self.facts.remove(k);
            self.labels.remove(k);
        }
    }

    /// Polygon `id`'s label and step (a slope without step for one not in the table).
    pub fn labelled(&self, id: u64) -> Labelled {
        self.ids.binary_search(&id).map_or((Label::Slope, None), |k| self.labels[k])
    }

    /// Labels everything again: the polygons whose label or step changed, and the stair.
    /// One pass over the flat facts and a few lookups in the sorted heights, without
    /// sorting or allocating per polygon: a map of 30,000 polygons relabels every frame.
    pub fn relabel(&mut self) -> (Vec<u64>, Option<Stair>) {
        let levels = self.levels();
        let gaps: Vec<f64> =
            levels.windows(2).map(|w| w[1] - w[0]).filter(|g| (STEP_RANGE[0]..=STEP_RANGE[1]).contains(g)).collect();
        let grid = median(gaps).zip(levels.first().copied()).map(|(rise, floor)| StepGrid { rise, floor });
        let step_of = |h: f64| grid.and_then(|g| g.step_of(h));
        // The highest step: step_of grows with the height where it is defined, so it is
        // that of the highest height that has one.
        let top = self.heights.iter().rev().find_map(|(h, _)| step_of(h.0)).unwrap_or(0);
        let horizontal = |f: &Facts| f.tilt_deg <= self.horizontal_max_tilt_deg;
        let mut tread_depths: Vec<f64> = self
            .facts
            .iter()
            .filter(|f| horizontal(f) && matches!(step_of(f.height), Some(k) if k >= 1 && k < top))
            .map(|f| f.depth)
            .collect();
        let typical_tread = median_in_place(&mut tread_depths);
        let floor = levels.first().copied();
        let label_of = |f: &Facts| -> Labelled {
            if horizontal(f) {
                let on_floor = floor.is_some_and(|floor| f.height - floor < LEVEL_GAP);
                return match step_of(f.height) {
                    _ if on_floor => (Label::Floor, Some(0)),
                    Some(k) if k >= 1 && k < top => (Label::Tread, Some(k)),
                    Some(k) if k >= 1 && typical_tread.is_some_and(|t| f.depth <= LANDING_DEPTH_RATIO * t) => {
                        (Label::Tread, Some(k))
                    }
                    // The top of a flight, or a raised surface off the step grid (a platform, a box).
                    step => (Label::Landing, step.filter(|&k| k >= 1)),
                };
            }
            if f.tilt_deg < self.vertical_min_tilt_deg {
                return (Label::Slope, None);
            }
            let tall = f.z_range[1] - f.z_range[0];
            let riser = grid.and_then(|g| {
                let k = g.step_of(f.z_range[1])?;
                (k >= 1 && tall <= 1.5 * g.rise).then_some(k)
            });
            match riser {
                Some(k) => (Label::Riser, Some(k)),
                None => (Label::Wall, None),
            }
        };
        let mut changed = Vec::new();
        // Tread depth: horizontal distance between the centroids of treads one step apart,
        // the last tread of step k (in id order) to the first of step k + 1.
        let mut ends: Vec<Option<([f64; 2], [f64; 2])>> = vec![None; top as usize + 1];
        for ((id, f), old) in self.ids.iter().zip(&self.facts).zip(&mut self.labels) {
            let new = label_of(f);
            if *old != new {
                *old = new;
                changed.push(*id);
            }
            if let (Label::Tread, Some(k)) = new
                && let Some(end) = ends.get_mut(k as usize)
            {
                end.get_or_insert((f.xy, f.xy)).1 = f.xy;
            }
        }
        let goings: Vec<f64> = ends
            .windows(2)
            .filter_map(|w| match w {
                [Some((_, last)), Some((first, _))] => Some((first[0] - last[0]).hypot(first[1] - last[1])),
                _ => None,
            })
            .collect();
        let stair =
            grid.filter(|_| top >= 1).map(|g| Stair { steps: top, step_height: g.rise, tread_depth: median(goings) });
        (changed, stair)
    }

    /// The height levels: the lowest horizontal height, then each first height at least
    /// [`LEVEL_GAP`] above the last level, found by a lookup in the sorted heights rather
    /// than a walk over them.
    fn levels(&self) -> Vec<f64> {
        let mut levels: Vec<f64> = Vec::new();
        let mut next = self.heights.iter().next().map(|(h, _)| h.0);
        while let Some(level) = next {
            levels.push(level);
            // Start a hair below, then test as the definition does (h - level < gap), so
            // rounding of level + gap decides nothing.
            let from = (Height(level + LEVEL_GAP - 1e-9), 0);
            next = self.heights.range(from..).map(|(h, _)| h.0).find(|&h| h - level >= LEVEL_GAP);
        }
        levels
    }
}

/// Steps of `rise` above `floor`.
#[derive(Clone, Copy, Debug)]
struct StepGrid {
    rise: f64,
    floor: f64,
}

impl StepGrid {
    /// The step a height is on, when it is within 0.3 rise of one.
    fn step_of(self, h: f64) -> Option<u32> {
        let k = ((h - self.floor) / self.rise).round();
        ((h - self.floor - k * self.rise).abs() < 0.3 * self.rise && k >= 0.0).then_some(k as u32)
    }
}

/// The median, by selection instead of a sort.
fn median_in_place(v: &mut [f64]) -> Option<f64> {
    let n = v.len();
    if n == 0 {
        return None;
    }
    let (lower, mid, _) = v.select_nth_unstable_by(n / 2, f64::total_cmp);
    let mid = *mid;
    Some(if n % 2 == 1 { mid } else { (lower.iter().copied().fold(f64::NEG_INFINITY, f64::max) + mid) / 2.0 })
}

/// A height with a total order (f64::total_cmp), to keep heights sorted in a set.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Height(pub f64);

impl Eq for Height {}

impl PartialOrd for Height {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for Height {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        self.0.total_cmp(&other.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The labelling as first written: the definition `Table::relabel` is held to.
    /// `horizontal_heights` are the heights of the horizontal facts (tilt up to
    /// `horizontal_max_tilt_deg`), ascending: the map keeps them sorted as its polygons change,
    /// so labelling a large map does not sort it every frame.
    fn label_by_definition(
        facts: &[Facts],
        horizontal_heights: impl IntoIterator<Item = f64>,
        horizontal_max_tilt_deg: f64,
        vertical_min_tilt_deg: f64,
    ) -> (Vec<(Label, Option<u32>)>, Option<Stair>) {
        let horizontal: Vec<usize> =
            (0..facts.len()).filter(|&i| facts[i].tilt_deg <= horizontal_max_tilt_deg).collect();
        let mut levels: Vec<f64> = Vec::new();
        for h in horizontal_heights {
            match levels.last() {
                Some(&l) if h - l < LEVEL_GAP => {}
                _ => levels.push(h),
            }
        }
        let gaps: Vec<f64> =
            levels.windows(2).map(|w| w[1] - w[0]).filter(|g| (STEP_RANGE[0]..=STEP_RANGE[1]).contains(g)).collect();
        let step_height = sorted_median(gaps);
        let floor = levels.first().copied();
        let step_of = |h: f64| -> Option<u32> {
            let (rise, floor) = (step_height?, floor?);
            let k = ((h - floor) / rise).round();
            ((h - floor - k * rise).abs() < 0.3 * rise && k >= 0.0).then_some(k as u32)
        };

        let mut out: Vec<(Label, Option<u32>)> = vec![(Label::Slope, None); facts.len()];
        let top = horizontal.iter().filter_map(|&i| step_of(facts[i].height)).max().unwrap_or(0);
        let tread_depths: Vec<f64> = horizontal
            .iter()
            .filter(|&&i| matches!(step_of(facts[i].height), Some(k) if k >= 1 && k < top))
            .map(|&i| facts[i].depth)
            .collect();
        let typical_tread = sorted_median(tread_depths);
        for &i in &horizontal {
            let on_floor = floor.is_some_and(|f| facts[i].height - f < LEVEL_GAP);
            out[i] = match step_of(facts[i].height) {
                _ if on_floor => (Label::Floor, Some(0)),
                Some(k) if k >= 1 && k < top => (Label::Tread, Some(k)),
                Some(k) if k >= 1 && typical_tread.is_some_and(|t| facts[i].depth <= LANDING_DEPTH_RATIO * t) => {
                    (Label::Tread, Some(k))
                }
                // The top of a flight, or a raised surface off the step grid (a platform, a box).
                step => (Label::Landing, step.filter(|&k| k >= 1)),
            };
        }
        for (i, f) in facts.iter().enumerate() {
            if f.tilt_deg < vertical_min_tilt_deg {
                continue;
            }
            let tall = f.z_range[1] - f.z_range[0];
            let riser = step_height.and_then(|rise| {
                let k = step_of(f.z_range[1])?;
                (k >= 1 && tall <= 1.5 * rise).then_some(k)
            });
            out[i] = match riser {
                Some(k) => (Label::Riser, Some(k)),
                None => (Label::Wall, None),
            };
        }

        // Tread depth: horizontal distance between the centroids of treads one step apart.
        let mut by_step: Vec<(u32, [f64; 2])> = horizontal
            .iter()
            .filter_map(|&i| match out[i] {
                (Label::Tread, Some(k)) => Some((k, facts[i].xy)),
                _ => None,
            })
            .collect();
        by_step.sort_by_key(|s| s.0);
        let goings: Vec<f64> = by_step
            .windows(2)
            .filter(|w| w[1].0 == w[0].0 + 1)
            .map(|w| (w[1].1[0] - w[0].1[0]).hypot(w[1].1[1] - w[0].1[1]))
            .collect();
        let stair = step_height.filter(|_| top >= 1).map(|step_height| Stair {
            steps: top,
            step_height,
            tread_depth: sorted_median(goings),
        });
        (out, stair)
    }

    /// Median by sorting, as the definition had it.
    fn sorted_median(mut v: Vec<f64>) -> Option<f64> {
        if v.is_empty() {
            return None;
        }
        v.sort_by(f64::total_cmp);
        let n = v.len();
        Some(if n % 2 == 1 { v[n / 2] } else { (v[n / 2 - 1] + v[n / 2]) / 2.0 })
    }

    #[test]
    fn relabelling_is_the_definition_on_random_staircases() {
        let mut state = 11u32;
        let mut rnd = || {
            state = crate::extract::cpu::ransac::hash(state);
            state as f64 / u32::MAX as f64
        };
        let mut labels_seen = std::collections::HashSet::new();
        for trial in 0..200 {
            let mut table = Table::new(10.0, 70.0);
            let rise = 0.1 + 0.1 * rnd();
            let n = 1 + (rnd() * 60.0) as u64;
            for id in 0..n {
                let step = (rnd() * 8.0).floor();
                let kind = rnd();
                let jitter = 0.02 * (rnd() - 0.5) + if rnd() < 0.1 { rise * 0.45 } else { 0.0 };
                let height = 0.3 + step * rise + jitter;
                let facts = Facts {
                    tilt_deg: if kind < 0.6 {
                        3.0 * rnd()
                    } else if kind < 0.9 {
                        80.0 + 10.0 * rnd()
                    } else {
                        30.0
                    },
                    height,
                    z_range: [height - rise * (0.3 + rnd()), height + 0.01 * rnd()],
                    depth: 0.2 + 0.3 * rnd() + if rnd() < 0.1 { 1.0 } else { 0.0 },
                    xy: [step * 0.3 + 0.05 * rnd(), rnd()],
                };
                table.set(id * 3 + (trial % 3), facts);
            }
            // Some removed again, as polygons are cleared.
            for id in 0..n / 5 {
                table.remove(id * 15);
            }
            let heights: Vec<f64> = table.heights.iter().map(|(h, _)| h.0).collect();
            let (want, want_stair) = label_by_definition(&table.facts, heights, 10.0, 70.0);
            let (_, stair) = table.relabel();
            assert_eq!(table.labels, want, "trial {trial}");
            assert_eq!(stair, want_stair, "trial {trial}");
            labels_seen.extend(want.iter().map(|l| l.0));
        }
        assert_eq!(labels_seen.len(), 6, "every label met: {labels_seen:?}");
    }
}
