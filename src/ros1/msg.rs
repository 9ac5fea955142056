//! The messages whose ROS 1 fields differ from ROS 2's: visualization_msgs/Marker (ROS 2
//! added textures and embedded meshes) and grid_map_msgs/GridMap (ROS 1 keeps the header in
//! its GridMapInfo), so the PlanarTerrain that holds one. polymap builds the ROS 2 message
//! once and sends it on ROS 1 in these layouts.

use serde::{Deserialize, Serialize};

use super::types::Ros1Message;
use crate::ros2::cdr::{self, CdrError};
use crate::ros2::msg::{
    self as ros2, ColorRgba, Duration, Float32MultiArray, Header, PlanarRegion, Point, Pose, Vector3,
};

/// visualization_msgs/Marker as Noetic defines it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
struct Marker {
    header: Header,
    ns: String,
    id: i32,
    r#type: i32,
    action: i32,
    pose: Pose,
    scale: Vector3,
    color: ColorRgba,
    lifetime: Duration,
    frame_locked: bool,
    points: Vec<Point>,
    colors: Vec<ColorRgba>,
    text: String,
    mesh_resource: String,
    mesh_use_embedded_materials: bool,
}

#[derive(Serialize, Deserialize)]
struct MarkerArray {
    markers: Vec<Marker>,
}

impl From<&ros2::Marker> for Marker {
    fn from(m: &ros2::Marker) -> Marker {
        Marker {
            header: m.header.clone(),
            ns: m.ns.clone(),
            id: m.id,
            r#type: m.r#type,
            action: m.action,
            pose: m.pose,
            scale: m.scale,
            color: m.color,
            lifetime: m.lifetime,
            frame_locked: m.frame_locked,
            points: m.points.clone(),
            colors: m.colors.clone(),
            text: m.text.clone(),
            mesh_resource: m.mesh_resource.clone(),
            mesh_use_embedded_materials: m.mesh_use_embedded_materials,
        }
    }
}

impl From<Marker> for ros2::Marker {
    fn from(m: Marker) -> ros2::Marker {
        ros2::Marker {
            header: m.header,
            ns: m.ns,
            id: m.id,
            r#type: m.r#type,
            action: m.action,
            pose: m.pose,
            scale: m.scale,
            color: m.color,
            lifetime: m.lifetime,
            frame_locked: m.frame_locked,
            points: m.points,
            colors: m.colors,
            texture_resource: String::new(),
            texture: Default::default(),
            uv_coordinates: Vec::new(),
            text: m.text,
            mesh_resource: m.mesh_resource,
            mesh_file: Default::default(),
            mesh_use_embedded_materials: m.mesh_use_embedded_materials,
        }
    }
}

impl Ros1Message for ros2::MarkerArray {
    const TYPE: &'static str = "visualization_msgs/MarkerArray";
    fn to_ros1(&self) -> Vec<u8> {
        cdr::to_ros1_vec(&MarkerArray { markers: self.markers.iter().map(Marker::from).collect() })
    }
    fn from_ros1(bytes: &[u8]) -> Result<Self, CdrError> {
        let array: MarkerArray = cdr::from_ros1_slice(bytes)?;
        Ok(ros2::MarkerArray { markers: array.markers.into_iter().map(ros2::Marker::from).collect() })
    }
}

/// grid_map_msgs/GridMapInfo as Noetic defines it.
#[derive(Serialize, Deserialize)]
struct GridMapInfo {
    header: Header,
    resolution: f64,
    length_x: f64,
    length_y: f64,
    pose: Pose,
}

#[derive(Serialize, Deserialize)]
struct GridMap {
    info: GridMapInfo,
    layers: Vec<String>,
    basic_layers: Vec<String>,
    data: Vec<Float32MultiArray>,
    outer_start_index: u16,
    inner_start_index: u16,
}

/// convex_plane_decomposition_msgs/PlanarTerrain (ROS 1 calls its regions `planarRegions`;
/// the bytes do not carry names).
#[derive(Serialize, Deserialize)]
struct PlanarTerrain {
    planar_regions: Vec<PlanarRegion>,
    gridmap: GridMap,
}

impl Ros1Message for ros2::PlanarTerrain {
    const TYPE: &'static str = "convex_plane_decomposition_msgs/PlanarTerrain";
    fn to_ros1(&self) -> Vec<u8> {
        let g = &self.gridmap;
        let gridmap = GridMap {
            info: GridMapInfo {
                header: g.header.clone(),
                resolution: g.info.resolution,
                length_x: g.info.length_x,
                length_y: g.info.length_y,
                pose: g.info.pose,
            },
            layers: g.layers.clone(),
            basic_layers: g.basic_layers.clone(),
            data: g.data.clone(),
            outer_start_index: g.outer_start_index,
            inner_start_index: g.inner_start_index,
        };
        cdr::to_ros1_vec(&PlanarTerrain { planar_regions: self.planar_regions.clone(), gridmap })
    }
    fn from_ros1(bytes: &[u8]) -> Result<Self, CdrError> {
        let t: PlanarTerrain = cdr::from_ros1_slice(bytes)?;
        let g = t.gridmap;
        Ok(ros2::PlanarTerrain {
            planar_regions: t.planar_regions,
            gridmap: ros2::GridMap {
                header: g.info.header,
                info: ros2::GridMapInfo {
                    resolution: g.info.resolution,
                    length_x: g.info.length_x,
                    length_y: g.info.length_y,
                    pose: g.info.pose,
                },
                layers: g.layers,
                basic_layers: g.basic_layers,
                data: g.data,
                outer_start_index: g.outer_start_index,
                inner_start_index: g.inner_start_index,
            },
        })
    }
}
