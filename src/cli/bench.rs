//! `polymap bench`: extraction timed per stage over many frames.

use anyhow::{Result, bail};

use super::progress;
use crate::config::{Backend, Config};
use crate::extract;
use crate::sequence::Sequence;

/// `polymap bench SEQ`: frames are read once, then extracted in a loop and timed.
pub fn bench(s: &Sequence, config: &Config, frames: usize, json: bool) -> Result<()> {
    if s.is_empty() || !(1..=1_000_000).contains(&frames) {
        bail!("nothing to time: {} frames, --frames {frames} (1..=1000000)", s.len());
    }
    let depth: Vec<_> = (0..s.len()).map(|k| s.depth(k)).collect::<Result<_, _>>()?;
    let mut extractor = extract::Extractor::new(&config.pipeline)?;
    // Warm-up: shader compilation, buffer allocation, the auto backend's choice.
    extractor.extract(&depth[0], &s.intrinsics)?;
    let bar = progress(frames as u64, "bench");
    let started = std::time::Instant::now();
    let mut times = Vec::with_capacity(frames);
    for k in 0..frames {
        times.push(extractor.extract(&depth[k % depth.len()], &s.intrinsics)?.times);
        bar.inc(1);
    }
    let wall = started.elapsed().as_secs_f64();
    bar.finish_and_clear();
    let stages = crate::bench::stage_spreads(&times);
    let device = match &extractor.gpu {
        Some(g) if g.has_timestamps() => format!("{}, stages by GPU timestamps", g.describe()),
        Some(g) => format!("{}, no GPU timestamps: the stages' time is in readback", g.describe()),
        None => format!(
            "CPU twin, {} threads, {} vectors",
            rayon::current_num_threads(),
            extract::cpu::simd::level().name()
        ),
    };
    let (w, h) = (s.intrinsics.width, s.intrinsics.height);
    let fps = frames as f64 / wall;
    if json {
        let per_stage: serde_json::Map<String, serde_json::Value> = stages
            .iter()
            .map(|(stage, sp)| (stage.name().to_string(), serde_json::to_value(sp).expect("plain numbers")))
            .collect();
        println!(
            "{}",
            serde_json::to_string_pretty(&serde_json::json!({
                "sequence": s.dir, "width": w, "height": h, "frames": frames,
                "backend": extractor.backend(), "device": device, "threads": rayon::current_num_threads(),
                "simd": extract::cpu::simd::level().name(), "fps": fps, "stages_ms": per_stage,
            }))?
        );
        return Ok(());
    }
    println!("{}: {frames} frames {w}x{h}, backend {} on {device}", s.dir.display(), extractor.backend());
    println!("{:>10} {:>10} {:>10}", "stage", "median ms", "p99 ms");
    for (stage, sp) in &stages {
        if stage.gpu_only() && extractor.backend() == Backend::Cpu {
            continue;
        }
        println!("{:>10} {:>10.3} {:>10.3}", stage.name(), sp.median, sp.p99);
    }
    println!("{fps:.1} frames per second end to end");
    Ok(())
}
