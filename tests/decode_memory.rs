//! What garbage on the odometry topic can make polymap allocate: the 16-byte message that
//! claims a 4 GiB string, and 10,000 mutations of a real odometry message, through the path
//! a sample takes (CDR decoding, the pose's conversion and checks, the pose buffer), with
//! every allocation counted. Alone in its test binary, so nothing else allocates meanwhile.

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

use parking_lot::Mutex;
use polymap::interface::convert;
use polymap::pose::{PoseBuffer, PoseLimits, RawPose};
use polymap::ros2::{cdr, msg::Odometry};
use rand::{RngExt, SeedableRng};

/// The system allocator, counting the bytes it holds and the most it held.
struct Counting;

static HELD: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        // SAFETY: forwarded as is.
        let p = unsafe { System.alloc(layout) };
        if !p.is_null() {
            let held = HELD.fetch_add(layout.size(), Ordering::Relaxed) + layout.size();
            PEAK.fetch_max(held, Ordering::Relaxed);
        }
        p
    }
    unsafe fn dealloc(&self, p: *mut u8, layout: Layout) {
        // SAFETY: forwarded as is.
        unsafe { System.dealloc(p, layout) };
        HELD.fetch_sub(layout.size(), Ordering::Relaxed);
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

/// One message through the odometry path, as the subscription hands it on.
fn take(buffer: &Mutex<PoseBuffer>, bytes: &[u8]) {
    let pose =
        cdr::from_slice::<Odometry>(bytes).map_err(|e| e.to_string()).and_then(|m| convert::pose_of_odometry(&m));
    polymap::runtime::odometry::take(buffer, "/odometry", polymap::runtime::odometry::Stream::Optimised, pose);
}

#[test]
fn the_16_byte_bomb_and_10000_mutated_odometry_messages_stay_within_a_few_megabytes() {
    let buffer = Mutex::new(PoseBuffer::with_limits(100, PoseLimits::from_config(&Default::default())));
    let now = polymap::clock::now_ns();
    let good = cdr::to_vec(&convert::odometry(
        &RawPose { stamp_ns: now - 1_000_000, position: [1.0, 2.0, 0.5], quat_xyzw: [0.0, 0.0, 0.0, 1.0] },
        "world",
        "body",
    ));
    // Where the message's lengths are: the frame id's (after the 4-byte header and the
    // stamp) and the child frame id's.
    let length_at = [12usize, 24];
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(14);
    let mut mutated = Vec::with_capacity(10_000);
    for k in 0..10_000 {
        let mut m = good.clone();
        match k % 4 {
            // A length claiming far more than there is.
            0 => {
                let at = length_at[rng.random_range(0..2)];
                let claim: u32 = rng.random_range(m.len() as u32..=u32::MAX);
                m[at..at + 4].copy_from_slice(&claim.to_le_bytes());
            }
            // Cut short.
            1 => m.truncate(rng.random_range(0..m.len() - 1)),
            // Not CDR at all.
            2 => m = (0..rng.random_range(0..2048)).map(|_| rng.random()).collect(),
            // A wrong encapsulation header.
            _ => m[1] = rng.random_range(2..=255),
        }
        mutated.push(m);
    }
    let bomb: [u8; 16] = [0x00, 0x01, 0x00, 0x00, 1, 0, 0, 0, 0, 0, 0, 0, 0xf0, 0xff, 0xff, 0xff];

    let before = HELD.load(Ordering::Relaxed);
    PEAK.store(before, Ordering::Relaxed);
    take(&buffer, &bomb);
    for m in &mutated {
        take(&buffer, m);
    }
    let peak = PEAK.load(Ordering::Relaxed) - before;

    let c = buffer.lock().counters;
    eprintln!("decoding the bomb and 10,000 mutations held at most {peak} bytes more; {c:?}");
    assert!(peak < 4 << 20, "the decoding path held {peak} bytes");
    assert_eq!(c.accepted, 0, "none of them is a pose");
    assert_eq!(c.undecodable + c.rejected, 10_001, "every one counted");
    assert!(buffer.lock().is_empty());
    // The real stream is not disturbed by them.
    take(&buffer, &good);
    assert_eq!(buffer.lock().counters.accepted, 1);
}
