//! ROS 2 message and service types: what each is called, what fields it has, and its type
//! hash (RIHS01, REP 2016), which rmw_zenoh puts in every key and liveliness token.
//!
//! A message is declared once with [`ros_message!`]: the macro writes the Rust struct (whose
//! serde derive gives the CDR layout, fields in declaration order) and its type description
//! from the same field list, so the bytes and the hash cannot disagree.

use serde::Serialize;
use serde::de::DeserializeOwned;
use sha2::{Digest, Sha256};

/// A field's type as `type_description_interfaces/msg/FieldType` describes it.
#[derive(Clone, Copy, Debug)]
pub struct FieldType {
    pub type_id: u8,
    pub capacity: u64,
    pub string_capacity: u64,
    /// The nested message type, for a message, or a sequence or array of them.
    pub nested: Option<Nested>,
}

/// A nested message type: its name and how to list its fields.
#[derive(Clone, Copy, Debug)]
pub struct Nested {
    pub name: &'static str,
    pub fields: fn() -> Vec<Field>,
}

#[derive(Clone, Copy, Debug)]
pub struct Field {
    pub name: &'static str,
    pub ty: FieldType,
}

/// REP 2016's type ids of the element types; containers add an offset.
pub mod type_id {
    pub const NESTED: u8 = 1;
    pub const INT8: u8 = 2;
    pub const UINT8: u8 = 3;
    pub const INT16: u8 = 4;
    pub const UINT16: u8 = 5;
    pub const INT32: u8 = 6;
    pub const UINT32: u8 = 7;
    pub const INT64: u8 = 8;
    pub const UINT64: u8 = 9;
    pub const FLOAT: u8 = 10;
    pub const DOUBLE: u8 = 11;
    pub const BOOLEAN: u8 = 15;
    pub const STRING: u8 = 17;
    /// `T[N]`
    pub const ARRAY: u8 = 48;
    /// `T[<=N]`
    pub const BOUNDED_SEQUENCE: u8 = 96;
    /// `T[]`
    pub const UNBOUNDED_SEQUENCE: u8 = 144;
}

/// A Rust type that can be a ROS message field.
pub trait RosField {
    fn field_type() -> FieldType;
}

macro_rules! primitive_fields {
    ($($t:ty => $id:ident),* $(,)?) => {$(
        impl RosField for $t {
            fn field_type() -> FieldType {
                FieldType { type_id: type_id::$id, capacity: 0, string_capacity: 0, nested: None }
            }
        }
    )*};
}

primitive_fields!(
    i8 => INT8, u8 => UINT8, i16 => INT16, u16 => UINT16, i32 => INT32, u32 => UINT32,
    i64 => INT64, u64 => UINT64, f32 => FLOAT, f64 => DOUBLE, bool => BOOLEAN, String => STRING,
);

impl<T: RosField> RosField for Vec<T> {
    fn field_type() -> FieldType {
        let element = T::field_type();
        FieldType { type_id: element.type_id + type_id::UNBOUNDED_SEQUENCE, ..element }
    }
}

impl<T: RosField, const N: usize> RosField for [T; N] {
    fn field_type() -> FieldType {
        let element = T::field_type();
        FieldType { type_id: element.type_id + type_id::ARRAY, capacity: N as u64, ..element }
    }
}

/// A ROS 2 message type.
pub trait RosMessage: RosField + Serialize + DeserializeOwned + Send + Sync + 'static {
    /// `pkg/msg/Name` (`pkg/srv/Name_Request` for a service's request).
    const TYPE_NAME: &'static str;
    fn fields() -> Vec<Field>;
}

/// A ROS 2 service type.
pub trait RosService: Send + Sync + 'static {
    /// `pkg/srv/Name`
    const TYPE_NAME: &'static str;
    /// `pkg/srv/Name_Event`: the message rosidl generates for every service (part of its hash).
    const EVENT_TYPE_NAME: &'static str;
    type Request: RosMessage;
    type Response: RosMessage;
}

/// `pkg/msg/Name` as DDS and rmw_zenoh spell a type: `pkg::msg::dds_::Name_`.
pub fn dds_type_name(type_name: &str) -> String {
    let mut parts = type_name.split('/');
    let (pkg, kind, name) = (parts.next().unwrap_or(""), parts.next().unwrap_or(""), parts.next().unwrap_or(""));
    format!("{pkg}::{kind}::dds_::{name}_")
}

/// The RIHS01 hash of a message type.
pub fn message_hash<T: RosMessage>() -> String {
    hash_of(&Nested { name: T::TYPE_NAME, fields: T::fields })
}

/// REP 2016: SHA-256 of the type's description and every type it refers to (sorted by name,
/// once each), as JSON written the way Python's `json.dumps(..., separators=(", ", ": "))`
/// writes it, without default values.
pub(crate) fn hash_of(top: &Nested) -> String {
    let mut referenced = std::collections::BTreeMap::new();
    let mut todo: Vec<Nested> = nested_of(&(top.fields)());
    while let Some(n) = todo.pop() {
        if !referenced.contains_key(n.name) {
            let fields = (n.fields)();
            todo.extend(nested_of(&fields));
            referenced.insert(n.name, fields);
        }
    }
    let refs: Vec<String> = referenced.iter().map(|(name, fields)| individual(name, fields)).collect();
    let json = format!(
        r#"{{"type_description": {}, "referenced_type_descriptions": [{}]}}"#,
        individual(top.name, &(top.fields)()),
        refs.join(", ")
    );
    let digest = Sha256::digest(json.as_bytes());
    let hex: String = digest.iter().map(|b| format!("{b:02x}")).collect();
    format!("RIHS01_{hex}")
}

fn nested_of(fields: &[Field]) -> Vec<Nested> {
    fields.iter().filter_map(|f| f.ty.nested).collect()
}

fn individual(name: &str, fields: &[Field]) -> String {
    let fields: Vec<String> = fields
        .iter()
        .map(|f| {
            let t = &f.ty;
            format!(
                r#"{{"name": "{}", "type": {{"type_id": {}, "capacity": {}, "string_capacity": {}, "nested_type_name": "{}"}}}}"#,
                f.name,
                t.type_id,
                t.capacity,
                t.string_capacity,
                t.nested.map_or("", |n| n.name)
            )
        })
        .collect();
    format!(r#"{{"type_name": "{name}", "fields": [{}]}}"#, fields.join(", "))
}

/// Declares ROS 2 message types: each a serde struct (CDR in field order) and its type
/// description from the same list of fields.
///
/// ```ignore
/// ros_message! {
///     /// geometry_msgs/Point
///     #[derive(Copy, Default)]
///     pub struct Point = "geometry_msgs/msg/Point" { pub x: f64, pub y: f64, pub z: f64 }
/// }
/// ```
#[macro_export]
macro_rules! ros_message {
    ($(
        $(#[$meta:meta])*
        pub struct $name:ident = $type_name:literal {
            $( $(#[$fmeta:meta])* pub $field:ident : $fty:ty ),* $(,)?
        }
    )*) => {$(
        $(#[$meta])*
        #[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
        pub struct $name {
            $( $(#[$fmeta])* pub $field: $fty ),*
        }

        impl $crate::ros2::types::RosField for $name {
            fn field_type() -> $crate::ros2::types::FieldType {
                $crate::ros2::types::FieldType {
                    type_id: $crate::ros2::types::type_id::NESTED,
                    capacity: 0,
                    string_capacity: 0,
                    nested: Some($crate::ros2::types::Nested {
                        name: $type_name,
                        fields: <$name as $crate::ros2::types::RosMessage>::fields,
                    }),
                }
            }
        }

        impl $crate::ros2::types::RosMessage for $name {
            const TYPE_NAME: &'static str = $type_name;
            fn fields() -> Vec<$crate::ros2::types::Field> {
                vec![$(
                    $crate::ros2::types::Field {
                        name: stringify!($field).trim_start_matches("r#"),
                        ty: <$fty as $crate::ros2::types::RosField>::field_type(),
                    }
                ),*]
            }
        }
    )*};
}
