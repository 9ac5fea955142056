//! How the live test's map scores over many runs, without running it many times: the
//! sequence is extracted once, then mapped from the frames a live run would take (the
//! mock camera at `--fps` against the looped walk, a random phase, up to `--drop` of them
//! dropped, `--seconds` long) and scored per tread against what those frames saw.
//!
//!   cargo run --release --example live_frame_patterns -- SEQ [--runs 200] [--fps 8] [--drop 0.05] [--seconds 8]
//!
//! Prints each run's worst tread the walk crosses and its top tread, then a summary.

use anyhow::{Context, Result, bail};
use polymap::config::Config;
use polymap::extract::Extractor;
use polymap::map::PolygonMap;
use polymap::sequence::Sequence;
use rand::{RngExt, SeedableRng};

fn main() -> Result<()> {
    let mut args = std::env::args().skip(1);
    let seq_dir =
        args.next().context("usage: live_frame_patterns SEQ [--runs N] [--fps HZ] [--drop P] [--seconds S]")?;
    let (mut runs, mut fps, mut drop, mut seconds) = (200u64, 8.0f64, 0.05f64, 8.0f64);
    while let Some(flag) = args.next() {
        let value: f64 = args.next().with_context(|| format!("{flag} needs a value"))?.parse()?;
        match flag.as_str() {
            "--runs" => runs = value as u64,
            "--fps" => fps = value,
            "--drop" => drop = value,
            "--seconds" => seconds = value,
            _ => bail!("unknown option {flag}"),
        }
    }
    let seq = Sequence::open(&seq_dir)?;
    let config = Config::default();
    let mut extractor = Extractor::new(&config.pipeline)?;
    let mut frames = Vec::new();
    for k in 0..seq.len() {
        let extraction = extractor.extract(&seq.depth(k)?, &seq.intrinsics)?;
        frames.push((extraction.polygons.polygons, extraction.depth));
    }
    let n = seq.len();
    let frame_rate = 1e9 * (n - 1) as f64 / (seq.poses[n - 1].stamp_ns - seq.poses[0].stamp_ns) as f64;
    let period = n as f64 / frame_rate;
    let (mut crossed_all, mut top_all) = (Vec::new(), Vec::new());
    for run in 0..runs {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(run);
        let phase = rng.random::<f64>() * period;
        let drop_share = rng.random::<f64>() * drop;
        // The first frame shown after each tick; the loop's first frame has no pose (the
        // mock VINS's loop jump), as live.
        let mut order = Vec::new();
        let mut t = phase;
        while t < phase + seconds {
            let k = ((t % period) * frame_rate).ceil() as usize % n;
            t += 1.0 / fps;
            if k != 0 && rng.random::<f64>() >= drop_share {
                order.push(k);
            }
        }
        let mut map = PolygonMap::new(&config.map);
        for &k in &order {
            map.update(&frames[k].0, &seq.poses[k], &seq.intrinsics, Some(&frames[k].1));
        }
        let mut seen = order.clone();
        seen.sort_unstable();
        seen.dedup();
        let (scores, _) = polymap::eval::map::score_map_seen_in(&map.snapshot(), &seq, &seen, false)?;
        let Some(top) = scores.iter().map(|s| s.step).max() else { continue };
        let crossed = scores.iter().filter(|s| s.step != top).map(|s| s.iou).fold(1.0, f64::min);
        let top_iou = scores.iter().find(|s| s.step == top).map_or(0.0, |s| s.iou);
        println!("run {run}: {} frames, worst crossed tread {crossed:.3}, top tread {top_iou:.3}", order.len());
        crossed_all.push(crossed);
        top_all.push(top_iou);
    }
    let summary = |v: &[f64]| {
        let min = v.iter().copied().fold(f64::INFINITY, f64::min);
        let under = v.iter().filter(|&&x| x < 0.9).count();
        format!("min {min:.3}, under 0.9 in {under} of {}", v.len())
    };
    println!("worst crossed tread: {}", summary(&crossed_all));
    println!("top tread: {}", summary(&top_all));
    Ok(())
}
