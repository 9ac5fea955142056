//! ROS 2's CDR (OMG XCDR1, as rmw_zenoh, rclcpp and zenoh-bridge-ros2dds carry it): a 4-byte
//! encapsulation header (`00 01 00 00` little-endian, `00 00 00 00` big-endian), then the
//! fields in declaration order, each primitive aligned to its size counted from the end of
//! the header; strings as a u32 length with the NUL counted and the NUL; sequences as a u32
//! count and the elements; fixed arrays as the elements alone.
//!
//! ROS 1's serialization is the same walk without the header, the alignment and the NULs,
//! and with std_msgs/Header's `seq` (written 0, skipped on reading): [`to_ros1_vec`] and
//! [`from_ros1_slice`] carry the same message structs over TCPROS (src/ros1/).
//!
//! polymap's own serde codec rather than a CDR crate: messages come from the network, and
//! decoding must never allocate more than the message it reads. Every length is checked
//! against the bytes left before anything is made of it (the `cdr` crate allocated the
//! length a string or sequence claimed, then checked: 16 bytes could claim 4 GiB), and a
//! message over [`MAX_MESSAGE_BYTES`] is refused unread.

use serde::de::{self, DeserializeSeed, IntoDeserializer, SeqAccess, Visitor};
use serde::{Deserialize, Serialize, ser};

/// Largest message polymap decodes, bytes: odometry is about 700, a service request less.
pub const MAX_MESSAGE_BYTES: usize = 1 << 20;

/// The field rosidl gives an empty ROS 2 message; ROS 1's empty messages have no bytes.
const ROSIDL_EMPTY_FIELD: &str = "structure_needs_at_least_one_member";

const HEADER_LE: [u8; 4] = [0, 1, 0, 0];
const HEADER_BE: [u8; 4] = [0, 0, 0, 0];

/// Why bytes are not a message, or a message not bytes.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum CdrError {
    #[error("{0} bytes, over the {MAX_MESSAGE_BYTES}-byte limit")]
    TooLarge(usize),
    #[error("no CDR encapsulation header (first bytes {0:02x?})")]
    Header(Vec<u8>),
    #[error("ends at byte {at} where {wanted} more were needed")]
    Truncated { at: usize, wanted: usize },
    #[error("a length of {claimed} at byte {at} claims more than the {left} bytes left")]
    LengthTooLong { at: usize, claimed: u64, left: usize },
    #[error("{0}")]
    Invalid(String),
    #[error("{0} trailing bytes after the message")]
    Trailing(usize),
}

impl ser::Error for CdrError {
    fn custom<T: std::fmt::Display>(msg: T) -> Self {
        CdrError::Invalid(msg.to_string())
    }
}

impl de::Error for CdrError {
    fn custom<T: std::fmt::Display>(msg: T) -> Self {
        CdrError::Invalid(msg.to_string())
    }
}

/// A message as little-endian CDR with its encapsulation header.
pub fn to_vec<T: Serialize + ?Sized>(msg: &T) -> Vec<u8> {
    let mut s = Writer { out: HEADER_LE.to_vec(), ros1: false };
    msg.serialize(&mut s).expect("ROS message types hold only what CDR can carry");
    s.out
}

/// A message as ROS 1 serializes it (TCPROS, rosbag): no header, no alignment.
pub fn to_ros1_vec<T: Serialize + ?Sized>(msg: &T) -> Vec<u8> {
    let mut s = Writer { out: Vec::new(), ros1: true };
    msg.serialize(&mut s).expect("ROS message types hold only what ROS 1 can carry");
    s.out
}

/// A message from ROS 1 bytes; every byte must be the message's.
pub fn from_ros1_slice<'a, T: Deserialize<'a>>(bytes: &'a [u8]) -> Result<T, CdrError> {
    if bytes.len() > MAX_MESSAGE_BYTES {
        return Err(CdrError::TooLarge(bytes.len()));
    }
    from_ros1_slice_unlimited(bytes)
}

/// As [`from_ros1_slice`], for a message whose size its caller has bounded (images, depth).
pub fn from_ros1_slice_unlimited<'a, T: Deserialize<'a>>(bytes: &'a [u8]) -> Result<T, CdrError> {
    let mut r = Reader { body: bytes, pos: 0, little: true, ros1: true };
    let msg = T::deserialize(&mut r)?;
    match r.body.len() - r.pos {
        0 => Ok(msg),
        n => Err(CdrError::Trailing(n)),
    }
}

/// A message from CDR bytes (either endianness). Trailing padding of up to 3 bytes is
/// allowed (some writers round the body to 4 bytes); anything more is an error.
pub fn from_slice<'a, T: Deserialize<'a>>(bytes: &'a [u8]) -> Result<T, CdrError> {
    if bytes.len() > MAX_MESSAGE_BYTES {
        return Err(CdrError::TooLarge(bytes.len()));
    }
    from_slice_unlimited(bytes)
}

/// As [`from_slice`], for a message whose size its caller has bounded (images in a log).
pub fn from_slice_unlimited<'a, T: Deserialize<'a>>(bytes: &'a [u8]) -> Result<T, CdrError> {
    let little = match bytes.get(..4) {
        Some(h) if h[..2] == HEADER_LE[..2] => true,
        Some(h) if h[..2] == HEADER_BE[..2] => false,
        _ => return Err(CdrError::Header(bytes.iter().take(4).copied().collect())),
    };
    let mut r = Reader { body: &bytes[4..], pos: 0, little, ros1: false };
    let msg = T::deserialize(&mut r)?;
    match r.body.len() - r.pos {
        0..=3 => Ok(msg),
        n => Err(CdrError::Trailing(n)),
    }
}

struct Writer {
    out: Vec<u8>,
    /// ROS 1's layout rather than CDR's.
    ros1: bool,
}

impl Writer {
    fn align(&mut self, n: usize) {
        if self.ros1 {
            return;
        }
        let body = self.out.len() - 4;
        self.out.resize(self.out.len() + (n - body % n) % n, 0);
    }

    fn len(&mut self, n: usize) -> Result<(), CdrError> {
        let n = u32::try_from(n).map_err(|_| CdrError::Invalid(format!("a length of {n} does not fit CDR's u32")))?;
        self.align(4);
        self.out.extend_from_slice(&n.to_le_bytes());
        Ok(())
    }
}

macro_rules! write_primitive {
    ($($method:ident($t:ty)),* $(,)?) => {$(
        fn $method(self, v: $t) -> Result<(), CdrError> {
            self.align(std::mem::size_of::<$t>());
            self.out.extend_from_slice(&v.to_le_bytes());
            Ok(())
        }
    )*};
}

impl ser::Serializer for &mut Writer {
    type Ok = ();
    type Error = CdrError;
    type SerializeSeq = Self;
    type SerializeTuple = Self;
    type SerializeTupleStruct = Self;
    type SerializeTupleVariant = ser::Impossible<(), CdrError>;
    type SerializeMap = ser::Impossible<(), CdrError>;
    type SerializeStruct = Self;
    type SerializeStructVariant = ser::Impossible<(), CdrError>;

    write_primitive!(
        serialize_i8(i8),
        serialize_i16(i16),
        serialize_i32(i32),
        serialize_i64(i64),
        serialize_u8(u8),
        serialize_u16(u16),
        serialize_u32(u32),
        serialize_u64(u64),
        serialize_f32(f32),
        serialize_f64(f64),
    );

    fn serialize_bool(self, v: bool) -> Result<(), CdrError> {
        self.out.push(v as u8);
        Ok(())
    }
    fn serialize_char(self, v: char) -> Result<(), CdrError> {
        let byte = u8::try_from(v).map_err(|_| CdrError::Invalid(format!("{v:?} is not a ROS char")))?;
        self.serialize_u8(byte)
    }
    fn serialize_str(self, v: &str) -> Result<(), CdrError> {
        self.len(v.len() + usize::from(!self.ros1))?;
        self.out.extend_from_slice(v.as_bytes());
        if !self.ros1 {
            self.out.push(0);
        }
        Ok(())
    }
    fn serialize_bytes(self, v: &[u8]) -> Result<(), CdrError> {
        self.len(v.len())?;
        self.out.extend_from_slice(v);
        Ok(())
    }
    fn serialize_none(self) -> Result<(), CdrError> {
        Err(CdrError::Invalid("CDR has no optional fields".into()))
    }
    fn serialize_some<T: Serialize + ?Sized>(self, _: &T) -> Result<(), CdrError> {
        Err(CdrError::Invalid("CDR has no optional fields".into()))
    }
    fn serialize_unit(self) -> Result<(), CdrError> {
        Ok(())
    }
    fn serialize_unit_struct(self, _: &'static str) -> Result<(), CdrError> {
        Ok(())
    }
    fn serialize_unit_variant(self, _: &'static str, index: u32, _: &'static str) -> Result<(), CdrError> {
        self.serialize_u32(index)
    }
    fn serialize_newtype_struct<T: Serialize + ?Sized>(self, _: &'static str, v: &T) -> Result<(), CdrError> {
        v.serialize(self)
    }
    fn serialize_newtype_variant<T: Serialize + ?Sized>(
        self,
        _: &'static str,
        _: u32,
        _: &'static str,
        _: &T,
    ) -> Result<(), CdrError> {
        Err(CdrError::Invalid("CDR has no unions here".into()))
    }
    fn serialize_seq(self, len: Option<usize>) -> Result<Self, CdrError> {
        self.len(len.ok_or_else(|| CdrError::Invalid("a sequence of unknown length".into()))?)?;
        Ok(self)
    }
    fn serialize_tuple(self, _: usize) -> Result<Self, CdrError> {
        Ok(self)
    }
    fn serialize_tuple_struct(self, _: &'static str, _: usize) -> Result<Self, CdrError> {
        Ok(self)
    }
    fn serialize_tuple_variant(
        self,
        _: &'static str,
        _: u32,
        _: &'static str,
        _: usize,
    ) -> Result<Self::SerializeTupleVariant, CdrError> {
        Err(CdrError::Invalid("CDR has no unions here".into()))
    }
    fn serialize_map(self, _: Option<usize>) -> Result<Self::SerializeMap, CdrError> {
        Err(CdrError::Invalid("CDR has no maps".into()))
    }
    fn serialize_struct(self, name: &'static str, _: usize) -> Result<Self, CdrError> {
        if self.ros1 && name == "Header" {
            self.serialize_u32(0)?; // ROS 1's seq: roscpp and rospy fill in their own
        }
        Ok(self)
    }
    fn serialize_struct_variant(
        self,
        _: &'static str,
        _: u32,
        _: &'static str,
        _: usize,
    ) -> Result<Self::SerializeStructVariant, CdrError> {
        Err(CdrError::Invalid("CDR has no unions here".into()))
    }
}

impl ser::SerializeSeq for &mut Writer {
    type Ok = ();
    type Error = CdrError;
    fn serialize_element<T: Serialize + ?Sized>(&mut self, v: &T) -> Result<(), CdrError> {
        v.serialize(&mut **self)
    }
    fn end(self) -> Result<(), CdrError> {
        Ok(())
    }
}

impl ser::SerializeTuple for &mut Writer {
    type Ok = ();
    type Error = CdrError;
    fn serialize_element<T: Serialize + ?Sized>(&mut self, v: &T) -> Result<(), CdrError> {
        v.serialize(&mut **self)
    }
    fn end(self) -> Result<(), CdrError> {
        Ok(())
    }
}

impl ser::SerializeTupleStruct for &mut Writer {
    type Ok = ();
    type Error = CdrError;
    fn serialize_field<T: Serialize + ?Sized>(&mut self, v: &T) -> Result<(), CdrError> {
        v.serialize(&mut **self)
    }
    fn end(self) -> Result<(), CdrError> {
        Ok(())
    }
}

impl ser::SerializeStruct for &mut Writer {
    type Ok = ();
    type Error = CdrError;
    fn serialize_field<T: Serialize + ?Sized>(&mut self, name: &'static str, v: &T) -> Result<(), CdrError> {
        if self.ros1 && name == ROSIDL_EMPTY_FIELD {
            return Ok(());
        }
        v.serialize(&mut **self)
    }
    fn end(self) -> Result<(), CdrError> {
        Ok(())
    }
}

struct Reader<'a> {
    body: &'a [u8],
    pos: usize,
    little: bool,
    /// ROS 1's layout rather than CDR's.
    ros1: bool,
}

impl<'a> Reader<'a> {
    fn left(&self) -> usize {
        self.body.len() - self.pos
    }

    /// Where the reader is, counted from the message's first byte.
    fn at(&self) -> usize {
        self.pos + if self.ros1 { 0 } else { 4 }
    }

    fn take(&mut self, n: usize) -> Result<&'a [u8], CdrError> {
        if n > self.left() {
            return Err(CdrError::Truncated { at: self.at(), wanted: n - self.left() });
        }
        let bytes = &self.body[self.pos..self.pos + n];
        self.pos += n;
        Ok(bytes)
    }

    fn align(&mut self, n: usize) -> Result<(), CdrError> {
        if self.ros1 {
            return Ok(());
        }
        let pad = (n - self.pos % n) % n;
        self.take(pad).map(|_| ())
    }

    fn array<const N: usize>(&mut self) -> Result<[u8; N], CdrError> {
        self.align(N)?;
        let mut a: [u8; N] = self.take(N)?.try_into().expect("took N bytes");
        if !self.little {
            a.reverse();
        }
        Ok(a)
    }

    /// A string's or sequence's length, never more than the bytes left: every element of a
    /// ROS message takes at least one byte.
    fn len(&mut self) -> Result<usize, CdrError> {
        let at = self.at();
        let n = u32::from_le_bytes(self.array::<4>()?) as usize;
        if n > self.left() {
            return Err(CdrError::LengthTooLong { at, claimed: n as u64, left: self.left() });
        }
        Ok(n)
    }

    fn string(&mut self) -> Result<&'a str, CdrError> {
        let at = self.at();
        let n = self.len()?;
        let bytes = self.take(n)?;
        if self.ros1 {
            return std::str::from_utf8(bytes).map_err(|e| CdrError::Invalid(format!("the string at byte {at}: {e}")));
        }
        // The count includes a terminating NUL; a few writers send an empty string as 0.
        let text = match bytes.split_last() {
            Some((0, text)) => text,
            Some(_) => return Err(CdrError::Invalid(format!("the string at byte {at} has no terminating NUL"))),
            None => bytes,
        };
        std::str::from_utf8(text).map_err(|e| CdrError::Invalid(format!("the string at byte {at}: {e}")))
    }
}

macro_rules! read_primitive {
    ($($method:ident($t:ty, $visit:ident)),* $(,)?) => {$(
        fn $method<V: Visitor<'de>>(self, v: V) -> Result<V::Value, CdrError> {
            v.$visit(<$t>::from_le_bytes(self.array()?))
        }
    )*};
}

impl<'de> de::Deserializer<'de> for &mut Reader<'de> {
    type Error = CdrError;

    read_primitive!(
        deserialize_i8(i8, visit_i8),
        deserialize_i16(i16, visit_i16),
        deserialize_i32(i32, visit_i32),
        deserialize_i64(i64, visit_i64),
        deserialize_u8(u8, visit_u8),
        deserialize_u16(u16, visit_u16),
        deserialize_u32(u32, visit_u32),
        deserialize_u64(u64, visit_u64),
        deserialize_f32(f32, visit_f32),
        deserialize_f64(f64, visit_f64),
    );

    fn deserialize_any<V: Visitor<'de>>(self, _: V) -> Result<V::Value, CdrError> {
        Err(CdrError::Invalid("CDR is not self-describing: the message type must be known".into()))
    }
    fn deserialize_bool<V: Visitor<'de>>(self, v: V) -> Result<V::Value, CdrError> {
        match self.take(1)?[0] {
            0 => v.visit_bool(false),
            1 => v.visit_bool(true),
            b => Err(CdrError::Invalid(format!("{b} at byte {} is not a bool", self.at() - 1))),
        }
    }
    fn deserialize_char<V: Visitor<'de>>(self, v: V) -> Result<V::Value, CdrError> {
        v.visit_char(self.take(1)?[0] as char)
    }
    fn deserialize_str<V: Visitor<'de>>(self, v: V) -> Result<V::Value, CdrError> {
        v.visit_borrowed_str(self.string()?)
    }
    fn deserialize_string<V: Visitor<'de>>(self, v: V) -> Result<V::Value, CdrError> {
        self.deserialize_str(v)
    }
    fn deserialize_bytes<V: Visitor<'de>>(self, v: V) -> Result<V::Value, CdrError> {
        let n = self.len()?;
        v.visit_borrowed_bytes(self.take(n)?)
    }
    fn deserialize_byte_buf<V: Visitor<'de>>(self, v: V) -> Result<V::Value, CdrError> {
        self.deserialize_bytes(v)
    }
    fn deserialize_option<V: Visitor<'de>>(self, _: V) -> Result<V::Value, CdrError> {
        Err(CdrError::Invalid("CDR has no optional fields".into()))
    }
    fn deserialize_unit<V: Visitor<'de>>(self, v: V) -> Result<V::Value, CdrError> {
        v.visit_unit()
    }
    fn deserialize_unit_struct<V: Visitor<'de>>(self, _: &'static str, v: V) -> Result<V::Value, CdrError> {
        v.visit_unit()
    }
    fn deserialize_newtype_struct<V: Visitor<'de>>(self, _: &'static str, v: V) -> Result<V::Value, CdrError> {
        v.visit_newtype_struct(self)
    }
    fn deserialize_seq<V: Visitor<'de>>(self, v: V) -> Result<V::Value, CdrError> {
        let n = self.len()?;
        v.visit_seq(Elements { reader: self, left: n })
    }
    fn deserialize_tuple<V: Visitor<'de>>(self, len: usize, v: V) -> Result<V::Value, CdrError> {
        v.visit_seq(Elements { reader: self, left: len })
    }
    fn deserialize_tuple_struct<V: Visitor<'de>>(
        self,
        _: &'static str,
        len: usize,
        v: V,
    ) -> Result<V::Value, CdrError> {
        self.deserialize_tuple(len, v)
    }
    fn deserialize_map<V: Visitor<'de>>(self, _: V) -> Result<V::Value, CdrError> {
        Err(CdrError::Invalid("CDR has no maps".into()))
    }
    fn deserialize_struct<V: Visitor<'de>>(
        self,
        name: &'static str,
        fields: &'static [&'static str],
        v: V,
    ) -> Result<V::Value, CdrError> {
        if self.ros1 && name == "Header" {
            self.take(4)?; // ROS 1's seq
        }
        if self.ros1 && fields == [ROSIDL_EMPTY_FIELD] {
            return v.visit_seq(de::value::SeqDeserializer::new(std::iter::once(0u8)));
        }
        self.deserialize_tuple(fields.len(), v)
    }
    fn deserialize_enum<V: Visitor<'de>>(
        self,
        _: &'static str,
        _: &'static [&'static str],
        v: V,
    ) -> Result<V::Value, CdrError> {
        let index = u32::from_le_bytes(self.array()?);
        v.visit_enum(index.into_deserializer())
    }
    fn deserialize_identifier<V: Visitor<'de>>(self, _: V) -> Result<V::Value, CdrError> {
        Err(CdrError::Invalid("CDR has no field names".into()))
    }
    fn deserialize_ignored_any<V: Visitor<'de>>(self, _: V) -> Result<V::Value, CdrError> {
        Err(CdrError::Invalid("CDR cannot skip a value of unknown type".into()))
    }
    fn is_human_readable(&self) -> bool {
        false
    }
}

/// The elements of a sequence, array or struct.
struct Elements<'r, 'de> {
    reader: &'r mut Reader<'de>,
    left: usize,
}

impl<'de> SeqAccess<'de> for Elements<'_, 'de> {
    type Error = CdrError;

    fn next_element_seed<T: DeserializeSeed<'de>>(&mut self, seed: T) -> Result<Option<T::Value>, CdrError> {
        if self.left == 0 {
            return Ok(None);
        }
        self.left -= 1;
        seed.deserialize(&mut *self.reader).map(Some)
    }

    /// Never more than the bytes left: what a collection reserves is bounded by the message.
    fn size_hint(&self) -> Option<usize> {
        Some(self.left.min(self.reader.left()))
    }
}
