//! `polymap bench`: per-stage and end-to-end time per frame over many frames, the
//! runtime metric of REFERENCE.md (median and p99 over at least 300 frames).

use crate::extract::StageTimes;
use crate::stats::{Spread, spread};

/// What `polymap bench` times of a frame: its stages in pipeline order, the frame's total,
/// and the GPU's busy time.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stage {
    Upload,
    Diffusion,
    Normals,
    Edges,
    Regions,
    Readback,
    Contours,
    Ransac,
    Polygons,
    Total,
    GpuBusy,
}

impl Stage {
    pub const ALL: [Stage; 11] = [
        Stage::Upload,
        Stage::Diffusion,
        Stage::Normals,
        Stage::Edges,
        Stage::Regions,
        Stage::Readback,
        Stage::Contours,
        Stage::Ransac,
        Stage::Polygons,
        Stage::Total,
        Stage::GpuBusy,
    ];

    /// Its name in `polymap bench`'s table and JSON.
    pub fn name(self) -> &'static str {
        match self {
            Stage::Upload => "upload",
            Stage::Diffusion => "diffusion",
            Stage::Normals => "normals",
            Stage::Edges => "edges",
            Stage::Regions => "regions",
            Stage::Readback => "readback",
            Stage::Contours => "contours",
            Stage::Ransac => "ransac",
            Stage::Polygons => "polygons",
            Stage::Total => "total",
            Stage::GpuBusy => "gpu_busy",
        }
    }

    /// Whether only the GPU twin has this time (the CPU twin's is 0: nothing to read back,
    /// no GPU to be busy).
    pub fn gpu_only(self) -> bool {
        matches!(self, Stage::Readback | Stage::GpuBusy)
    }

    /// Its time in one frame's `StageTimes`, ms.
    pub fn of(self, t: &StageTimes) -> f64 {
        match self {
            Stage::Upload => t.upload,
            Stage::Diffusion => t.diffusion,
            Stage::Normals => t.normals,
            Stage::Edges => t.edges,
            Stage::Regions => t.regions,
            Stage::Readback => t.readback,
            Stage::Contours => t.contours,
            Stage::Ransac => t.ransac,
            Stage::Polygons => t.polygons,
            Stage::Total => t.total,
            Stage::GpuBusy => t.gpu_busy,
        }
    }
}

/// Every stage's spread over the frames, in pipeline order.
pub fn stage_spreads(times: &[StageTimes]) -> Vec<(Stage, Spread)> {
    Stage::ALL.iter().map(|&s| (s, spread(&times.iter().map(|t| s.of(t)).collect::<Vec<_>>()))).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_stage_reads_its_own_time_under_its_own_name() {
        let t = StageTimes {
            upload: 1.0,
            diffusion: 2.0,
            normals: 3.0,
            edges: 4.0,
            regions: 5.0,
            readback: 6.0,
            contours: 7.0,
            ransac: 8.0,
            polygons: 9.0,
            total: 10.0,
            gpu_busy: 11.0,
        };
        let json = serde_json::to_value(t).expect("plain numbers");
        for stage in Stage::ALL {
            assert_eq!(json[stage.name()].as_f64(), Some(stage.of(&t)), "{stage:?}: the field of its name");
        }
        let spreads = stage_spreads(&[t, StageTimes { diffusion: 4.0, ..t }, StageTimes { diffusion: 6.0, ..t }]);
        assert_eq!(spreads.len(), 11);
        assert_eq!(spreads[1].0, Stage::Diffusion);
        assert_eq!((spreads[1].1.median, spreads[1].1.p99), (4.0, 6.0));
        let gpu_only: Vec<Stage> = Stage::ALL.into_iter().filter(|s| s.gpu_only()).collect();
        assert_eq!(gpu_only, [Stage::Readback, Stage::GpuBusy]);
    }
}
