//! Reading a polymap sequence from your own code: frames, poses and truth.
//!
//! cargo run --example read_sequence -- mock_frames/straight_320

use polymap::sequence::Sequence;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let dir = std::env::args().nth(1).unwrap_or_else(|| "mock_frames/straight_320".into());
    let seq = Sequence::open(&dir)?;
    println!("{dir}: {} frames, {}x{}", seq.len(), seq.intrinsics.width, seq.intrinsics.height);
    for k in 0..seq.len() {
        let frame = seq.depth(k)?;
        let valid: Vec<f64> = frame.pixels.iter().filter(|&&d| d != 0).map(|&d| d as f64 * frame.depth_scale).collect();
        let mean = valid.iter().sum::<f64>() / valid.len().max(1) as f64;
        let t = seq.poses[k].transform.translation.vector;
        println!(
            "frame {k:3}  stamp {:.3} s  camera at ({:6.3}, {:6.3}, {:6.3}) m  {:5.1} % valid, mean depth {mean:.3} m",
            frame.stamp_ns as f64 * 1e-9,
            t.x,
            t.y,
            t.z,
            100.0 * valid.len() as f64 / frame.pixels.len() as f64
        );
    }
    if let Some(truth) = &seq.truth {
        for (i, p) in truth.polygons.iter().enumerate().filter(|(_, p)| p.label == "tread") {
            println!(
                "truth polygon {}: tread {} at {:.3} m, {} vertices",
                i + 1,
                p.step.unwrap_or(0),
                p.height,
                p.boundary.len()
            );
        }
    }
    Ok(())
}
