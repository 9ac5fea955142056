//! ROS 2 bags in MCAP (rosbag2's default storage since Iron), streamed with foxglove's `mcap`
//! crate's sans-io reader: one chunk in memory at a time, every record's length bounded.

use std::collections::{HashMap, VecDeque};
use std::io::Read;
use std::path::PathBuf;
use std::sync::Arc;

use ::mcap::records::Record;
use ::mcap::sans_io::linear_reader::{LinearReadEvent, LinearReader, LinearReaderOptions};

use super::{Connection, Encoding, Message};

/// Largest record (a chunk, compressed or not, or one message) read, bytes.
const MAX_RECORD_BYTES: usize = 256 << 20;

#[derive(Debug, thiserror::Error)]
pub enum McapFileError {
    #[error("{path}: {why}")]
    Io { path: PathBuf, why: std::io::Error },
    #[error("{path}: not a readable MCAP file: {why}")]
    Format { path: PathBuf, why: String },
}

/// The messages of one or more MCAP files (a rosbag2 split into several), in file order.
pub struct McapReader {
    files: VecDeque<PathBuf>,
    current: Option<(PathBuf, std::fs::File, LinearReader)>,
    /// Schema id -> its name (`sensor_msgs/msg/Image`), and channel id -> its connection.
    schemas: HashMap<u16, String>,
    channels: HashMap<u16, Arc<Connection>>,
}

impl McapReader {
    pub fn open(files: &[PathBuf]) -> Result<McapReader, McapFileError> {
        let mut reader = McapReader {
            files: files.iter().cloned().collect(),
            current: None,
            schemas: HashMap::new(),
            channels: HashMap::new(),
        };
        reader.next_file()?;
        Ok(reader)
    }

    /// Opens the next file; false when there is none.
    fn next_file(&mut self) -> Result<bool, McapFileError> {
        let Some(path) = self.files.pop_front() else { return Ok(false) };
        let file = std::fs::File::open(&path).map_err(|why| McapFileError::Io { path: path.clone(), why })?;
        let options = LinearReaderOptions::default().with_record_length_limit(MAX_RECORD_BYTES);
        self.current = Some((path, file, LinearReader::new_with_options(options)));
        // Ids are a file's own.
        self.schemas.clear();
        self.channels.clear();
        Ok(true)
    }

    /// The next message, in the order the files store them; None at the end.
    pub fn next_message(&mut self) -> Result<Option<Message>, McapFileError> {
        // The mcap crate (0.24 to 0.26) subtracts a record's length inside an uncompressed
        // chunk from what the chunk has left unchecked: a record longer than its chunk
        // panics (overflow checks are on for it, release too, so it never wraps on).
        let path = self.current.as_ref().map(|(path, ..)| path.clone()).unwrap_or_default();
        std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| self.read_next())).unwrap_or_else(|_| {
            self.current = None;
            self.files.clear();
            Err(McapFileError::Format { path, why: "a record longer than the chunk holding it".into() })
        })
    }

    fn read_next(&mut self) -> Result<Option<Message>, McapFileError> {
        loop {
            let Some((path, file, reader)) = &mut self.current else { return Ok(None) };
            let format = |why: String| McapFileError::Format { path: path.clone(), why };
            let event = match reader.next_event() {
                Some(event) => event.map_err(|e| format(e.to_string()))?,
                None => {
                    self.current = None;
                    self.next_file()?;
                    continue;
                }
            };
            match event {
                LinearReadEvent::ReadRequest(need) => {
                    let n =
                        file.read(reader.insert(need)).map_err(|why| McapFileError::Io { path: path.clone(), why })?;
                    reader.notify_read(n);
                }
                LinearReadEvent::Record { opcode, data } => {
                    match ::mcap::parse_record(opcode, data).map_err(|e| format(e.to_string()))? {
                        Record::Schema { header, .. } => {
                            self.schemas.insert(header.id, header.name);
                        }
                        Record::Channel(c) => {
                            let encoding = match c.message_encoding.as_str() {
                                "cdr" => Encoding::Cdr,
                                "ros1" => Encoding::Ros1,
                                other => Encoding::Other(other.to_string()),
                            };
                            let message_type = self.schemas.get(&c.schema_id).cloned().unwrap_or_default();
                            self.channels.insert(c.id, Arc::new(Connection { topic: c.topic, message_type, encoding }));
                        }
                        Record::Message { header, data } => {
                            let connection = self.channels.get(&header.channel_id).cloned().ok_or_else(|| {
                                format(format!("a message on channel {}, never declared", header.channel_id))
                            })?;
                            return Ok(Some(Message { connection, time_ns: header.log_time, data: data.into_owned() }));
                        }
                        _ => {}
                    }
                }
            }
        }
    }
}
