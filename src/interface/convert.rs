//! Conversions between polymap's own types and its ROS messages, both ways, in one place.

use crate::camera::ImuSample;
use crate::extract::Footing;
use crate::map::{Label, MapFrame, MapPolygon, MapSnapshot, Region};
use crate::pose::RawPose;
use crate::ros2::msg::{
    self, ColorRgba, Duration, FramePolygons, Header, Image, Imu, Map, MapUpdate, Marker, MarkerArray, Odometry, Point,
    Pose, PoseStamped, PoseWithCovariance, Quaternion, Ring, TfMessage, Time, Transform, TransformStamped,
    TwistWithCovariance, Vector3,
};
use crate::types::{DepthFrame, Intrinsics, StampNs};

fn ring(r: &[[f64; 3]]) -> Ring {
    Ring { points: r.iter().map(|&p| p.into()).collect() }
}

fn points(r: &[Point]) -> Vec<[f64; 3]> {
    r.iter().map(|p| [p.x, p.y, p.z]).collect()
}

pub fn header(stamp_ns: StampNs, frame_id: &str) -> Header {
    Header { stamp: Time::from_ns(stamp_ns), frame_id: frame_id.into() }
}

/// A label as polymap_msgs/Polygon's `LABEL_*` constant.
pub fn label_code(label: Label) -> u8 {
    match label {
        Label::Floor => msg::Polygon::LABEL_FLOOR,
        Label::Tread => msg::Polygon::LABEL_TREAD,
        Label::Landing => msg::Polygon::LABEL_LANDING,
        Label::Riser => msg::Polygon::LABEL_RISER,
        Label::Wall => msg::Polygon::LABEL_WALL,
        Label::Slope => msg::Polygon::LABEL_SLOPE,
    }
}

/// The label a `LABEL_*` constant names (None for LABEL_NONE or an unknown code).
pub fn label_of(code: u8) -> Option<Label> {
    [Label::Floor, Label::Tread, Label::Landing, Label::Riser, Label::Wall, Label::Slope]
        .into_iter()
        .find(|&l| label_code(l) == code)
}

/// A map polygon as planners get it.
pub fn map_polygon(p: &MapPolygon) -> msg::Polygon {
    msg::Polygon {
        id: p.id,
        label: label_code(p.label),
        step: p.step.map_or(-1, |s| s as i32),
        normal: p.normal,
        offset: p.offset,
        area: p.area,
        centroid: p.centroid.into(),
        boundary: p.boundary.iter().map(|&v| v.into()).collect(),
        holes: p.holes.iter().map(|h| ring(h)).collect(),
        convex_pieces: p.convex_pieces.iter().map(|h| ring(h)).collect(),
        insets: p.insets.iter().map(region).collect(),
        observations: p.observations,
        plane_covariance: p.plane_covariance,
        steppable: p.footing.is_steppable(),
        footing: footing_code(p.footing),
        pixels: p.pixels,
    }
}

/// A footing's `FOOTING_*` code in polymap_msgs/Polygon.
pub fn footing_code(f: Footing) -> u8 {
    match f {
        Footing::Steppable => msg::Polygon::FOOTING_STEPPABLE,
        Footing::TiltUnknown => msg::Polygon::FOOTING_TILT_UNKNOWN,
        Footing::FewPixels => msg::Polygon::FOOTING_FEW_PIXELS,
    }
}

/// The footing of a `FOOTING_*` code; None for one polymap never sends.
pub fn footing_of(code: u8) -> Option<Footing> {
    [Footing::Steppable, Footing::TiltUnknown, Footing::FewPixels].into_iter().find(|&f| footing_code(f) == code)
}

fn region(r: &Region) -> msg::Region {
    msg::Region {
        boundary: r.boundary.iter().map(|&v| v.into()).collect(),
        holes: r.holes.iter().map(|h| ring(h)).collect(),
    }
}

/// A map polygon back from its message; None for a label or footing code polymap never
/// sends, or a `steppable` that contradicts its footing.
pub fn map_polygon_of(p: &msg::Polygon) -> Option<MapPolygon> {
    Some(MapPolygon {
        id: p.id,
        label: label_of(p.label)?,
        normal: p.normal,
        offset: p.offset,
        area: p.area,
        centroid: [p.centroid.x, p.centroid.y, p.centroid.z],
        boundary: points(&p.boundary),
        holes: p.holes.iter().map(|r| points(&r.points)).collect(),
        convex_pieces: p.convex_pieces.iter().map(|r| points(&r.points)).collect(),
        insets: p
            .insets
            .iter()
            .map(|r| Region {
                boundary: points(&r.boundary),
                holes: r.holes.iter().map(|h| points(&h.points)).collect(),
            })
            .collect(),
        observations: p.observations,
        step: (p.step >= 0).then_some(p.step as u32),
        plane_covariance: p.plane_covariance,
        footing: footing_of(p.footing).filter(|f| f.is_steppable() == p.steppable)?,
        pixels: p.pixels,
    })
}

/// One frame's extracted polygon (not labelled, seen once).
pub fn frame_polygon(p: &crate::extract::Polygon) -> msg::Polygon {
    msg::Polygon {
        id: p.id as u64,
        label: msg::Polygon::LABEL_NONE,
        step: -1,
        normal: p.normal,
        offset: p.offset,
        area: p.area,
        centroid: p.centroid().into(),
        boundary: p.boundary.iter().map(|&v| v.into()).collect(),
        holes: p.holes.iter().map(|h| ring(h)).collect(),
        observations: 1,
        plane_covariance: if p.uncertainty.is_known() { p.uncertainty.coefficient_covariance() } else { [0.0; 16] },
        steppable: p.footing.is_steppable(),
        footing: footing_code(p.footing),
        pixels: u32::try_from(p.pixel_count).unwrap_or(u32::MAX),
        ..msg::Polygon::default()
    }
}

pub fn frame_polygons(stamp_ns: StampNs, frame_id: &str, polygons: &[crate::extract::Polygon]) -> FramePolygons {
    FramePolygons { header: header(stamp_ns, frame_id), polygons: polygons.iter().map(frame_polygon).collect() }
}

/// What one frame changed, as polygons whole.
pub struct MapDelta<'a> {
    pub stamp_ns: StampNs,
    pub epoch: u64,
    pub from_version: u64,
    pub version: u64,
    pub added: &'a [MapPolygon],
    pub changed: &'a [MapPolygon],
    pub removed: &'a [u64],
    pub drift_z: f64,
    pub drift_var: f64,
}

pub fn map_update(d: &MapDelta, frame_id: &str) -> MapUpdate {
    MapUpdate {
        header: header(d.stamp_ns, frame_id),
        epoch: d.epoch,
        from_version: d.from_version,
        version: d.version,
        added: d.added.iter().map(map_polygon).collect(),
        changed: d.changed.iter().map(map_polygon).collect(),
        removed: d.removed.to_vec(),
        drift_z: d.drift_z,
        drift_var: d.drift_var,
    }
}

/// The whole map of mapper run `epoch`, in `frame_id`.
pub fn map(s: &MapSnapshot, stamp_ns: StampNs, epoch: u64, frame_id: &str) -> Map {
    Map {
        header: header(stamp_ns, frame_id),
        epoch,
        version: s.version,
        drift_z: s.drift_z,
        drift_var: s.drift_var,
        polygons: s.polygons.iter().map(map_polygon).collect(),
    }
}

/// The map a client received; polygons with a label code it does not know are left out.
pub fn snapshot_of(m: &Map) -> MapSnapshot {
    MapSnapshot {
        version: m.version,
        frame: MapFrame::World,
        drift_z: m.drift_z,
        drift_var: m.drift_var,
        drift_xy: [0.0; 2],
        drift_yaw: 0.0,
        drift_covariance: None,
        stair: None,
        polygons: m.polygons.iter().filter_map(map_polygon_of).collect(),
    }
}

pub fn foothold(f: &crate::map::foothold::Foothold, stamp_ns: StampNs, frame_id: &str) -> msg::Foothold {
    let header = header(stamp_ns, frame_id);
    match f {
        None => msg::Foothold { header, ..msg::Foothold::default() },
        Some(f) => msg::Foothold {
            header,
            found: true,
            contains: f.distance == 0.0,
            polygon_id: f.polygon.id,
            label: label_code(f.polygon.label),
            normal: f.polygon.normal,
            offset: f.polygon.offset,
            piece: f.piece.iter().map(|&v| v.into()).collect(),
            distance: f.distance,
        },
    }
}

// RViz markers.

pub const MARKER_LINE_STRIP: i32 = 4;
pub const MARKER_ADD: i32 = 0;
pub const MARKER_DELETE: i32 = 2;
pub const MARKER_DELETEALL: i32 = 3;
/// The namespace polymap's markers live in.
pub const MARKER_NS: &str = "polymap";

pub(super) fn marker(header: &Header, id: u64, action: i32) -> Marker {
    Marker {
        header: header.clone(),
        ns: MARKER_NS.into(),
        // RViz ids are int32; map ids count up from 1 and stay far below 2^31.
        id: (id & 0x7fff_ffff) as i32,
        r#type: MARKER_LINE_STRIP,
        action,
        pose: Pose::default(),
        scale: Vector3 { x: 0.01, y: 0.0, z: 0.0 },
        color: ColorRgba::default(),
        lifetime: Duration::default(),
        frame_locked: false,
        points: Vec::new(),
        colors: Vec::new(),
        texture_resource: String::new(),
        texture: msg::CompressedImage::default(),
        uv_coordinates: Vec::new(),
        text: String::new(),
        mesh_resource: String::new(),
        mesh_file: msg::MeshFile::default(),
        mesh_use_embedded_materials: false,
    }
}

/// Markers for changed polygons (each outline a closed line strip in its label's colour, as
/// the top-down picture draws it) and a delete for each removed one.
pub fn markers(header: &Header, polygons: &[&msg::Polygon], removed: &[u64]) -> MarkerArray {
    let mut markers: Vec<Marker> = polygons
        .iter()
        .map(|p| {
            let mut m = marker(header, p.id, MARKER_ADD);
            // Not steppable: grey and faint, whatever its label.
            let [r, g, b] = (label_of(p.label).filter(|_| p.steppable))
                .map(|l| crate::map::render::label_colour(l, (p.step >= 0).then_some(p.step as u32)).0)
                .unwrap_or([200, 200, 200]);
            let a = if p.steppable { 1.0 } else { 0.4 };
            m.color = ColorRgba { r: r as f32 / 255.0, g: g as f32 / 255.0, b: b as f32 / 255.0, a };
            m.points = p.boundary.clone();
            m.points.extend(p.boundary.first().copied());
            m
        })
        .collect();
    markers.extend(removed.iter().map(|&id| marker(header, id, MARKER_DELETE)));
    MarkerArray { markers }
}

/// The whole map's markers: a DELETEALL (so a viewer keeps nothing of an older map), then
/// every polygon's outline.
pub fn whole_map_markers(m: &Map) -> MarkerArray {
    let mut all = markers(&m.header, &m.polygons.iter().collect::<Vec<_>>(), &[]);
    all.markers.insert(0, marker(&m.header, 0, MARKER_DELETEALL));
    all
}

/// The drift as a transform: `odometry_frame` (VINS's) seen from `map_frame`, which is
/// VINS's frame with the drift taken out: a point p in VINS's frame is `map_from_odometry` p
/// in the map frame (a turn about z and a shift).
pub fn drift_transform(
    stamp_ns: StampNs,
    map_frame: &str,
    odometry_frame: &str,
    map_from_odometry: &nalgebra::Isometry3<f64>,
) -> TfMessage {
    let (t, q) = (map_from_odometry.translation.vector, map_from_odometry.rotation);
    TfMessage {
        transforms: vec![TransformStamped {
            header: header(stamp_ns, map_frame),
            child_frame_id: odometry_frame.into(),
            transform: Transform {
                translation: Vector3 { x: t.x, y: t.y, z: t.z },
                rotation: Quaternion { x: q.i, y: q.j, z: q.k, w: q.w },
            },
        }],
    }
}

// Depth from a ROS image topic, as realsense-ros publishes the L515's.

/// The unit polymap keeps a 32FC1 image's metres in: the L515's, 0.25 mm.
const FLOAT_DEPTH_UNIT_M: f64 = 0.00025;

/// A depth image and its camera_info as a frame: 16UC1 / mono16 in `unit_m` (None: REP 118's
/// millimetres), or 32FC1 in metres (kept in 0.25 mm units; NaN, inf and <= 0 are invalid).
/// Why not, when the image is not a depth image or does not fit its camera_info.
pub fn depth_frame(
    image: &Image,
    info: &msg::CameraInfo,
    unit_m: Option<f64>,
) -> Result<(DepthFrame, Intrinsics), String> {
    let (w, h) = (image.width as usize, image.height as usize);
    if (image.width, image.height) != (info.width, info.height) {
        return Err(format!(
            "the image is {}x{} but its camera_info says {}x{}",
            image.width, image.height, info.width, info.height
        ));
    }
    if w == 0 || h == 0 || w > 4096 || h > 4096 {
        return Err(format!("an image of {w}x{h} pixels"));
    }
    let bytes_per_pixel = match image.encoding.as_str() {
        "16UC1" | "mono16" => 2,
        "32FC1" => 4,
        other => return Err(format!("encoding {other:?} is not a depth image (16UC1, mono16 or 32FC1)")),
    };
    let step = image.step as usize;
    if step < w * bytes_per_pixel || image.data.len() < step * h {
        return Err(format!(
            "{} bytes with a step of {step} do not hold {w}x{h} pixels of {bytes_per_pixel} bytes",
            image.data.len()
        ));
    }
    let k = &info.k;
    if !(k[0] > 0.0 && k[4] > 0.0 && k.iter().all(|v| v.is_finite())) {
        return Err(format!("camera_info's K {k:?} has no focal lengths"));
    }
    let big = image.is_bigendian != 0;
    let mut pixels = Vec::with_capacity(w * h);
    for row in image.data.chunks(step).take(h) {
        for px in row[..w * bytes_per_pixel].chunks_exact(bytes_per_pixel) {
            pixels.push(match (bytes_per_pixel, big) {
                (2, false) => u16::from_le_bytes([px[0], px[1]]),
                (2, true) => u16::from_be_bytes([px[0], px[1]]),
                (_, false) => metres_to_units(f32::from_le_bytes([px[0], px[1], px[2], px[3]])),
                (_, true) => metres_to_units(f32::from_be_bytes([px[0], px[1], px[2], px[3]])),
            });
        }
    }
    let depth_scale = match bytes_per_pixel {
        2 => unit_m.unwrap_or(0.001),
        _ => FLOAT_DEPTH_UNIT_M,
    };
    let intrinsics =
        Intrinsics { width: image.width, height: image.height, fx: k[0], fy: k[4], cx: k[2], cy: k[5], depth_scale };
    let stamp_ns = image.header.stamp.to_ns().ok_or_else(|| format!("stamp {:?}", image.header.stamp))?;
    Ok((DepthFrame { stamp_ns, width: image.width, height: image.height, depth_scale, pixels }, intrinsics))
}

fn metres_to_units(m: f32) -> u16 {
    match m.is_finite() && m > 0.0 {
        true => (m as f64 / FLOAT_DEPTH_UNIT_M).round().min(u16::MAX as f64) as u16,
        false => 0,
    }
}

// The D435i, as realsense-ros publishes it.

/// The IR image of infra`index`.
pub fn ir_image(stamp_ns: StampNs, index: u8, intr: &Intrinsics, pixels: Vec<u8>) -> Image {
    Image {
        header: header(stamp_ns, &format!("camera_infra{index}_optical_frame")),
        height: intr.height,
        width: intr.width,
        encoding: "mono8".into(),
        is_bigendian: 0,
        step: intr.width,
        data: pixels,
    }
}

/// The CameraInfo beside it: rectified images, so no distortion and R = I; infra2's
/// projection carries the baseline (P[3] = -fx * baseline), as realsense-ros writes it.
pub fn ir_camera_info(stamp_ns: StampNs, index: u8, intr: &Intrinsics, baseline_m: f64) -> msg::CameraInfo {
    let (fx, fy, cx, cy) = (intr.fx, intr.fy, intr.cx, intr.cy);
    let tx = if index == 2 { -fx * baseline_m } else { 0.0 };
    msg::CameraInfo {
        header: header(stamp_ns, &format!("camera_infra{index}_optical_frame")),
        height: intr.height,
        width: intr.width,
        distortion_model: "plumb_bob".into(),
        d: vec![0.0; 5],
        k: [fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0],
        r: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        p: [fx, 0.0, cx, tx, 0.0, fy, cy, 0.0, 0.0, 0.0, 1.0, 0.0],
        binning_x: 0,
        binning_y: 0,
        roi: msg::RegionOfInterest::default(),
    }
}

/// One united IMU sample: no orientation (covariance[0] = -1, the ROS convention), and the
/// configured variances on the rates' diagonals.
pub fn imu(sample: &ImuSample, angular_velocity_cov: f64, linear_accel_cov: f64) -> Imu {
    let diagonal = |c: f64| [c, 0.0, 0.0, 0.0, c, 0.0, 0.0, 0.0, c];
    Imu {
        header: header(sample.stamp_ns, "camera_imu_optical_frame"),
        orientation: Quaternion::default(),
        orientation_covariance: [-1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        angular_velocity: sample.gyro.into(),
        angular_velocity_covariance: diagonal(angular_velocity_cov),
        linear_acceleration: sample.accel.into(),
        linear_acceleration_covariance: diagonal(linear_accel_cov),
    }
}

// Odometry: VINS's out, polymap's in.

fn raw_pose(header: &Header, pose: &Pose) -> Result<RawPose, String> {
    let stamp_ns = header.stamp.to_ns().ok_or_else(|| format!("stamp {:?} is not a time", header.stamp))?;
    let (p, q) = (pose.position, pose.orientation);
    Ok(RawPose { stamp_ns, position: [p.x, p.y, p.z], quat_xyzw: [q.x, q.y, q.z, q.w] })
}

/// The pose an Odometry message carries (not yet checked: the pose buffer does that).
pub fn pose_of_odometry(m: &Odometry) -> Result<RawPose, String> {
    raw_pose(&m.header, &m.pose.pose)
}

pub fn pose_of_pose_stamped(m: &PoseStamped) -> Result<RawPose, String> {
    raw_pose(&m.header, &m.pose)
}

/// An Odometry message of a pose, as VINS sends it.
pub fn odometry(pose: &RawPose, frame_id: &str, child_frame_id: &str) -> Odometry {
    let [x, y, z] = pose.position;
    let [qx, qy, qz, qw] = pose.quat_xyzw;
    Odometry {
        header: header(pose.stamp_ns, frame_id),
        child_frame_id: child_frame_id.into(),
        pose: PoseWithCovariance {
            pose: Pose { position: Point { x, y, z }, orientation: Quaternion { x: qx, y: qy, z: qz, w: qw } },
            covariance: [0.0; 36],
        },
        twist: TwistWithCovariance::default(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn footing_round_trips_and_only_steppable_polygons_are_marked_so() {
        let square = |z: f64, footing: Footing| crate::extract::Polygon {
            id: 0,
            normal: [0.0, 0.0, 1.0],
            offset: -z,
            area: 0.09,
            boundary: vec![[0.0, 0.0, z], [0.3, 0.0, z], [0.3, 0.3, z], [0.0, 0.3, z]],
            holes: vec![],
            boundary_kinds: vec![Default::default(); 4],
            hole_kinds: vec![],
            pixel_count: 900,
            inlier_ratio: 1.0,
            rms: 0.001,
            uncertainty: Default::default(),
            footing,
        };
        let polygons =
            [square(0.1, Footing::Steppable), square(0.2, Footing::TiltUnknown), square(0.3, Footing::FewPixels)];
        let frame = frame_polygons(0, "camera", &polygons);
        assert_eq!(
            frame.polygons.iter().map(|p| (p.steppable, p.footing)).collect::<Vec<_>>(),
            [
                (true, msg::Polygon::FOOTING_STEPPABLE),
                (false, msg::Polygon::FOOTING_TILT_UNKNOWN),
                (false, msg::Polygon::FOOTING_FEW_PIXELS)
            ]
        );
        for f in [Footing::Steppable, Footing::TiltUnknown, Footing::FewPixels] {
            assert_eq!(footing_of(footing_code(f)), Some(f));
        }
        assert_eq!(footing_of(7), None);
        // A map polygon whose steppable contradicts its footing, or whose footing is unknown,
        // is refused as it is read.
        let mut p = map_polygon(&crate::map::MapPolygon {
            id: 3,
            label: Label::Tread,
            normal: [0.0, 0.0, 1.0],
            offset: -0.1,
            area: 0.09,
            centroid: [0.15, 0.15, 0.1],
            boundary: polygons[0].boundary.clone(),
            holes: vec![],
            convex_pieces: vec![],
            insets: vec![],
            observations: 2,
            step: Some(1),
            plane_covariance: [0.0; 16],
            footing: Footing::TiltUnknown,
            pixels: 300,
        });
        assert_eq!(map_polygon_of(&p).map(|q| (q.footing, q.pixels)), Some((Footing::TiltUnknown, 300)));
        p.steppable = true;
        assert!(map_polygon_of(&p).is_none(), "steppable with footing tilt_unknown");
        (p.steppable, p.footing) = (false, 9);
        assert!(map_polygon_of(&p).is_none(), "an unknown footing");
    }
}
