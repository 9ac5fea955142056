//! rmw_zenoh's sample attachment: who sent a sample and its place in their stream. Every
//! sample, query and reply carries one, and rmw_zenoh drops samples without it.
//!
//! Layout (zenoh-ext's serializer, no keys): sequence number (i64 LE), source timestamp (i64
//! LE, ns since the epoch), then the 16-byte GID as a sequence (LEB128 length 16, the bytes).
//! rmw_zenoh before 0.2.4 (Jazzy) / 0.1.2 (Humble) wrote each field after its name; such
//! attachments are read too.

/// A sender's identity: XXH3-128 of its liveliness token, as rmw_zenoh derives it.
pub type Gid = [u8; 16];

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Attachment {
    pub sequence_number: i64,
    pub source_timestamp_ns: i64,
    pub gid: Gid,
}

/// The length byte of the GID sequence.
const GID_LEN: u8 = 16;
/// The older, keyed layout's field names.
const KEYS: [&[u8]; 3] = [b"sequence_number", b"source_timestamp", b"source_gid"];

/// The GID of the entity announced by `token`.
pub fn gid_of(token: &str) -> Gid {
    xxhash_rust::xxh3::xxh3_128(token.as_bytes()).to_le_bytes()
}

impl Attachment {
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(33);
        out.extend_from_slice(&self.sequence_number.to_le_bytes());
        out.extend_from_slice(&self.source_timestamp_ns.to_le_bytes());
        out.push(GID_LEN);
        out.extend_from_slice(&self.gid);
        out
    }

    /// Reads either layout; None for anything else.
    pub fn from_bytes(bytes: &[u8]) -> Option<Attachment> {
        let mut r = bytes;
        // The two layouts differ in length: 33 bytes, or 77 with the names.
        let keyed = bytes.len() == 33 + KEYS.iter().map(|k| 1 + k.len()).sum::<usize>();
        let mut field = |name: &[u8], len: usize| -> Option<&[u8]> {
            if keyed {
                let (&n, rest) = r.split_first()?;
                let key = rest.get(..n as usize)?;
                if key != name {
                    return None;
                }
                r = &rest[n as usize..];
            }
            let value = r.get(..len)?;
            r = &r[len..];
            Some(value)
        };
        let sequence_number = i64::from_le_bytes(field(KEYS[0], 8)?.try_into().ok()?);
        let source_timestamp_ns = i64::from_le_bytes(field(KEYS[1], 8)?.try_into().ok()?);
        let gid_seq = field(KEYS[2], 17)?;
        if gid_seq[0] != GID_LEN || !r.is_empty() {
            return None;
        }
        Some(Attachment { sequence_number, source_timestamp_ns, gid: gid_seq[1..].try_into().ok()? })
    }
}
