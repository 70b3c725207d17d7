//! `visualization_msgs`: markers for rviz2.

use serde::{Deserialize, Serialize};

use super::builtin::Duration;
use super::geometry::{Point, Pose, Vector3};
use super::ros_message;
use super::std::{ColorRgba, Header};

/// `sensor_msgs/CompressedImage`, a marker's embedded texture.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct CompressedImage {
    pub header: Header,
    pub format: String,
    pub data: Vec<u8>,
}

/// `visualization_msgs/UVCoordinate`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct UvCoordinate {
    pub u: f32,
    pub v: f32,
}

/// `visualization_msgs/MeshFile`.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct MeshFile {
    pub filename: String,
    pub data: Vec<u8>,
}

/// `visualization_msgs/Marker`, with the texture and embedded mesh fields
/// Humble added.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Marker {
    pub header: Header,
    pub ns: String,
    pub id: i32,
    /// [`SPHERE`], [`LINE_STRIP`], [`TEXT_VIEW_FACING`], ...
    pub r#type: i32,
    /// [`ADD`], [`DELETE`], [`DELETEALL`].
    pub action: i32,
    pub pose: Pose,
    pub scale: Vector3,
    pub color: ColorRgba,
    /// How long rviz2 shows it without an update; zero is forever.
    pub lifetime: Duration,
    pub frame_locked: bool,
    pub points: Vec<Point>,
    pub colors: Vec<ColorRgba>,
    pub texture_resource: String,
    pub texture: CompressedImage,
    pub uv_coordinates: Vec<UvCoordinate>,
    pub text: String,
    pub mesh_resource: String,
    pub mesh_file: MeshFile,
    pub mesh_use_embedded_materials: bool,
}

/// Marker types.
pub const ARROW: i32 = 0;
pub const SPHERE: i32 = 2;
pub const CYLINDER: i32 = 3;
pub const LINE_STRIP: i32 = 4;
pub const TEXT_VIEW_FACING: i32 = 9;

/// Marker actions.
pub const ADD: i32 = 0;
pub const DELETE: i32 = 2;
pub const DELETEALL: i32 = 3;

/// `visualization_msgs/MarkerArray`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct MarkerArray {
    pub markers: Vec<Marker>,
}

ros_message!(MarkerArray => "visualization_msgs" / "MarkerArray");
