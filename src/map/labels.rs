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

/// Labels and steps of `facts`, in order, and the stair if there is one.
/// `horizontal_heights` are the heights of the horizontal facts (tilt up to
/// `horizontal_max_tilt_deg`), ascending: the map keeps them sorted as its polygons change,
/// so labelling a large map does not sort it every frame.
pub fn label(
    facts: &[Facts],
    horizontal_heights: impl IntoIterator<Item = f64>,
    horizontal_max_tilt_deg: f64,
    vertical_min_tilt_deg: f64,
) -> (Vec<(Label, Option<u32>)>, Option<Stair>) {
    let horizontal: Vec<usize> = (0..facts.len()).filter(|&i| facts[i].tilt_deg <= horizontal_max_tilt_deg).collect();
    let mut levels: Vec<f64> = Vec::new();
    for h in horizontal_heights {
        match levels.last() {
            Some(&l) if h - l < LEVEL_GAP => {}
            _ => levels.push(h),
        }
    }
    let gaps: Vec<f64> =
        levels.windows(2).map(|w| w[1] - w[0]).filter(|g| (STEP_RANGE[0]..=STEP_RANGE[1]).contains(g)).collect();
    let step_height = median(gaps);
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
    let typical_tread = median(tread_depths);
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
        tread_depth: median(goings),
    });
    (out, stair)
}

fn median(mut v: Vec<f64>) -> Option<f64> {
    if v.is_empty() {
        return None;
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    Some(if n % 2 == 1 { v[n / 2] } else { (v[n / 2 - 1] + v[n / 2]) / 2.0 })
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
    pub fn relabel(&mut self) -> (Vec<u64>, Option<Stair>) {
        let heights = self.heights.iter().map(|(h, _)| h.0);
        let (out, stair) = label(&self.facts, heights, self.horizontal_max_tilt_deg, self.vertical_min_tilt_deg);
        let mut changed = Vec::new();
        for ((id, old), new) in self.ids.iter().zip(&mut self.labels).zip(out) {
            if *old != new {
                *old = new;
                changed.push(*id);
            }
        }
        (changed, stair)
    }
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
