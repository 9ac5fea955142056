//! Records a sequence's depth as an L515-like `.bag` with librealsense's own recorder, the
//! kind realsense-viewer writes, so it plays through polymap's L515 driver code
//! (`sources.depth.kind = "bag"`):
//!
//! ```sh
//! cargo run --release --features realsense --example make_bag -- SEQ OUT.bag [FRAMES]
//! ```

use polymap::camera::realsense::bag::write_l515_bag;
use polymap::sequence::Sequence;

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (Some(seq), Some(out)) = (args.first(), args.get(1)) else {
        anyhow::bail!("usage: make_bag SEQ OUT.bag [FRAMES (default: all)]");
    };
    let frames = args.get(2).map(|n| n.parse()).transpose()?.unwrap_or(0);
    let seq = Sequence::open(seq)?;
    write_l515_bag(&seq, out.as_ref(), frames)?;
    println!(
        "{out}: {} depth frames {}x{}",
        if frames == 0 { seq.len() } else { frames.min(seq.len()) },
        seq.intrinsics.width,
        seq.intrinsics.height
    );
    Ok(())
}
