//! XML-RPC over HTTP/1.1, as far as ROS 1's master and slave APIs use it: calls and
//! responses of ints, booleans, doubles, strings, arrays and structs.
//!
//! polymap's own small client and server rather than an XML-RPC crate: what a peer sends is
//! bounded (the request head, the body, the nesting of values) before it is read, and the
//! only dependencies are quick-xml's parser and httparse's head parser.

use std::time::Duration;

use quick_xml::events::Event;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpStream;

/// Largest HTTP head and body read, bytes. The master's longest answer (a topic's publishers)
/// is a few KiB.
pub const MAX_HEAD_BYTES: usize = 16 * 1024;
pub const MAX_BODY_BYTES: usize = 1 << 20;
/// Deepest nesting of arrays and structs read.
const MAX_DEPTH: usize = 16;
/// How long a call or a request may take.
pub const TIMEOUT: Duration = Duration::from_secs(5);

#[derive(Clone, Debug, PartialEq)]
pub enum Value {
    Int(i32),
    Bool(bool),
    Double(f64),
    Str(String),
    Array(Vec<Value>),
    Struct(Vec<(String, Value)>),
}

impl Value {
    pub fn as_str(&self) -> Option<&str> {
        match self {
            Value::Str(s) => Some(s),
            _ => None,
        }
    }
    pub fn as_int(&self) -> Option<i32> {
        match self {
            Value::Int(i) => Some(*i),
            _ => None,
        }
    }
    pub fn as_array(&self) -> Option<&[Value]> {
        match self {
            Value::Array(a) => Some(a),
            _ => None,
        }
    }

    fn write(&self, out: &mut String) {
        out.push_str("<value>");
        match self {
            Value::Int(i) => out.push_str(&format!("<i4>{i}</i4>")),
            Value::Bool(b) => out.push_str(&format!("<boolean>{}</boolean>", u8::from(*b))),
            Value::Double(d) => out.push_str(&format!("<double>{d:?}</double>")),
            Value::Str(s) => out.push_str(&format!("<string>{}</string>", quick_xml::escape::escape(s.as_str()))),
            Value::Array(items) => {
                out.push_str("<array><data>");
                items.iter().for_each(|v| v.write(out));
                out.push_str("</data></array>");
            }
            Value::Struct(members) => {
                out.push_str("<struct>");
                for (name, v) in members {
                    out.push_str(&format!("<member><name>{}</name>", quick_xml::escape::escape(name.as_str())));
                    v.write(out);
                    out.push_str("</member>");
                }
                out.push_str("</struct>");
            }
        }
        out.push_str("</value>");
    }
}

impl From<&str> for Value {
    fn from(s: &str) -> Value {
        Value::Str(s.to_string())
    }
}

impl From<i32> for Value {
    fn from(i: i32) -> Value {
        Value::Int(i)
    }
}

#[derive(Debug, thiserror::Error)]
pub enum XmlRpcError {
    #[error("{0}")]
    Io(#[from] std::io::Error),
    #[error("no answer within {} s", TIMEOUT.as_secs())]
    Timeout,
    #[error("HTTP: {0}")]
    Http(String),
    #[error("XML-RPC: {0}")]
    Malformed(String),
    #[error("XML-RPC fault {code}: {message}")]
    Fault { code: i32, message: String },
}

fn malformed(what: impl std::fmt::Display) -> XmlRpcError {
    XmlRpcError::Malformed(what.to_string())
}

pub fn call_body(method: &str, params: &[Value]) -> String {
    let mut out = format!("<?xml version=\"1.0\"?><methodCall><methodName>{method}</methodName><params>");
    for p in params {
        out.push_str("<param>");
        p.write(&mut out);
        out.push_str("</param>");
    }
    out + "</params></methodCall>"
}

pub fn response_body(value: &Value) -> String {
    let mut out = String::from("<?xml version=\"1.0\"?><methodResponse><params><param>");
    value.write(&mut out);
    out + "</param></params></methodResponse>"
}

pub fn fault_body(code: i32, message: &str) -> String {
    let mut out = String::from("<?xml version=\"1.0\"?><methodResponse><fault>");
    Value::Struct(vec![("faultCode".into(), Value::Int(code)), ("faultString".into(), message.into())]).write(&mut out);
    out + "</fault></methodResponse>"
}

/// A parser over a document, skipping what carries no value (declarations, whitespace).
struct Parser<'a> {
    reader: quick_xml::Reader<&'a [u8]>,
}

impl<'a> Parser<'a> {
    fn new(xml: &'a [u8]) -> Parser<'a> {
        Parser { reader: quick_xml::Reader::from_reader(xml) }
    }

    fn next(&mut self) -> Result<Event<'a>, XmlRpcError> {
        loop {
            match self.reader.read_event().map_err(malformed)? {
                Event::Decl(_) | Event::Comment(_) | Event::PI(_) | Event::DocType(_) => continue,
                Event::Text(t) if t.iter().all(u8::is_ascii_whitespace) => continue,
                e => return Ok(e),
            }
        }
    }

    /// The next element's start; its name.
    fn open(&mut self) -> Result<String, XmlRpcError> {
        match self.next()? {
            Event::Start(s) => Ok(String::from_utf8_lossy(s.name().as_ref()).into_owned()),
            e => Err(malformed(format!("expected an element, found {e:?}"))),
        }
    }

    fn expect_open(&mut self, name: &str) -> Result<(), XmlRpcError> {
        match self.open()? {
            n if n == name => Ok(()),
            n => Err(malformed(format!("expected <{name}>, found <{n}>"))),
        }
    }

    fn expect_close(&mut self, name: &str) -> Result<(), XmlRpcError> {
        match self.next()? {
            Event::End(e) if e.name().as_ref() == name.as_bytes() => Ok(()),
            e => Err(malformed(format!("expected </{name}>, found {e:?}"))),
        }
    }

    /// Text up to the closing tag of `name` (an element with nothing in it gives "").
    fn text(&mut self, name: &str) -> Result<String, XmlRpcError> {
        let mut text = String::new();
        loop {
            match self.reader.read_event().map_err(malformed)? {
                Event::Text(t) => text.push_str(&t.xml_content().map_err(malformed)?),
                Event::GeneralRef(r) => {
                    let name = String::from_utf8_lossy(&r);
                    let resolved = match name.as_ref() {
                        "lt" => "<".to_string(),
                        "gt" => ">".to_string(),
                        "amp" => "&".to_string(),
                        "quot" => "\"".to_string(),
                        "apos" => "'".to_string(),
                        _ => match r.resolve_char_ref().map_err(malformed)? {
                            Some(c) => c.to_string(),
                            None => return Err(malformed(format!("unknown entity &{name};"))),
                        },
                    };
                    text.push_str(&resolved);
                }
                Event::CData(c) => text.push_str(&String::from_utf8_lossy(&c)),
                Event::End(e) if e.name().as_ref() == name.as_bytes() => return Ok(text),
                e => return Err(malformed(format!("expected text in <{name}>, found {e:?}"))),
            }
        }
    }

    /// A `<value>`'s contents, its start already read.
    fn value(&mut self, depth: usize) -> Result<Value, XmlRpcError> {
        if depth > MAX_DEPTH {
            return Err(malformed(format!("values nested over {MAX_DEPTH} deep")));
        }
        // A value is a typed element, or bare text (a string).
        let mut bare = String::new();
        let tag = loop {
            match self.reader.read_event().map_err(malformed)? {
                Event::Start(s) => break String::from_utf8_lossy(s.name().as_ref()).into_owned(),
                Event::Empty(s) => {
                    let v = match s.name().as_ref() {
                        b"string" => Value::Str(String::new()),
                        b"array" => Value::Array(Vec::new()),
                        b"struct" => Value::Struct(Vec::new()),
                        other => {
                            return Err(malformed(format!("<{}/> is not a value", String::from_utf8_lossy(other))));
                        }
                    };
                    self.expect_close("value")?;
                    return Ok(v);
                }
                Event::Text(t) => bare.push_str(&t.xml_content().map_err(malformed)?),
                Event::End(e) if e.name().as_ref() == b"value" => return Ok(Value::Str(bare)),
                e => return Err(malformed(format!("expected a value, found {e:?}"))),
            }
        };
        let v = match tag.as_str() {
            "i4" | "int" | "i8" => {
                let t = self.text(&tag)?;
                Value::Int(t.trim().parse().map_err(|_| malformed(format!("{t:?} is not an int")))?)
            }
            "boolean" => Value::Bool(self.text(&tag)?.trim() == "1"),
            "double" => {
                let t = self.text(&tag)?;
                Value::Double(t.trim().parse().map_err(|_| malformed(format!("{t:?} is not a double")))?)
            }
            "string" | "dateTime.iso8601" | "base64" => Value::Str(self.text(&tag)?),
            "array" => {
                self.expect_open("data")?;
                let mut items = Vec::new();
                loop {
                    match self.next()? {
                        Event::Start(s) if s.name().as_ref() == b"value" => items.push(self.value(depth + 1)?),
                        Event::End(e) if e.name().as_ref() == b"data" => break,
                        e => return Err(malformed(format!("expected a value in an array, found {e:?}"))),
                    }
                }
                self.expect_close("array")?;
                Value::Array(items)
            }
            "struct" => {
                let mut members = Vec::new();
                loop {
                    match self.next()? {
                        Event::Start(s) if s.name().as_ref() == b"member" => {
                            self.expect_open("name")?;
                            let name = self.text("name")?;
                            self.expect_open("value")?;
                            members.push((name, self.value(depth + 1)?));
                            self.expect_close("member")?;
                        }
                        Event::End(e) if e.name().as_ref() == b"struct" => break,
                        e => return Err(malformed(format!("expected a member, found {e:?}"))),
                    }
                }
                Value::Struct(members)
            }
            other => return Err(malformed(format!("<{other}> is not a value type"))),
        };
        self.expect_close("value")?;
        Ok(v)
    }

    /// `<params>`' values, its start already read.
    fn params(&mut self) -> Result<Vec<Value>, XmlRpcError> {
        let mut params = Vec::new();
        loop {
            match self.next()? {
                Event::Start(s) if s.name().as_ref() == b"param" => {
                    self.expect_open("value")?;
                    params.push(self.value(0)?);
                    self.expect_close("param")?;
                }
                Event::End(e) if e.name().as_ref() == b"params" => return Ok(params),
                Event::Empty(e) if e.name().as_ref() == b"params" => return Ok(params),
                e => return Err(malformed(format!("expected a param, found {e:?}"))),
            }
        }
    }
}

/// A call's method name and parameters.
pub fn parse_call(xml: &[u8]) -> Result<(String, Vec<Value>), XmlRpcError> {
    let mut p = Parser::new(xml);
    p.expect_open("methodCall")?;
    p.expect_open("methodName")?;
    let method = p.text("methodName")?;
    let params = match p.next()? {
        Event::Start(s) if s.name().as_ref() == b"params" => p.params()?,
        Event::Empty(s) if s.name().as_ref() == b"params" => Vec::new(),
        Event::End(e) if e.name().as_ref() == b"methodCall" => Vec::new(),
        e => return Err(malformed(format!("expected <params>, found {e:?}"))),
    };
    Ok((method.trim().to_string(), params))
}

/// A response's value, or its fault as an error.
pub fn parse_response(xml: &[u8]) -> Result<Value, XmlRpcError> {
    let mut p = Parser::new(xml);
    p.expect_open("methodResponse")?;
    match p.open()?.as_str() {
        "params" => p.params()?.into_iter().next().ok_or_else(|| malformed("a response with no value")),
        "fault" => {
            p.expect_open("value")?;
            let fault = p.value(0)?;
            let member = |name: &str| match &fault {
                Value::Struct(m) => m.iter().find(|(n, _)| n == name).map(|(_, v)| v.clone()),
                _ => None,
            };
            Err(XmlRpcError::Fault {
                code: member("faultCode").and_then(|v| v.as_int()).unwrap_or(0),
                message: member("faultString").and_then(|v| v.as_str().map(String::from)).unwrap_or_default(),
            })
        }
        other => Err(malformed(format!("<{other}> in a response"))),
    }
}

/// `http://host:port/...` as (host, port).
pub fn host_port(uri: &str) -> Result<(String, u16), XmlRpcError> {
    let rest =
        uri.strip_prefix("http://").ok_or_else(|| XmlRpcError::Http(format!("{uri:?} is not an http:// URI")))?;
    let authority = rest.split('/').next().unwrap_or("");
    let (host, port) = authority.rsplit_once(':').ok_or_else(|| XmlRpcError::Http(format!("{uri:?} names no port")))?;
    let port = port.parse().map_err(|_| XmlRpcError::Http(format!("{uri:?}: {port:?} is not a port")))?;
    Ok((host.to_string(), port))
}

/// Calls `method` at `uri` and returns its value; a fault is an error.
pub async fn call(uri: &str, method: &str, params: &[Value]) -> Result<Value, XmlRpcError> {
    let body = call_body(method, params);
    tokio::time::timeout(TIMEOUT, async {
        let (host, port) = host_port(uri)?;
        let mut stream = TcpStream::connect((host.as_str(), port)).await?;
        stream.set_nodelay(true)?;
        let request = format!(
            "POST /RPC2 HTTP/1.1\r\nHost: {host}:{port}\r\nUser-Agent: polymap\r\nContent-Type: text/xml\r\nContent-Length: {}\r\nConnection: close\r\n\r\n{body}",
            body.len()
        );
        stream.write_all(request.as_bytes()).await?;
        let (head, body, _) = read_message(&mut stream, Side::Response).await?;
        if head != 200 {
            return Err(XmlRpcError::Http(format!("{uri} answered {method} with status {head}")));
        }
        parse_response(&body)
    })
    .await
    .map_err(|_| XmlRpcError::Timeout)?
}

#[derive(Clone, Copy, PartialEq)]
enum Side {
    Request,
    Response,
}

/// Requests larger than this count against [`LARGE_BODIES`], bytes.
const LARGE_BODY_BYTES: usize = 64 * 1024;
/// KiB of large request bodies read at once, all peers together: a crowd of megabyte bodies
/// holds this much, not a megabyte each (the master's calls are a few KiB and never wait).
static LARGE_BODIES: tokio::sync::Semaphore = tokio::sync::Semaphore::const_new(4 * 1024);

/// An HTTP message's status (0 for a request), its body, both bounded, and a large request's
/// share of [`LARGE_BODIES`], held while it is answered.
async fn read_message(
    stream: &mut TcpStream,
    side: Side,
) -> Result<(u16, Vec<u8>, Option<tokio::sync::SemaphorePermit<'static>>), XmlRpcError> {
    let mut buf = Vec::with_capacity(1024);
    let mut chunk = [0u8; 4096];
    let (status, content_length, head_len) = loop {
        let n = stream.read(&mut chunk).await?;
        if n == 0 {
            return Err(XmlRpcError::Http(format!("the connection closed after {} bytes of the head", buf.len())));
        }
        buf.extend_from_slice(&chunk[..n]);
        let mut headers = [httparse::EMPTY_HEADER; 32];
        let http = |e: httparse::Error| XmlRpcError::Http(e.to_string());
        let parsed = match side {
            Side::Request => {
                let mut r = httparse::Request::new(&mut headers);
                match r.parse(&buf).map_err(http)? {
                    httparse::Status::Complete(len) => Some((0, len, content_length_of(r.headers))),
                    httparse::Status::Partial => None,
                }
            }
            Side::Response => {
                let mut r = httparse::Response::new(&mut headers);
                match r.parse(&buf).map_err(http)? {
                    httparse::Status::Complete(len) => Some((r.code.unwrap_or(0), len, content_length_of(r.headers))),
                    httparse::Status::Partial => None,
                }
            }
        };
        match parsed {
            Some((status, len, content_length)) => break (status, content_length?, len),
            None if buf.len() > MAX_HEAD_BYTES => {
                return Err(XmlRpcError::Http(format!("a head over {MAX_HEAD_BYTES} bytes")));
            }
            None => {}
        }
    };
    let mut body = buf.split_off(head_len);
    let share = match (side, content_length) {
        (Side::Request, Some(n)) if n > LARGE_BODY_BYTES && n <= MAX_BODY_BYTES => {
            let kib = n.div_ceil(1024) as u32;
            let share = LARGE_BODIES.try_acquire_many(kib).map_err(|_| {
                XmlRpcError::Http(format!("a body of {n} bytes while 4 MiB of large bodies are being read"))
            })?;
            // Its share is granted: read it into one buffer of its size, not a doubling one.
            body.reserve_exact(n.saturating_sub(body.len()));
            Some(share)
        }
        _ => None,
    };
    super::note_read(content_length.unwrap_or(MAX_BODY_BYTES));
    read_body(stream, &mut body, content_length, side).await.map(|()| (status, body, share))
}

/// The rest of a message's body after its head, `body` what of it came with the head.
async fn read_body(
    stream: &mut TcpStream,
    body: &mut Vec<u8>,
    content_length: Option<usize>,
    side: Side,
) -> Result<(), XmlRpcError> {
    match content_length {
        Some(n) if n > MAX_BODY_BYTES => Err(XmlRpcError::Http(format!("a body of {n} bytes, over {MAX_BODY_BYTES}"))),
        Some(n) => {
            if body.len() < n {
                stream.take((n - body.len()) as u64).read_to_end(body).await?;
            }
            if body.len() < n {
                return Err(XmlRpcError::Http(format!("the body ends after {} of {n} bytes", body.len())));
            }
            body.truncate(n);
            Ok(())
        }
        // A response without a length runs to the connection's end; a request must say.
        None if side == Side::Response => {
            stream.take((MAX_BODY_BYTES + 1 - body.len().min(MAX_BODY_BYTES)) as u64).read_to_end(body).await?;
            match body.len() > MAX_BODY_BYTES {
                true => Err(XmlRpcError::Http(format!("a body over {MAX_BODY_BYTES} bytes"))),
                false => Ok(()),
            }
        }
        None => Err(XmlRpcError::Http("a request without Content-Length".into())),
    }
}

fn content_length_of(headers: &[httparse::Header]) -> Result<Option<usize>, XmlRpcError> {
    match headers.iter().find(|h| h.name.eq_ignore_ascii_case("content-length")) {
        None => Ok(None),
        Some(h) => std::str::from_utf8(h.value)
            .ok()
            .and_then(|v| v.trim().parse().ok())
            .map(Some)
            .ok_or_else(|| XmlRpcError::Http(format!("Content-Length {:?}", String::from_utf8_lossy(h.value)))),
    }
}

/// Reads one request from `stream`, answers it with what `handle` makes of it (a method
/// name and parameters to a value, or a fault), and closes.
pub async fn serve_one(
    mut stream: TcpStream,
    handle: impl FnOnce(&str, &[Value]) -> Result<Value, String>,
) -> Result<(), XmlRpcError> {
    let (_, body, _share) = tokio::time::timeout(TIMEOUT, read_message(&mut stream, Side::Request))
        .await
        .map_err(|_| XmlRpcError::Timeout)??;
    let (answer, result) = match parse_call(&body) {
        Ok((method, params)) => match handle(&method, &params) {
            Ok(v) => (response_body(&v), Ok(())),
            Err(why) => (fault_body(1, &why), Ok(())),
        },
        Err(e) => (fault_body(-32700, &e.to_string()), Err(e)),
    };
    let response = format!(
        "HTTP/1.1 200 OK\r\nServer: polymap\r\nContent-Type: text/xml\r\nContent-Length: {}\r\nConnection: close\r\n\r\n{answer}",
        answer.len()
    );
    tokio::time::timeout(TIMEOUT, stream.write_all(response.as_bytes())).await.map_err(|_| XmlRpcError::Timeout)??;
    result
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_call_reads_back_as_written() {
        let params = vec![
            Value::from("/polymap"),
            Value::Array(vec![Value::Array(vec!["TCPROS".into()]), Value::Int(-3), Value::Bool(true)]),
            Value::Struct(vec![("a".into(), Value::Double(0.5)), ("b".into(), "x<&>y".into())]),
        ];
        let (method, back) = parse_call(call_body("requestTopic", &params).as_bytes()).unwrap();
        assert_eq!((method.as_str(), back), ("requestTopic", params));
    }

    /// Python's xmlrpc.client writes whitespace between elements and bare strings.
    #[test]
    fn pythons_layout_parses() {
        let xml = b"<?xml version='1.0'?>\n<methodResponse>\n<params>\n<param>\n<value><array><data>\n<value><int>1</int></value>\n<value><string></string></value>\n<value>bare text</value>\n<value><array><data>\n</data></array></value>\n</data></array></value>\n</param>\n</params>\n</methodResponse>\n";
        let v = parse_response(xml).unwrap();
        assert_eq!(v, Value::Array(vec![Value::Int(1), "".into(), "bare text".into(), Value::Array(vec![])]));
    }

    #[test]
    fn faults_and_garbage_are_errors() {
        match parse_response(fault_body(-1, "no such topic").as_bytes()) {
            Err(XmlRpcError::Fault { code: -1, message }) => assert_eq!(message, "no such topic"),
            other => panic!("{other:?}"),
        }
        assert!(parse_call(b"<methodCall><methodName>x</methodName><params><param><value><i4>nine").is_err());
        assert!(parse_call(b"\x00\xff garbage").is_err());
        let deep = format!(
            "<methodCall><methodName>x</methodName><params><param><value>{}</value></param></params></methodCall>",
            "<array><data><value>".repeat(100)
        );
        assert!(matches!(parse_call(deep.as_bytes()), Err(XmlRpcError::Malformed(m)) if m.contains("nested")));
    }

    #[test]
    fn uris_split_into_host_and_port() {
        assert_eq!(host_port("http://robot:11311/").unwrap(), ("robot".to_string(), 11311));
        assert!(host_port("rosrpc://robot:1").is_err());
        assert!(host_port("http://robot/").is_err());
    }
}
