//! `visualization_msgs/MarkerArray` and what it is made of: shapes a viewer draws (RViz,
//! Foxglove), here the formation's edges and their errors in a recording.
//!
//! The layout is ROS 2 Jazzy's `Marker`, texture and mesh file included (empty when unused), in
//! declaration order as the `.msg` files give it; `tests/wire_format.rs` checks the bytes and the
//! hashes against `rosbags`.

use crate::cdr::{CdrEncodeError, CdrError, CdrReader, CdrWriter};
use crate::msg::{Header, Pose, Quaternion, RosMessage, Vector3, message_identity};
use crate::schema::{self, MsgDefinition};

/// `builtin_interfaces/msg/Duration`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Duration {
    /// Seconds.
    pub sec: i32,
    /// Nanoseconds within the second.
    pub nanosec: u32,
}

/// `std_msgs/msg/ColorRGBA`, each channel in `[0, 1]`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ColorRgba {
    /// Red.
    pub r: f32,
    /// Green.
    pub g: f32,
    /// Blue.
    pub b: f32,
    /// Opacity.
    pub a: f32,
}

impl ColorRgba {
    fn write(&self, w: &mut CdrWriter) {
        for c in [self.r, self.g, self.b, self.a] {
            w.write_f32(c);
        }
    }

    fn read(r: &mut CdrReader<'_>, field: &'static str) -> Result<ColorRgba, CdrError> {
        Ok(ColorRgba {
            r: r.read_f32(field)?,
            g: r.read_f32(field)?,
            b: r.read_f32(field)?,
            a: r.read_f32(field)?,
        })
    }
}

/// `sensor_msgs/msg/CompressedImage`: a marker's texture (unused here, so usually empty).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct CompressedImage {
    /// Stamp and frame.
    pub header: Header,
    /// `png`, `jpeg`, ...
    pub format: String,
    /// The encoded image.
    pub data: Vec<u8>,
}

/// `visualization_msgs/msg/MeshFile`: a mesh carried in the marker (usually empty).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct MeshFile {
    /// The file's name, for its format.
    pub filename: String,
    /// The file's bytes.
    pub data: Vec<u8>,
}

/// What a [`Marker`] draws (`Marker.type`).
pub mod marker_type {
    /// One line segment per pair of `points`.
    pub const LINE_LIST: i32 = 5;
    /// A sphere.
    pub const SPHERE: i32 = 2;
    /// `text`, facing the viewer.
    pub const TEXT_VIEW_FACING: i32 = 9;
}

/// What a [`Marker`] does (`Marker.action`).
pub mod marker_action {
    /// Add or replace the marker `(ns, id)`.
    pub const ADD: i32 = 0;
    /// Remove the marker `(ns, id)`.
    pub const DELETE: i32 = 2;
    /// Remove every marker of the array's publisher.
    pub const DELETEALL: i32 = 3;
}

/// `visualization_msgs/msg/Marker`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Marker {
    /// Stamp and the frame the pose and points are in.
    pub header: Header,
    /// Namespace: with `id`, names the marker.
    pub ns: String,
    /// Id within the namespace.
    pub id: i32,
    /// What it draws ([`marker_type`]).
    pub kind: i32,
    /// Add, delete, delete all ([`marker_action`]).
    pub action: i32,
    /// Where it is.
    pub pose: Pose,
    /// Its size (for lines, `x` is the width) \[m\].
    pub scale: Vector3,
    /// Its colour, unless `colors` gives one per point.
    pub color: ColorRgba,
    /// How long it lasts (0: until replaced).
    pub lifetime: Duration,
    /// Whether it moves with its frame.
    pub frame_locked: bool,
    /// Points of lines and lists.
    pub points: Vec<Vector3>,
    /// One colour per point, or none.
    pub colors: Vec<ColorRgba>,
    /// Texture URI.
    pub texture_resource: String,
    /// Texture image.
    pub texture: CompressedImage,
    /// Texture coordinates, one per point.
    pub uv_coordinates: Vec<(f32, f32)>,
    /// Text of a text marker.
    pub text: String,
    /// Mesh URI.
    pub mesh_resource: String,
    /// Mesh carried inline.
    pub mesh_file: MeshFile,
    /// Whether the mesh's own materials are used.
    pub mesh_use_embedded_materials: bool,
}

impl Marker {
    /// The fewest bytes one element takes in a sequence, padding aside: two stamps, twelve
    /// strings and sequences at 4 bytes each when empty, and the fixed fields.
    const MIN_CDR_SIZE: usize = 2 * 8 + 12 * 4 + 3 * 4 + 7 * 8 + 3 * 8 + 4 * 4 + 8 + 2;

    fn write(&self, w: &mut CdrWriter) -> Result<(), CdrEncodeError> {
        self.header.write(w)?;
        w.write_string("markers.ns", &self.ns)?;
        w.write_i32(self.id);
        w.write_i32(self.kind);
        w.write_i32(self.action);
        self.pose.position.write(w);
        self.pose.orientation.write(w);
        self.scale.write(w);
        self.color.write(w);
        w.write_i32(self.lifetime.sec);
        w.write_u32(self.lifetime.nanosec);
        w.write_bool(self.frame_locked);
        w.write_sequence("markers.points", &self.points, |w, p| {
            p.write(w);
            Ok(())
        })?;
        w.write_sequence("markers.colors", &self.colors, |w, c| {
            c.write(w);
            Ok(())
        })?;
        w.write_string("markers.texture_resource", &self.texture_resource)?;
        self.texture.header.write(w)?;
        w.write_string("markers.texture.format", &self.texture.format)?;
        w.write_u8_sequence("markers.texture.data", &self.texture.data)?;
        w.write_sequence(
            "markers.uv_coordinates",
            &self.uv_coordinates,
            |w, &(u, v)| {
                w.write_f32(u);
                w.write_f32(v);
                Ok(())
            },
        )?;
        w.write_string("markers.text", &self.text)?;
        w.write_string("markers.mesh_resource", &self.mesh_resource)?;
        w.write_string("markers.mesh_file.filename", &self.mesh_file.filename)?;
        w.write_u8_sequence("markers.mesh_file.data", &self.mesh_file.data)?;
        w.write_bool(self.mesh_use_embedded_materials);
        Ok(())
    }

    fn read(r: &mut CdrReader<'_>) -> Result<Marker, CdrError> {
        let header = Header::read(r)?;
        let ns = r.read_string("markers.ns")?;
        let id = r.read_i32("markers.id")?;
        let kind = r.read_i32("markers.type")?;
        let action = r.read_i32("markers.action")?;
        let pose = Pose {
            position: Vector3::read(r, "markers.pose.position")?,
            orientation: Quaternion::read(r, "markers.pose.orientation")?,
        };
        let scale = Vector3::read(r, "markers.scale")?;
        let color = ColorRgba::read(r, "markers.color")?;
        let lifetime = Duration {
            sec: r.read_i32("markers.lifetime.sec")?,
            nanosec: r.read_u32("markers.lifetime.nanosec")?,
        };
        let frame_locked = r.read_bool("markers.frame_locked")?;
        let points =
            r.read_sequence("markers.points", 24, |r| Vector3::read(r, "markers.points"))?;
        let colors = r.read_sequence("markers.colors", 16, |r| {
            ColorRgba::read(r, "markers.colors")
        })?;
        let texture_resource = r.read_string("markers.texture_resource")?;
        let texture = CompressedImage {
            header: Header::read(r)?,
            format: r.read_string("markers.texture.format")?,
            data: r.read_u8_sequence("markers.texture.data")?,
        };
        let uv_coordinates = r.read_sequence("markers.uv_coordinates", 8, |r| {
            Ok((
                r.read_f32("markers.uv_coordinates")?,
                r.read_f32("markers.uv_coordinates")?,
            ))
        })?;
        Ok(Marker {
            header,
            ns,
            id,
            kind,
            action,
            pose,
            scale,
            color,
            lifetime,
            frame_locked,
            points,
            colors,
            texture_resource,
            texture,
            uv_coordinates,
            text: r.read_string("markers.text")?,
            mesh_resource: r.read_string("markers.mesh_resource")?,
            mesh_file: MeshFile {
                filename: r.read_string("markers.mesh_file.filename")?,
                data: r.read_u8_sequence("markers.mesh_file.data")?,
            },
            mesh_use_embedded_materials: r.read_bool("markers.mesh_use_embedded_materials")?,
        })
    }
}

/// `visualization_msgs/msg/MarkerArray`: markers published together.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct MarkerArray {
    /// The markers, in the order a viewer applies them.
    pub markers: Vec<Marker>,
}

impl RosMessage for MarkerArray {
    message_identity! {
        "visualization_msgs" / "MarkerArray", &schema::MARKER_ARRAY,
        "RIHS01_86cb8800b6fb05b5eff1abd7a56f62a5641d3ae9a1c29e78e67e704f1d067dcf"
    }

    fn write_fields(&self, w: &mut CdrWriter) -> Result<(), CdrEncodeError> {
        w.write_sequence("markers", &self.markers, |w, marker| marker.write(w))
    }

    fn read_fields(r: &mut CdrReader<'_>) -> Result<Self, CdrError> {
        let markers = r.read_sequence("markers", Marker::MIN_CDR_SIZE, Marker::read)?;
        Ok(MarkerArray { markers })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_empty_marker_takes_its_minimum_size() {
        let array = MarkerArray {
            markers: vec![Marker::default()],
        };
        let bytes = array.to_cdr().unwrap();
        // Header (4) and the count (4), then the marker; the fixed f64 fields may add padding.
        assert!(bytes.len() - 8 >= Marker::MIN_CDR_SIZE, "{}", bytes.len());
        assert_eq!(MarkerArray::from_cdr(&bytes).unwrap(), array);
    }
}
