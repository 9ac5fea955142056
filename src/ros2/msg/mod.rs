//! ROS 2 message and service types: the common interfaces polymap uses, polymap_msgs, and
//! the terrain messages of existing legged planners; and services' type hashes, which
//! hold service_msgs/ServiceEventInfo.

mod polymap;
mod standard;
mod terrain;

pub use polymap::*;
pub use standard::*;
pub use terrain::*;

use crate::ros2::types::{Field, FieldType, Nested, RosField, RosMessage, RosService, hash_of, type_id};

/// The RIHS01 hash of a service type: of its description with the request, the response and
/// the event message rosidl generates for every service.
pub fn service_hash<S: RosService>() -> String {
    hash_of(&service_description::<S>())
}

fn service_description<S: RosService>() -> Nested {
    fn parts<S: RosService>() -> Vec<Field> {
        let nested =
            |n: Nested| FieldType { type_id: type_id::NESTED, capacity: 0, string_capacity: 0, nested: Some(n) };
        let [request, response] = request_and_response::<S>(["request_message", "response_message"], nested);
        let event =
            Field { name: "event_message", ty: nested(Nested { name: S::EVENT_TYPE_NAME, fields: event_fields::<S> }) };
        vec![request, response, event]
    }
    fn event_fields<S: RosService>() -> Vec<Field> {
        let at_most_one = |n: Nested| FieldType {
            type_id: type_id::NESTED + type_id::BOUNDED_SEQUENCE,
            capacity: 1,
            string_capacity: 0,
            nested: Some(n),
        };
        let [request, response] = request_and_response::<S>(["request", "response"], at_most_one);
        vec![Field { name: "info", ty: ServiceEventInfo::field_type() }, request, response]
    }
    Nested { name: S::TYPE_NAME, fields: parts::<S> }
}

/// Fields `names` holding the service's request and its response, each typed by `ty`.
fn request_and_response<S: RosService>(names: [&'static str; 2], ty: impl Fn(Nested) -> FieldType) -> [Field; 2] {
    [
        Field { name: names[0], ty: ty(Nested { name: S::Request::TYPE_NAME, fields: S::Request::fields }) },
        Field { name: names[1], ty: ty(Nested { name: S::Response::TYPE_NAME, fields: S::Response::fields }) },
    ]
}
