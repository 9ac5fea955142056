//! The terrain messages legged planners already consume, laid out as their packages' ROS 2
//! .msg files define them (written from the definitions; none of their code):
//! convex_plane_decomposition_msgs (leggedrobotics' plane_segmentation, ROS 2: the field is
//! `planar_regions`), grid_map_msgs (ANYbotics' grid_map, ROS 2: the header on GridMap), and
//! the std_msgs multi-array a grid map layer travels in.

use super::standard::{Header, Pose};
use crate::ros_message;

ros_message! {
    /// std_msgs/MultiArrayDimension
    #[derive(Default)]
    pub struct MultiArrayDimension = "std_msgs/msg/MultiArrayDimension" {
        pub label: String,
        pub size: u32,
        pub stride: u32,
    }

    /// std_msgs/MultiArrayLayout
    #[derive(Default)]
    pub struct MultiArrayLayout = "std_msgs/msg/MultiArrayLayout" {
        pub dim: Vec<MultiArrayDimension>,
        pub data_offset: u32,
    }

    /// std_msgs/Float32MultiArray
    #[derive(Default)]
    pub struct Float32MultiArray = "std_msgs/msg/Float32MultiArray" {
        pub layout: MultiArrayLayout,
        pub data: Vec<f32>,
    }

    /// grid_map_msgs/GridMapInfo: the grid's geometry.
    #[derive(Default)]
    pub struct GridMapInfo = "grid_map_msgs/msg/GridMapInfo" {
        /// m per cell.
        pub resolution: f64,
        /// Extent along x and y, m.
        pub length_x: f64,
        pub length_y: f64,
        /// The grid's centre in the header's frame (the grid is axis-aligned with it).
        pub pose: Pose,
    }

    /// grid_map_msgs/GridMap (ROS 2).
    #[derive(Default)]
    pub struct GridMap = "grid_map_msgs/msg/GridMap" {
        pub header: Header,
        pub info: GridMapInfo,
        pub layers: Vec<String>,
        pub basic_layers: Vec<String>,
        /// One per layer, column-major (grid_map's Eigen matrices).
        pub data: Vec<Float32MultiArray>,
        pub outer_start_index: u16,
        pub inner_start_index: u16,
    }

    /// convex_plane_decomposition_msgs/Point2d
    #[derive(Copy, Default)]
    pub struct Point2d = "convex_plane_decomposition_msgs/msg/Point2d" {
        pub x: f32,
        pub y: f32,
    }

    /// convex_plane_decomposition_msgs/Polygon2d: first and last points connected, not repeated.
    #[derive(Default)]
    pub struct Polygon2d = "convex_plane_decomposition_msgs/msg/Polygon2d" {
        pub points: Vec<Point2d>,
    }

    /// convex_plane_decomposition_msgs/PolygonWithHoles2d
    #[derive(Default)]
    pub struct PolygonWithHoles2d = "convex_plane_decomposition_msgs/msg/PolygonWithHoles2d" {
        pub outer_boundary: Polygon2d,
        pub holes: Vec<Polygon2d>,
    }

    /// convex_plane_decomposition_msgs/BoundingBox2d (of the outer boundary, in the plane's frame).
    #[derive(Copy, Default)]
    pub struct BoundingBox2d = "convex_plane_decomposition_msgs/msg/BoundingBox2d" {
        pub min_x: f32,
        pub min_y: f32,
        pub max_x: f32,
        pub max_y: f32,
    }

    /// convex_plane_decomposition_msgs/PlanarRegion: 2-D shapes in the plane's frame, whose
    /// pose (plane to terrain frame, z along the upward normal) is `plane_parameters`.
    #[derive(Default)]
    pub struct PlanarRegion = "convex_plane_decomposition_msgs/msg/PlanarRegion" {
        pub plane_parameters: Pose,
        pub bbox2d: BoundingBox2d,
        pub boundary: PolygonWithHoles2d,
        pub insets: Vec<PolygonWithHoles2d>,
    }

    /// convex_plane_decomposition_msgs/PlanarTerrain (ROS 2): regions in the grid map's frame.
    #[derive(Default)]
    pub struct PlanarTerrain = "convex_plane_decomposition_msgs/msg/PlanarTerrain" {
        pub planar_regions: Vec<PlanarRegion>,
        pub gridmap: GridMap,
    }
}
