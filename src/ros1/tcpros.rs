//! TCPROS framing: a connection header (a u32 length, then fields each a u32 length and
//! `key=value`), then messages each a u32 length and the serialized message.
//!
//! Every length a peer sends is checked before anything is allocated: against the limit of
//! what it frames (a header, a topic's messages) and, inside a header, against the bytes
//! left. A body is read with its buffer growing as bytes arrive, so a peer that claims a
//! megabyte and sends ten bytes holds ten.

use std::collections::BTreeMap;
use std::time::Duration;

use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};

/// Largest connection header read, bytes. A subscriber's carries its type's full definition
/// (PlanarTerrain's, the longest polymap meets, is under 8 KiB).
pub const MAX_HEADER_BYTES: usize = 64 * 1024;

/// How long a peer has to send its connection header, or to answer ours.
pub const HANDSHAKE_TIMEOUT: Duration = Duration::from_secs(5);

/// How long the rest of a frame may take once its length came: a peer that stalls a
/// message half-sent holds its buffer no longer than this.
pub const BODY_TIMEOUT: Duration = Duration::from_secs(5);

#[derive(Debug, thiserror::Error)]
pub enum TcprosError {
    #[error("{0}")]
    Io(#[from] std::io::Error),
    #[error("{what} of {claimed} bytes is over the {limit}-byte limit")]
    TooLong { what: &'static str, claimed: u64, limit: usize },
    #[error("the connection header is malformed: {0}")]
    Malformed(String),
    #[error("{what} did not arrive within {} s", after.as_secs_f64())]
    Timeout { what: &'static str, after: Duration },
    #[error("the peer refused the connection: {0}")]
    Refused(String),
}

/// A connection header's fields.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct ConnectionHeader(pub BTreeMap<String, String>);

impl ConnectionHeader {
    pub fn new(fields: &[(&str, &str)]) -> ConnectionHeader {
        ConnectionHeader(fields.iter().map(|(k, v)| (k.to_string(), v.to_string())).collect())
    }

    pub fn get(&self, key: &str) -> Option<&str> {
        self.0.get(key).map(String::as_str)
    }

    /// A field that must be there.
    pub fn require(&self, key: &str) -> Result<&str, TcprosError> {
        self.get(key).ok_or_else(|| TcprosError::Malformed(format!("no `{key}` field")))
    }

    /// The header as it goes on the wire, its length first.
    pub fn encode(&self) -> Vec<u8> {
        let mut body = Vec::new();
        for (k, v) in &self.0 {
            body.extend_from_slice(&((k.len() + 1 + v.len()) as u32).to_le_bytes());
            body.extend_from_slice(k.as_bytes());
            body.push(b'=');
            body.extend_from_slice(v.as_bytes());
        }
        let mut out = (body.len() as u32).to_le_bytes().to_vec();
        out.extend_from_slice(&body);
        out
    }

    /// A header's fields from its bytes (without the total length).
    pub fn decode(bytes: &[u8]) -> Result<ConnectionHeader, TcprosError> {
        let mut fields = BTreeMap::new();
        for (k, v) in fields_of(bytes)? {
            let v = std::str::from_utf8(v).map_err(|e| TcprosError::Malformed(format!("field {k}: {e}")))?;
            fields.insert(k.to_string(), v.to_string());
        }
        Ok(ConnectionHeader(fields))
    }
}

/// The `name=value` fields of a header (TCPROS's, or a rosbag record's, whose values may be
/// binary), each checked against the bytes left.
pub fn fields_of(mut bytes: &[u8]) -> Result<Vec<(&str, &[u8])>, TcprosError> {
    let mut fields = Vec::new();
    while !bytes.is_empty() {
        let Some((len, rest)) = bytes.split_first_chunk::<4>() else {
            return Err(TcprosError::Malformed(format!("{} stray bytes at the end", bytes.len())));
        };
        let len = u32::from_le_bytes(*len) as usize;
        if len > rest.len() {
            return Err(TcprosError::Malformed(format!("a field claims {len} bytes where {} are left", rest.len())));
        }
        let (field, rest) = rest.split_at(len);
        let eq = field.iter().position(|&b| b == b'=').ok_or_else(|| {
            TcprosError::Malformed(format!("{:?} has no `=`", String::from_utf8_lossy(&field[..field.len().min(40)])))
        })?;
        let name =
            std::str::from_utf8(&field[..eq]).map_err(|e| TcprosError::Malformed(format!("a field name: {e}")))?;
        fields.push((name, &field[eq + 1..]));
        bytes = rest;
    }
    Ok(fields)
}

/// The peer's connection header, within [`HANDSHAKE_TIMEOUT`].
pub async fn read_header<S: AsyncRead + Unpin>(stream: &mut S) -> Result<ConnectionHeader, TcprosError> {
    let what = "a connection header";
    let bytes = within(HANDSHAKE_TIMEOUT, what, read_frame(stream, what, MAX_HEADER_BYTES, None)).await??;
    ConnectionHeader::decode(&bytes)
}

/// One length-prefixed frame of at most `limit` bytes: its length within `start` (None:
/// however long it takes), the rest within [`BODY_TIMEOUT`] of it.
pub async fn read_frame<S: AsyncRead + Unpin>(
    stream: &mut S,
    what: &'static str,
    limit: usize,
    start: Option<Duration>,
) -> Result<Vec<u8>, TcprosError> {
    let len = match start {
        Some(after) => within(after, what, stream.read_u32_le()).await??,
        None => stream.read_u32_le().await?,
    } as usize;
    if len > limit {
        return Err(TcprosError::TooLong { what, claimed: len as u64, limit });
    }
    super::note_read(len);
    within(BODY_TIMEOUT, what, read_body(stream, what, len)).await?
}

async fn within<T>(after: Duration, what: &'static str, f: impl Future<Output = T>) -> Result<T, TcprosError> {
    tokio::time::timeout(after, f).await.map_err(|_| TcprosError::Timeout { what, after })
}

async fn read_body<S: AsyncRead + Unpin>(
    stream: &mut S,
    what: &'static str,
    len: usize,
) -> Result<Vec<u8>, TcprosError> {
    let mut body = Vec::with_capacity(len.min(64 * 1024));
    let read = (&mut *stream).take(len as u64).read_to_end(&mut body).await?;
    if read < len {
        return Err(std::io::Error::new(
            std::io::ErrorKind::UnexpectedEof,
            format!("{what} ends after {read} of {len} bytes"),
        )
        .into());
    }
    Ok(body)
}

/// `bytes` with their length first, in one write.
pub fn framed(bytes: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(4 + bytes.len());
    out.extend_from_slice(&(bytes.len() as u32).to_le_bytes());
    out.extend_from_slice(bytes);
    out
}

pub async fn write_header<S: AsyncWrite + Unpin>(stream: &mut S, header: &ConnectionHeader) -> std::io::Result<()> {
    stream.write_all(&header.encode()).await?;
    stream.flush().await
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_header_decodes_to_what_was_encoded() {
        let h = ConnectionHeader::new(&[("topic", "/odom"), ("md5sum", "*"), ("message_definition", "a=b\nc")]);
        let bytes = h.encode();
        assert_eq!(u32::from_le_bytes(bytes[..4].try_into().unwrap()) as usize, bytes.len() - 4);
        assert_eq!(ConnectionHeader::decode(&bytes[4..]).unwrap(), h);
    }

    #[test]
    fn a_field_longer_than_the_header_is_refused() {
        let mut bytes = 0xFFFF_FFF0u32.to_le_bytes().to_vec();
        bytes.extend_from_slice(b"topic=/x");
        assert!(matches!(ConnectionHeader::decode(&bytes), Err(TcprosError::Malformed(_))));
        assert!(matches!(ConnectionHeader::decode(&[1, 0]), Err(TcprosError::Malformed(_))));
        assert!(matches!(ConnectionHeader::decode(&[3, 0, 0, 0, b'a', b'b', b'c']), Err(TcprosError::Malformed(_))));
    }

    #[tokio::test]
    async fn a_frame_over_the_limit_is_refused_unread() {
        let mut bytes: &[u8] = &[0xF0, 0xFF, 0xFF, 0xFF, 1, 2, 3];
        match read_frame(&mut bytes, "a message", 1024, None).await {
            Err(TcprosError::TooLong { claimed, limit: 1024, .. }) => assert_eq!(claimed, 0xFFFF_FFF0),
            other => panic!("{other:?}"),
        }
        let mut short: &[u8] = &[8, 0, 0, 0, 1, 2];
        assert!(matches!(read_frame(&mut short, "a message", 1024, None).await, Err(TcprosError::Io(_))));
    }

    #[tokio::test(start_paused = true)]
    async fn a_frame_that_stalls_is_given_up() {
        // Its length, then nothing: the body's deadline ends it.
        let (mut ours, mut theirs) = tokio::io::duplex(64);
        theirs.write_all(&100u32.to_le_bytes()).await.unwrap();
        let read = read_frame(&mut ours, "a message", 1024, None).await;
        assert!(matches!(read, Err(TcprosError::Timeout { what: "a message", after: BODY_TIMEOUT })), "{read:?}");
        // Nothing at all, where its start has a deadline too.
        let read = read_frame(&mut ours, "a request", 1024, Some(Duration::from_secs(2))).await;
        assert!(matches!(read, Err(TcprosError::Timeout { what: "a request", .. })), "{read:?}");
        drop(theirs);
    }
}
