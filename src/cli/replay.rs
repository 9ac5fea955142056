//! `polymap replay`: a sequence, or a robot's log (ROS 1 bag, MCAP), through extraction and
//! the map, with a line of what it made, the map's JSON and its top-down picture.

use std::path::Path;

use anyhow::{Context, Result, bail};

use super::progress;
use crate::config::Config;
use crate::eval::drift;
use crate::logs::{Log, LogKind, LogTopics};
use crate::map::persist::initial_map;
use crate::map::render::top_down;
use crate::replay::{replay as replay_sequence, write_json};
use crate::sequence::Sequence;

/// Replays the sequence or log at `seq` (a log's topics by its kind, `topics`) into the
/// configured map; the map's JSON to `out`, its picture to `render`.
pub fn replay(
    seq: &Path,
    topics: impl Fn(LogKind) -> LogTopics,
    config: &Config,
    out: Option<&Path>,
    render: Option<&Path>,
    drift_trace: Option<&Path>,
) -> Result<()> {
    if let Some(log) = Log::find(seq)? {
        let mut map = initial_map(&config.map);
        let bar = progress(0, "replay");
        let r = crate::logs::replay(&log, &topics(log.kind), config, &mut map, |done, of| {
            bar.set_length(of);
            bar.set_position(done);
        })?;
        bar.finish_and_clear();
        if r.mapped == 0 {
            bail!("{}: no image mapped: {r}", seq.display());
        }
        println!("{}: {r} -> {} map polygons; drift {:.1} mm", seq.display(), map.len(), map.drift.z * 1e3);
        if let Some(path) = out {
            write_json(&mut map, path)?;
        }
        if drift_trace.is_some() {
            bail!("--drift-trace takes a sequence (its truth has the drift injected), not a log");
        }
        if let Some(path) = render {
            top_down(&map.snapshot(), None).save(path).with_context(|| format!("writing {}", path.display()))?;
        }
        return Ok(());
    }
    let s = Sequence::open(seq)?;
    let mut map = initial_map(&config.map);
    let bar = progress(s.len() as u64, "replay");
    let mut trace = Vec::new();
    replay_sequence(&s, config, &mut map, |k, update, map| {
        bar.inc(1);
        trace.push(drift::sample(k, map, update, s.truth.as_ref()));
    })?;
    bar.finish_and_clear();
    if let Some(stem) = drift_trace {
        let with = |ext: &str| std::path::PathBuf::from(format!("{}.{ext}", stem.display()));
        let (csv, png) = (with("csv"), with("png"));
        drift::write_csv(&trace, &csv).with_context(|| format!("writing {}", csv.display()))?;
        let name = s.dir.file_name().map_or(s.dir.display().to_string(), |n| n.to_string_lossy().into_owned());
        let title = format!("{name}: injected black, estimated blue (2 sigma shaded)");
        drift::plot(&trace, &title).save(&png).with_context(|| format!("writing {}", png.display()))?;
    }
    let c = map.counters;
    println!(
        "{}: {} frames -> {} map polygons ({} merges, {} cleared, {} rejected); drift {:.1} mm (sd {:.1} mm)",
        seq.display(),
        s.len(),
        map.len(),
        c.merged,
        c.cleared,
        c.rejected,
        map.drift.z * 1e3,
        map.drift.var().sqrt() * 1e3
    );
    if let Some(st) = map.stair() {
        println!(
            "stair: {} steps, step height {:.1} mm, tread depth {}",
            st.steps,
            st.step_height * 1e3,
            st.tread_depth.map_or("-".into(), |d| format!("{:.1} mm", d * 1e3))
        );
    }
    if let Some(path) = out {
        write_json(&mut map, path)?;
    }
    if let Some(path) = render {
        top_down(&map.snapshot(), s.truth.as_ref())
            .save(path)
            .with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(())
}
