//! The on-disk sequence format, read and written.
//!
//! ```text
//! SEQ/camera.toml        width, height, fx, fy, cx, cy, depth_scale (metres per depth unit)
//! SEQ/depth/NNNNNN.png   16-bit grayscale PNG per frame, 000000.png first, 0 = invalid
//! SEQ/poses.txt          TUM "stamp tx ty tz qx qy qz qw" = T_world_camera, one per frame
//! SEQ/truth.json         optional ground-truth polygons in the world frame (z up)
//! SEQ/labels/NNNNNN.png  optional 16-bit index into truth.json's polygons (1-based), 0 = none
//! ```
//!
//! Opening a sequence checks everything except pixel values and reports the first
//! problem with its file (and line, for poses.txt).

use std::fs::{self, File};
use std::io::{BufReader, BufWriter, Write};
use std::path::{Path, PathBuf};

use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion};
use serde::{Deserialize, Serialize};

use crate::types::{DepthFrame, Intrinsics, Pose, StampNs, ns_to_seconds_string};

/// What kind of problem a sequence has; the message says the details.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SequenceErrorKind {
    Io,
    BadCamera,
    MissingFrame,
    BadFrameName,
    BadPng,
    BitDepth,
    SizeMismatch,
    BadPoseLine,
    NonUnitQuaternion,
    StampOrder,
    PoseCount,
    BadTruth,
}

/// A problem with a sequence, naming the file (and the line where there is one).
#[derive(Debug, thiserror::Error)]
#[error("{}{}: {reason}", path.display(), line.map(|l| format!(":{l}")).unwrap_or_default())]
pub struct SequenceError {
    pub path: PathBuf,
    pub line: Option<usize>,
    pub kind: SequenceErrorKind,
    pub reason: String,
}

fn err(path: &Path, kind: SequenceErrorKind, reason: impl Into<String>) -> SequenceError {
    SequenceError { path: path.to_owned(), line: None, kind, reason: reason.into() }
}

fn io_err(path: &Path, e: impl std::fmt::Display) -> SequenceError {
    err(path, SequenceErrorKind::Io, e.to_string())
}

/// Ground truth of a synthetic (or surveyed) scene, in the world frame.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Truth {
    /// The staircase's dimensions, when the scene has one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stair: Option<StairTruth>,
    pub polygons: Vec<TruthPolygon>,
    /// Vertical drift injected into poses.txt, m per frame: frame k's true camera height is
    /// its written one minus k times this.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub pose_drift_per_frame: f64,
    /// Horizontal and yaw drift injected into poses.txt beside the vertical one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pose_drift: Option<HorizontalDrift>,
}

/// Drift in x, y and yaw as `polymap synth` injects it: frame k's written pose is D_k times
/// its true one, D_k a turn by k `yaw_deg_per_frame` about `pivot` (the walk's start, seen
/// from above) then a shift by k `xy_per_frame`, and after `jump` its step as well.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HorizontalDrift {
    /// m per frame.
    pub xy_per_frame: [f64; 2],
    pub yaw_deg_per_frame: f64,
    /// m, world.
    pub pivot: [f64; 2],
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub jump: Option<PoseJump>,
}

/// A step of the odometry (a loop closure) from frame `frame` on: a turn by `yaw_deg` about
/// the pivot, then a shift by `xyz` (m).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PoseJump {
    pub frame: usize,
    pub xyz: [f64; 3],
    pub yaw_deg: f64,
}

impl HorizontalDrift {
    /// D_k without its vertical part.
    pub fn at(&self, k: usize) -> nalgebra::Isometry3<f64> {
        let turn = |deg: f64| {
            let p = nalgebra::Vector3::new(self.pivot[0], self.pivot[1], 0.0);
            nalgebra::Translation3::from(p)
                * nalgebra::UnitQuaternion::from_euler_angles(0.0, 0.0, deg.to_radians())
                * nalgebra::Translation3::from(-p)
        };
        let [x, y] = self.xy_per_frame.map(|v| v * k as f64);
        let mut d = nalgebra::Translation3::new(x, y, 0.0) * turn(self.yaw_deg_per_frame * k as f64);
        if let Some(j) = self.jump.as_ref().filter(|j| k >= j.frame) {
            d = nalgebra::Translation3::from(nalgebra::Vector3::from(j.xyz)) * turn(j.yaw_deg) * d;
        }
        d
    }
}

fn is_zero(v: &f64) -> bool {
    *v == 0.0
}

impl Truth {
    /// Frame k's true pose, from the pose poses.txt gives it.
    pub fn true_pose(&self, k: usize, written: &nalgebra::Isometry3<f64>) -> nalgebra::Isometry3<f64> {
        self.drift_at(k).inverse() * written
    }

    /// D_k: the drift injected into frame k's pose (written = D_k true).
    pub fn drift_at(&self, k: usize) -> nalgebra::Isometry3<f64> {
        let horizontal = self.pose_drift.as_ref().map_or_else(nalgebra::Isometry3::identity, |d| d.at(k));
        nalgebra::Translation3::new(0.0, 0.0, self.pose_drift_per_frame * k as f64) * horizontal
    }
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StairTruth {
    /// "straight" or "spiral".
    pub kind: String,
    pub steps: u32,
    /// Riser height, m.
    pub rise: f64,
    /// Tread depth along the walking line, m (spiral: at the walking radius).
    pub going: f64,
    /// Stair width, m (spiral: outer radius minus post radius).
    pub width: f64,
}

/// One true planar surface.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TruthPolygon {
    /// tread, riser, floor, landing, side, post, box_top, box_side.
    pub label: String,
    /// Step index: tread k is the k-th tread above the floor, riser k rises to it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub step: Option<u32>,
    /// Height of a horizontal surface; of the top edge for any other, m.
    pub height: f64,
    /// Outer boundary, counter-clockwise seen from the side the normal points to.
    pub boundary: Vec<[f64; 3]>,
}

/// A readable sequence whose structure has been checked.
#[derive(Clone, Debug)]
pub struct Sequence {
    pub dir: PathBuf,
    pub intrinsics: Intrinsics,
    /// T_world_camera of each frame, stamps strictly increasing.
    pub poses: Vec<Pose>,
    pub truth: Option<Truth>,
    pub has_labels: bool,
}

fn frame_name(k: usize) -> String {
    format!("{k:06}.png")
}

impl Sequence {
    pub fn open(dir: impl AsRef<Path>) -> Result<Sequence, SequenceError> {
        let dir = dir.as_ref().to_owned();
        let intrinsics = read_camera(&dir.join("camera.toml"))?;
        let frames = count_frames(&dir.join("depth"))?;
        let poses = read_poses(&dir.join("poses.txt"), frames)?;
        let truth_path = dir.join("truth.json");
        let truth = if truth_path.exists() { Some(read_truth(&truth_path)?) } else { None };
        let labels_dir = dir.join("labels");
        let has_labels = labels_dir.is_dir();
        if has_labels && truth.is_none() {
            return Err(err(&labels_dir, SequenceErrorKind::BadTruth, "labels/ needs truth.json beside it"));
        }
        for k in 0..frames {
            check_png_header(&dir.join("depth").join(frame_name(k)), &intrinsics)?;
            if has_labels {
                check_png_header(&labels_dir.join(frame_name(k)), &intrinsics)?;
            }
        }
        Ok(Sequence { dir, intrinsics, poses, truth, has_labels })
    }

    pub fn len(&self) -> usize {
        self.poses.len()
    }

    pub fn is_empty(&self) -> bool {
        self.poses.is_empty()
    }

    pub fn depth_path(&self, k: usize) -> PathBuf {
        self.dir.join("depth").join(frame_name(k))
    }

    /// Frame k's depth, stamped with its pose's stamp.
    pub fn depth(&self, k: usize) -> Result<DepthFrame, SequenceError> {
        let pose = self.poses.get(k).ok_or_else(|| {
            err(
                &self.depth_path(k),
                SequenceErrorKind::MissingFrame,
                format!("no frame {k}: the sequence has {}", self.len()),
            )
        })?;
        let pixels = read_png16(&self.depth_path(k), &self.intrinsics)?;
        Ok(DepthFrame {
            stamp_ns: pose.stamp_ns,
            width: self.intrinsics.width,
            height: self.intrinsics.height,
            depth_scale: self.intrinsics.depth_scale,
            pixels,
        })
    }

    /// Frame k's truth labels (1-based indices into `truth.polygons`, 0 = none).
    pub fn labels(&self, k: usize) -> Result<Vec<u16>, SequenceError> {
        let path = self.dir.join("labels").join(frame_name(k));
        if !self.has_labels {
            return Err(err(&path, SequenceErrorKind::MissingFrame, "this sequence has no labels/"));
        }
        let labels = read_png16(&path, &self.intrinsics)?;
        let n = self.truth.as_ref().map_or(0, |t| t.polygons.len());
        if let Some(bad) = labels.iter().find(|&&l| l as usize > n) {
            return Err(err(
                &path,
                SequenceErrorKind::BadTruth,
                format!("label {bad} but truth.json has {n} polygons"),
            ));
        }
        Ok(labels)
    }
}

/// The most a sequence's text files hold: camera.toml a few lines; poses.txt about 100 bytes
/// a frame, so a day at 30 Hz; truth.json a scene of a few thousand polygons.
const MAX_CAMERA_BYTES: u64 = 64 << 10;
const MAX_POSES_BYTES: u64 = 1 << 30;
const MAX_TRUTH_BYTES: u64 = 256 << 20;

fn read_camera(path: &Path) -> Result<Intrinsics, SequenceError> {
    let text = crate::files::read_text_capped(path, MAX_CAMERA_BYTES).map_err(|e| io_err(path, e))?;
    let intr: Intrinsics =
        toml::from_str(&text).map_err(|e| err(path, SequenceErrorKind::BadCamera, e.to_string().trim_end()))?;
    match intr.problem() {
        Some(p) => Err(err(path, SequenceErrorKind::BadCamera, p)),
        None => Ok(intr),
    }
}

/// Number of frames in depth/, which must be 000000.png .. without gaps.
fn count_frames(depth_dir: &Path) -> Result<usize, SequenceError> {
    let entries = fs::read_dir(depth_dir).map_err(|e| io_err(depth_dir, e))?;
    let mut indices = Vec::new();
    for entry in entries {
        let name = entry.map_err(|e| io_err(depth_dir, e))?.file_name();
        let name = name.to_string_lossy();
        let Some(stem) = name.strip_suffix(".png") else { continue };
        match stem.parse::<usize>() {
            Ok(k) if stem.len() == 6 => indices.push(k),
            _ => {
                return Err(err(
                    &depth_dir.join(&*name),
                    SequenceErrorKind::BadFrameName,
                    "depth frames must be named NNNNNN.png (six digits)",
                ));
            }
        }
    }
    if indices.is_empty() {
        return Err(err(depth_dir, SequenceErrorKind::MissingFrame, "no depth frames (expected 000000.png ...)"));
    }
    indices.sort_unstable();
    if let Some(missing) = indices.iter().enumerate().find(|(i, k)| i != *k).map(|(i, _)| i) {
        return Err(err(
            &depth_dir.join(frame_name(missing)),
            SequenceErrorKind::MissingFrame,
            format!(
                "missing: frames must be numbered from 000000.png without gaps, found {} up to {}",
                indices.len(),
                frame_name(*indices.last().unwrap())
            ),
        ));
    }
    Ok(indices.len())
}

/// Exact decimal seconds to nanoseconds ("12.5" -> 12_500_000_000); exponents fall back to f64.
pub fn parse_stamp(s: &str) -> Option<StampNs> {
    if s.contains(['e', 'E']) {
        return crate::types::seconds_to_ns(s.parse().ok()?);
    }
    let (int, frac) = s.split_once('.').unwrap_or((s, ""));
    if int.is_empty() || !int.bytes().all(|b| b.is_ascii_digit()) || !frac.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    let secs: u64 = int.parse().ok()?;
    let mut nanos = 0u64;
    for (i, b) in frac.bytes().take(9).enumerate() {
        nanos += (b - b'0') as u64 * 10u64.pow(8 - i as u32);
    }
    secs.checked_mul(1_000_000_000)?.checked_add(nanos)
}

/// Largest |‖q‖ - 1| accepted in poses.txt: TUM files carry 6-7 digits.
pub const QUATERNION_NORM_TOLERANCE: f64 = 1e-3;

/// Largest |‖q‖ - 1| of a quaternion taken as written rather than normalised.
const EXACT_UNIT_TOLERANCE: f64 = 1e-12;

/// One TUM line "stamp tx ty tz qx qy qz qw" to a pose, or why not.
pub fn parse_tum_line(line: &str) -> Result<Pose, (SequenceErrorKind, String)> {
    let fields: Vec<&str> = line.split_whitespace().collect();
    if fields.len() != 8 {
        return Err((
            SequenceErrorKind::BadPoseLine,
            format!("expected 8 fields \"stamp tx ty tz qx qy qz qw\", found {}", fields.len()),
        ));
    }
    let stamp_ns = parse_stamp(fields[0]).ok_or_else(|| {
        (SequenceErrorKind::BadPoseLine, format!("stamp {:?} is not non-negative decimal seconds", fields[0]))
    })?;
    let mut v = [0.0f64; 7];
    for (i, f) in fields[1..].iter().enumerate() {
        v[i] = f.parse::<f64>().ok().filter(|x| x.is_finite()).ok_or_else(|| {
            (SequenceErrorKind::BadPoseLine, format!("field {} ({:?}) is not a finite number", i + 2, f))
        })?;
    }
    let distance = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    if distance > crate::types::MAX_COORDINATE_M {
        return Err((
            SequenceErrorKind::BadPoseLine,
            format!(
                "position is {distance:.3e} m from the origin, beyond the {} m polymap maps",
                crate::types::MAX_COORDINATE_M
            ),
        ));
    }
    let q = Quaternion::new(v[6], v[3], v[4], v[5]);
    let norm = q.norm();
    if (norm - 1.0).abs() > QUATERNION_NORM_TOLERANCE {
        return Err((
            SequenceErrorKind::NonUnitQuaternion,
            format!("quaternion (qx qy qz qw) has norm {norm:.6}, expected 1"),
        ));
    }
    // A quaternion unit to double precision (as `polymap record` writes them) is kept as
    // written, so a recording replays bit for bit; others are normalised.
    let rotation = match (norm - 1.0).abs() <= EXACT_UNIT_TOLERANCE {
        true => UnitQuaternion::new_unchecked(q),
        false => UnitQuaternion::from_quaternion(q),
    };
    let transform = Isometry3::from_parts(Translation3::new(v[0], v[1], v[2]), rotation);
    Ok(Pose { stamp_ns, transform })
}

/// A pose as a TUM line: the stamp exact (nine decimals), the numbers with nine decimals
/// (`exact`: with as many as make them read back bit for bit).
pub fn format_tum_line(pose: &Pose, exact: bool) -> String {
    let t = pose.transform.translation.vector;
    let q = pose.transform.rotation.coords; // x, y, z, w
    let numbers = [t.x, t.y, t.z, q.x, q.y, q.z, q.w].map(|v| match exact {
        true => format!("{v:?}"),
        false => format!("{v:.9}"),
    });
    format!("{} {}", ns_to_seconds_string(pose.stamp_ns), numbers.join(" "))
}

fn read_poses(path: &Path, frames: usize) -> Result<Vec<Pose>, SequenceError> {
    let text = crate::files::read_text_capped(path, MAX_POSES_BYTES).map_err(|e| io_err(path, e))?;
    let at =
        |line: usize, kind, reason: String| SequenceError { path: path.to_owned(), line: Some(line), kind, reason };
    let mut poses: Vec<Pose> = Vec::with_capacity(frames);
    let mut last_line = 0;
    for (i, line) in text.lines().enumerate() {
        let n = i + 1;
        last_line = n;
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        if poses.len() == frames {
            return Err(at(n, SequenceErrorKind::PoseCount, format!("more poses than the {frames} depth frames")));
        }
        let pose = parse_tum_line(line).map_err(|(kind, reason)| at(n, kind, reason))?;
        if let Some(prev) = poses.last().filter(|p| p.stamp_ns >= pose.stamp_ns) {
            return Err(at(
                n,
                SequenceErrorKind::StampOrder,
                format!(
                    "stamp {} is not after the previous {}",
                    ns_to_seconds_string(pose.stamp_ns),
                    ns_to_seconds_string(prev.stamp_ns)
                ),
            ));
        }
        poses.push(pose);
    }
    if poses.len() < frames {
        return Err(at(
            last_line + 1,
            SequenceErrorKind::PoseCount,
            format!("file ends after {} poses but depth/ has {frames} frames (one pose per frame)", poses.len()),
        ));
    }
    Ok(poses)
}

fn read_truth(path: &Path) -> Result<Truth, SequenceError> {
    let text = crate::files::read_text_capped(path, MAX_TRUTH_BYTES).map_err(|e| io_err(path, e))?;
    let truth: Truth =
        serde_json::from_str(&text).map_err(|e| err(path, SequenceErrorKind::BadTruth, e.to_string()))?;
    for (i, p) in truth.polygons.iter().enumerate() {
        if p.boundary.len() < 3 || p.boundary.iter().flatten().any(|c| !c.is_finite()) {
            return Err(err(
                path,
                SequenceErrorKind::BadTruth,
                format!("polygon {} needs at least 3 finite vertices", i + 1),
            ));
        }
    }
    Ok(truth)
}

fn open_png(path: &Path) -> Result<png::Reader<BufReader<File>>, SequenceError> {
    let file = File::open(path).map_err(|e| {
        let kind = if e.kind() == std::io::ErrorKind::NotFound {
            SequenceErrorKind::MissingFrame
        } else {
            SequenceErrorKind::Io
        };
        err(path, kind, e.to_string())
    })?;
    png::Decoder::new(BufReader::new(file)).read_info().map_err(|e| err(path, SequenceErrorKind::BadPng, e.to_string()))
}

fn check_header(path: &Path, info: &png::Info, intr: &Intrinsics) -> Result<(), SequenceError> {
    if info.bit_depth != png::BitDepth::Sixteen || info.color_type != png::ColorType::Grayscale {
        return Err(err(
            path,
            SequenceErrorKind::BitDepth,
            format!("{:?}-bit {:?} PNG, expected 16-bit grayscale", info.bit_depth as u8, info.color_type),
        ));
    }
    if (info.width, info.height) != (intr.width, intr.height) {
        return Err(err(
            path,
            SequenceErrorKind::SizeMismatch,
            format!("{}x{} but camera.toml says {}x{}", info.width, info.height, intr.width, intr.height),
        ));
    }
    Ok(())
}

fn check_png_header(path: &Path, intr: &Intrinsics) -> Result<(), SequenceError> {
    let reader = open_png(path)?;
    check_header(path, reader.info(), intr)
}

/// A 16-bit grayscale PNG of the sequence's size, as row-major values.
pub fn read_png16(path: &Path, intr: &Intrinsics) -> Result<Vec<u16>, SequenceError> {
    let mut reader = open_png(path)?;
    check_header(path, reader.info(), intr)?;
    let size = reader.output_buffer_size().ok_or_else(|| err(path, SequenceErrorKind::BadPng, "image too large"))?;
    let mut buf = vec![0u8; size];
    reader.next_frame(&mut buf).map_err(|e| err(path, SequenceErrorKind::BadPng, e.to_string()))?;
    Ok(buf.chunks_exact(2).map(|b| u16::from_be_bytes([b[0], b[1]])).collect())
}

/// Writes `values` as a 16-bit grayscale PNG.
pub fn write_png16(path: &Path, width: u32, height: u32, values: &[u16]) -> std::io::Result<()> {
    assert_eq!(values.len(), width as usize * height as usize, "image buffer does not match its size");
    let mut encoder = png::Encoder::new(BufWriter::new(File::create(path)?), width, height);
    encoder.set_color(png::ColorType::Grayscale);
    encoder.set_depth(png::BitDepth::Sixteen);
    encoder.set_compression(png::Compression::High);
    let mut writer = encoder.write_header().map_err(std::io::Error::other)?;
    let bytes: Vec<u8> = values.iter().flat_map(|v| v.to_be_bytes()).collect();
    writer.write_image_data(&bytes).map_err(std::io::Error::other)?;
    writer.finish().map_err(std::io::Error::other)
}

/// Writes a sequence frame by frame; `finish` writes poses.txt (and truth.json).
pub struct SequenceWriter {
    dir: PathBuf,
    intrinsics: Intrinsics,
    poses: Vec<Pose>,
    with_labels: bool,
    /// Poses with every digit (`polymap record`), not nine decimals.
    exact_poses: bool,
}

impl SequenceWriter {
    pub fn create(dir: impl AsRef<Path>, intrinsics: Intrinsics, with_labels: bool) -> std::io::Result<SequenceWriter> {
        let dir = dir.as_ref().to_owned();
        if let Some(p) = intrinsics.problem() {
            return Err(std::io::Error::new(std::io::ErrorKind::InvalidInput, p));
        }
        fs::create_dir_all(dir.join("depth"))?;
        if with_labels {
            fs::create_dir_all(dir.join("labels"))?;
        }
        fs::write(dir.join("camera.toml"), toml::to_string(&intrinsics).map_err(std::io::Error::other)?)?;
        Ok(SequenceWriter { dir, intrinsics, poses: Vec::new(), with_labels, exact_poses: false })
    }

    /// Writes poses.txt's numbers so they read back bit for bit.
    pub fn with_exact_poses(self) -> SequenceWriter {
        SequenceWriter { exact_poses: true, ..self }
    }

    pub fn intrinsics(&self) -> &Intrinsics {
        &self.intrinsics
    }

    /// Appends a frame: its depth, T_world_camera and (if the writer has them) labels.
    /// Returns the depth PNG's size in bytes.
    pub fn push(&mut self, depth: &[u16], pose: Pose, labels: Option<&[u16]>) -> std::io::Result<u64> {
        let k = self.poses.len();
        let (w, h) = (self.intrinsics.width, self.intrinsics.height);
        let depth_path = self.dir.join("depth").join(frame_name(k));
        write_png16(&depth_path, w, h, depth)?;
        match (self.with_labels, labels) {
            (true, Some(l)) => write_png16(&self.dir.join("labels").join(frame_name(k)), w, h, l)?,
            (false, None) => {}
            _ => {
                return Err(std::io::Error::new(
                    std::io::ErrorKind::InvalidInput,
                    "labels must be given for every frame or none",
                ));
            }
        }
        self.poses.push(pose);
        Ok(fs::metadata(&depth_path)?.len())
    }

    pub fn finish(self, truth: Option<&Truth>) -> std::io::Result<()> {
        let mut out = BufWriter::new(File::create(self.dir.join("poses.txt"))?);
        writeln!(out, "# stamp tx ty tz qx qy qz qw  (T_world_camera, optical frame; stamp in seconds)")?;
        for p in &self.poses {
            writeln!(out, "{}", format_tum_line(p, self.exact_poses))?;
        }
        out.flush()?;
        if let Some(t) = truth {
            fs::write(self.dir.join("truth.json"), serde_json::to_string_pretty(t).map_err(std::io::Error::other)?)?;
        }
        Ok(())
    }
}
