//! ROS 1 bags (format 2.0), streamed: one record at a time, a chunk decompressed whole
//! (rosbag's chunks are 768 KiB by default), so memory does not grow with the bag.
//!
//! polymap's own reader rather than the `rosbag` crate, which memory-maps the whole file:
//! its pages stay resident as they are read, so a 400 MB bag would take 400 MB. Every
//! length is checked against a limit before anything is allocated, and a bag that ends
//! in the middle of a record says where.

use std::collections::{HashMap, VecDeque};
use std::io::{BufReader, Read};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use super::{Connection, Encoding, Message};
use crate::ros1::tcpros::fields_of;

const MAGIC: &[u8] = b"#ROSBAG V2.0\n";
/// Largest record header (a connection's carries its type's definition) and record data
/// (a chunk, compressed or not), bytes.
const MAX_HEADER_BYTES: usize = 1 << 20;
const MAX_DATA_BYTES: usize = 256 << 20;

const OP_MESSAGE: u8 = 0x02;
const OP_CHUNK: u8 = 0x05;
const OP_CONNECTION: u8 = 0x07;

#[derive(Debug, thiserror::Error)]
pub enum BagError {
    #[error("{path}: {why}")]
    Io { path: PathBuf, why: std::io::Error },
    #[error("{path}: not a ROS 1 bag (version 2.0): it starts {start:?}")]
    NotABag { path: PathBuf, start: String },
    #[error("{path}: truncated at byte {at}: {what}")]
    Truncated { path: PathBuf, at: u64, what: String },
    #[error("{path}: the record at byte {at}: {why}")]
    Record { path: PathBuf, at: u64, why: String },
}

/// A record's header and data.
type Record = (Vec<u8>, Vec<u8>);

pub struct BagReader {
    path: PathBuf,
    input: BufReader<std::fs::File>,
    /// Bytes read from the file so far.
    at: u64,
    connections: HashMap<u32, Arc<Connection>>,
    /// The messages of the chunk being read.
    pending: VecDeque<Message>,
}

impl BagReader {
    pub fn open(path: &Path) -> Result<BagReader, BagError> {
        let io = |why| BagError::Io { path: path.to_owned(), why };
        let mut input = BufReader::with_capacity(1 << 20, std::fs::File::open(path).map_err(io)?);
        let mut magic = [0u8; MAGIC.len()];
        let n = read_up_to(&mut input, &mut magic).map_err(io)?;
        if magic[..n] != *MAGIC {
            let start = String::from_utf8_lossy(&magic[..n]).into_owned();
            return Err(BagError::NotABag { path: path.to_owned(), start });
        }
        let at = MAGIC.len() as u64;
        Ok(BagReader { path: path.to_owned(), input, at, connections: HashMap::new(), pending: VecDeque::new() })
    }

    /// The next message, in the order the bag stores them; None at the end.
    pub fn next_message(&mut self) -> Result<Option<Message>, BagError> {
        loop {
            if let Some(m) = self.pending.pop_front() {
                return Ok(Some(m));
            }
            let start = self.at;
            let Some((header, data)) = self.record()? else { return Ok(None) };
            self.take(start, &header, data, false)?;
        }
    }

    /// One record's header and data, or None at the end of the file.
    fn record(&mut self) -> Result<Option<Record>, BagError> {
        let start = self.at;
        let Some(header) = self.block("a record header", MAX_HEADER_BYTES, true)? else { return Ok(None) };
        let data = self.block("a record's data", MAX_DATA_BYTES, false)?.ok_or_else(|| BagError::Truncated {
            path: self.path.clone(),
            at: self.at,
            what: format!("the record at byte {start} has no data"),
        })?;
        Ok(Some((header, data)))
    }

    /// A u32 length and that many bytes (None: the file ended cleanly before the length).
    fn block(&mut self, what: &str, limit: usize, may_end: bool) -> Result<Option<Vec<u8>>, BagError> {
        let mut len = [0u8; 4];
        let n = read_up_to(&mut self.input, &mut len).map_err(|why| BagError::Io { path: self.path.clone(), why })?;
        if n == 0 && may_end {
            return Ok(None);
        }
        if n < 4 {
            return Err(self.truncated(format!("{what}'s length")));
        }
        self.at += 4;
        let len = u32::from_le_bytes(len) as usize;
        if len > limit {
            return Err(BagError::Record {
                path: self.path.clone(),
                at: self.at - 4,
                why: format!("{what} of {len} bytes, over the {limit}-byte limit"),
            });
        }
        let mut bytes = Vec::with_capacity(len.min(1 << 20));
        let got = (&mut self.input)
            .take(len as u64)
            .read_to_end(&mut bytes)
            .map_err(|why| BagError::Io { path: self.path.clone(), why })?;
        self.at += got as u64;
        if got < len {
            return Err(self.truncated(format!("{what} of {len} bytes has {got}")));
        }
        Ok(Some(bytes))
    }

    fn truncated(&self, what: String) -> BagError {
        BagError::Truncated { path: self.path.clone(), at: self.at, what }
    }

    fn bad(&self, at: u64, why: impl std::fmt::Display) -> BagError {
        BagError::Record { path: self.path.clone(), at, why: why.to_string() }
    }

    /// What a record means: connections are kept, messages queued, chunks opened; the rest
    /// (the bag header, indexes, chunk infos) is skipped.
    fn take(&mut self, at: u64, header: &[u8], data: Vec<u8>, in_chunk: bool) -> Result<(), BagError> {
        let fields = fields_of(header).map_err(|e| self.bad(at, e))?;
        let field = |name: &str| fields.iter().find(|(k, _)| *k == name).map(|(_, v)| *v);
        let u32_of = |name: &str| {
            field(name)
                .and_then(|v| v.try_into().ok())
                .map(u32::from_le_bytes)
                .ok_or_else(|| self.bad(at, format!("no 4-byte `{name}`")))
        };
        match field("op") {
            Some([OP_CONNECTION]) => {
                let conn = u32_of("conn")?;
                let topic = String::from_utf8_lossy(field("topic").unwrap_or_default()).into_owned();
                let own = fields_of(&data).map_err(|e| self.bad(at, e))?;
                let message_type = own
                    .iter()
                    .find(|(k, _)| *k == "type")
                    .map(|(_, v)| String::from_utf8_lossy(v).into_owned())
                    .ok_or_else(|| self.bad(at, "a connection without a type"))?;
                self.connections.insert(conn, Arc::new(Connection { topic, message_type, encoding: Encoding::Ros1 }));
            }
            Some([OP_MESSAGE]) => {
                let conn = u32_of("conn")?;
                let time =
                    field("time").and_then(|v| <[u8; 8]>::try_from(v).ok()).ok_or_else(|| self.bad(at, "no `time`"))?;
                let (sec, nsec) = (
                    u32::from_le_bytes(time[..4].try_into().unwrap_or_default()),
                    u32::from_le_bytes(time[4..].try_into().unwrap_or_default()),
                );
                let connection = self
                    .connections
                    .get(&conn)
                    .cloned()
                    .ok_or_else(|| self.bad(at, format!("a message on connection {conn}, never declared")))?;
                self.pending.push_back(Message { connection, time_ns: sec as u64 * 1_000_000_000 + nsec as u64, data });
            }
            Some([OP_CHUNK]) if !in_chunk => {
                let size = u32_of("size")? as usize;
                if size > MAX_DATA_BYTES {
                    return Err(self.bad(at, format!("a chunk of {size} bytes, over the {MAX_DATA_BYTES}-byte limit")));
                }
                let compression = String::from_utf8_lossy(field("compression").unwrap_or(b"none")).into_owned();
                let chunk = self.decompress(at, &compression, data, size)?;
                self.chunk(at, &chunk)?;
            }
            Some(_) => {}
            None => return Err(self.bad(at, "a record without `op`")),
        }
        Ok(())
    }

    fn decompress(&self, at: u64, compression: &str, data: Vec<u8>, size: usize) -> Result<Vec<u8>, BagError> {
        let mut out = Vec::with_capacity(size);
        let read = match compression {
            "none" => return Ok(data),
            "bz2" => bzip2::read::BzDecoder::new(&data[..]).take(size as u64 + 1).read_to_end(&mut out),
            "lz4" => lz4_flex::frame::FrameDecoder::new(&data[..]).take(size as u64 + 1).read_to_end(&mut out),
            other => return Err(self.bad(at, format!("chunk compression {other:?} (polymap reads none, bz2 and lz4)"))),
        };
        match read {
            Ok(n) if n == size => Ok(out),
            Ok(n) => Err(self.bad(at, format!("a {compression} chunk of {n} bytes where its header says {size}"))),
            Err(e) => Err(self.bad(at, format!("a {compression} chunk: {e}"))),
        }
    }

    /// The records inside a chunk.
    fn chunk(&mut self, at: u64, mut bytes: &[u8]) -> Result<(), BagError> {
        let block = |bytes: &mut &[u8]| -> Option<Vec<u8>> {
            let (len, rest) = bytes.split_first_chunk::<4>()?;
            let len = u32::from_le_bytes(*len) as usize;
            let (block, rest) = (rest.get(..len)?, &rest[len..]);
            *bytes = rest;
            Some(block.to_vec())
        };
        while !bytes.is_empty() {
            let (Some(header), Some(data)) = (block(&mut bytes), block(&mut bytes)) else {
                return Err(self.bad(at, "a record in the chunk runs past its end"));
            };
            self.take(at, &header, data, true)?;
        }
        Ok(())
    }
}

/// Reads as much of `buf` as the input has (less only at its end).
fn read_up_to(input: &mut impl Read, buf: &mut [u8]) -> std::io::Result<usize> {
    let mut n = 0;
    while n < buf.len() {
        match input.read(&mut buf[n..])? {
            0 => break,
            k => n += k,
        }
    }
    Ok(n)
}
