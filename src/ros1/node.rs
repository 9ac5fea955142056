//! A ROS 1 node: registered with the rosmaster over XML-RPC, serving its slave API, and
//! talking TCPROS to its peers on one port for every topic and service (as roscpp does).
//!
//! Each peer connection is a task of its own with its own limits: a silent or broken peer
//! holds only its task, and a slow subscriber loses messages from its own queue (the
//! topic's depth) without holding up the others. Whatever a peer gets wrong (a header that
//! does not parse or arrive, a frame over its limit, an XML-RPC body that is not a call) is
//! refused, logged and counted in [`Node::refused`].

use std::collections::HashMap;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Duration;

use parking_lot::Mutex;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::mpsc;
use tokio::task::AbortHandle;

use super::tcpros::{self, ConnectionHeader, TcprosError};
use super::types::{Ros1Message, Ros1Service, TypeInfo};
use super::xmlrpc::{self, Value};
use super::{NodeOptions, Ros1Error};
use crate::ros2::cdr::CdrError;
use crate::ros2::{Service, Topic};

type Frame = Arc<Vec<u8>>;

/// What a subscription does with a message's bytes.
type OnBytes = Arc<dyn Fn(&[u8]) + Send + Sync>;

/// A handler of a service's request bytes: the response's bytes, or why not.
type RawHandler = Arc<dyn Fn(&[u8]) -> Result<Vec<u8>, String> + Send + Sync>;

pub struct Node {
    inner: Arc<Inner>,
    tasks: Mutex<Vec<AbortHandle>>,
}

struct Inner {
    opts: NodeOptions,
    /// `http://host:port/`: where the master and peers call this node.
    caller_api: String,
    tcpros_port: u16,
    publications: Mutex<HashMap<String, Arc<Publication>>>,
    subscriptions: Mutex<HashMap<String, Arc<Subscribed>>>,
    services: Mutex<HashMap<String, ServiceEntry>>,
    refused: AtomicU64,
    shut_down: AtomicBool,
    next_connection: AtomicU64,
    /// Permits for peer connections open at once: XML-RPC calls and TCPROS connections
    /// apart, so a crowd on one side does not lock the master out of the other.
    xmlrpc_peers: Arc<tokio::sync::Semaphore>,
    tcpros_peers: Arc<tokio::sync::Semaphore>,
}

struct Publication {
    topic: String,
    info: TypeInfo,
    latch: bool,
    /// Messages a subscriber's queue holds before it loses the oldest new ones.
    depth: usize,
    last: Mutex<Option<Frame>>,
    links: Mutex<Vec<Link>>,
}

/// One subscriber's connection to a publication.
struct Link {
    id: u64,
    subscriber: String,
    queue: mpsc::Sender<Frame>,
}

struct Subscribed {
    topic: String,
    info: TypeInfo,
    /// Largest message taken on this topic, bytes.
    limit: usize,
    on: OnBytes,
    /// Publishers connected (or connecting), by their XML-RPC URI.
    publishers: Mutex<HashMap<String, AbortHandle>>,
    /// The TCPROS endpoints (host, port) streaming to it now: one connection each, however
    /// many URIs name it.
    endpoints: Mutex<std::collections::HashSet<(String, u16)>>,
}

#[derive(Clone)]
struct ServiceEntry {
    info: TypeInfo,
    request_type: String,
    response_type: String,
    handle: RawHandler,
}

impl Node {
    /// Starts the node's XML-RPC and TCPROS servers once the master answers (waiting for it,
    /// as roscpp nodes do); registers nothing yet.
    pub async fn new(opts: NodeOptions) -> Result<Node, Ros1Error> {
        let bind = if opts.host_is_loopback() { "127.0.0.1" } else { "0.0.0.0" };
        let xmlrpc_listener = TcpListener::bind((bind, 0)).await?;
        let tcpros_listener = TcpListener::bind((bind, 0)).await?;
        let caller_api = format!("http://{}:{}/", opts.host, xmlrpc_listener.local_addr()?.port());
        let inner = Arc::new(Inner {
            caller_api,
            tcpros_port: tcpros_listener.local_addr()?.port(),
            opts,
            publications: Mutex::default(),
            subscriptions: Mutex::default(),
            services: Mutex::default(),
            refused: AtomicU64::new(0),
            shut_down: AtomicBool::new(false),
            next_connection: AtomicU64::new(1),
            xmlrpc_peers: Arc::new(tokio::sync::Semaphore::new(MAX_XMLRPC_PEERS)),
            tcpros_peers: Arc::new(tokio::sync::Semaphore::new(MAX_TCPROS_PEERS)),
        });
        // As roscpp does: wait for the master (a robot's services start in any order).
        let mut waited = 0u64;
        while let Err(e) = inner.master("getPid", vec![inner.opts.name.as_str().into()]).await {
            if waited.is_multiple_of(10) {
                tracing::warn!("waiting for the ROS 1 master (is roscore running?): {e}");
            }
            waited += 1;
            tokio::time::sleep(Duration::from_millis(500)).await;
        }
        let tasks = vec![
            tokio::spawn(serve_xmlrpc(inner.clone(), xmlrpc_listener)).abort_handle(),
            tokio::spawn(serve_tcpros(inner.clone(), tcpros_listener)).abort_handle(),
            tokio::spawn(give_back_memory()).abort_handle(),
        ];
        Ok(Node { inner, tasks: Mutex::new(tasks) })
    }

    pub fn name(&self) -> &str {
        &self.inner.opts.name
    }

    pub fn master_uri(&self) -> &str {
        &self.inner.opts.master_uri
    }

    /// Peer connections and calls refused since the start.
    pub fn refused(&self) -> u64 {
        self.inner.refused.load(Ordering::Relaxed)
    }

    /// Whether the master told this node to shut down (another node took its name,
    /// `rosnode kill`).
    pub fn is_shut_down(&self) -> bool {
        self.inner.shut_down.load(Ordering::Relaxed)
    }

    /// Advertises `topic`: latched when its QoS keeps samples for late joiners.
    pub async fn publisher<T: Ros1Message>(&self, topic: &Topic<T>) -> Result<Publisher<T>, Ros1Error> {
        let publication = Arc::new(Publication {
            topic: topic.name.to_string(),
            info: TypeInfo::of::<T>(),
            latch: topic.qos.is_latched(),
            depth: topic.qos.depth().max(1) as usize,
            last: Mutex::default(),
            links: Mutex::default(),
        });
        self.inner.publications.lock().insert(publication.topic.clone(), publication.clone());
        let i = &self.inner;
        i.master(
            "registerPublisher",
            vec![
                i.opts.name.as_str().into(),
                publication.topic.as_str().into(),
                T::TYPE.into(),
                i.caller_api.as_str().into(),
            ],
        )
        .await?;
        Ok(Publisher { publication, _type: std::marker::PhantomData })
    }

    /// Subscribes to `topic`: every message (or why it is not one) reaches `on`, from every
    /// publisher the master names now or later.
    pub async fn subscribe<T: Ros1Message>(
        &self,
        topic: &Topic<T>,
        on: impl Fn(Result<T, CdrError>) + Send + Sync + 'static,
    ) -> Result<(), Ros1Error> {
        let subscribed = Arc::new(Subscribed {
            topic: topic.name.to_string(),
            info: TypeInfo::of::<T>(),
            limit: T::MAX_BYTES,
            on: Arc::new(move |bytes: &[u8]| on(T::from_ros1(bytes))),
            publishers: Mutex::default(),
            endpoints: Mutex::default(),
        });
        self.inner.subscriptions.lock().insert(subscribed.topic.clone(), subscribed.clone());
        let i = &self.inner;
        let publishers = i
            .master(
                "registerSubscriber",
                vec![
                    i.opts.name.as_str().into(),
                    subscribed.topic.as_str().into(),
                    T::TYPE.into(),
                    i.caller_api.as_str().into(),
                ],
            )
            .await?;
        connect_publishers(i, &subscribed, &uris(&publishers));
        Ok(())
    }

    /// Serves `service`: each request (or why it is not one) goes to `handler`, whose error
    /// the caller receives as the service's failure.
    pub async fn serve<S: Ros1Service>(
        &self,
        service: &Service<S>,
        handler: impl Fn(Result<S::Request, CdrError>) -> Result<S::Response, String> + Send + Sync + 'static,
    ) -> Result<(), Ros1Error> {
        let name = service.name.to_string();
        let entry = ServiceEntry {
            info: TypeInfo::of_service::<S>(),
            request_type: <S::Request as Ros1Message>::TYPE.to_string(),
            response_type: <S::Response as Ros1Message>::TYPE.to_string(),
            handle: Arc::new(move |bytes: &[u8]| handler(S::Request::from_ros1(bytes)).map(|r| r.to_ros1())),
        };
        self.inner.services.lock().insert(name.clone(), entry);
        let i = &self.inner;
        let service_api = format!("rosrpc://{}:{}", i.opts.host, i.tcpros_port);
        i.master(
            "registerService",
            vec![
                i.opts.name.as_str().into(),
                name.as_str().into(),
                service_api.as_str().into(),
                i.caller_api.as_str().into(),
            ],
        )
        .await?;
        Ok(())
    }

    /// Unregisters every topic and service from the master (best effort: the master may be
    /// gone) and stops serving.
    pub async fn shutdown(&self) {
        let i = self.inner.clone();
        let caller = || -> Value { i.opts.name.as_str().into() };
        let api = || -> Value { i.caller_api.as_str().into() };
        let publications: Vec<String> = i.publications.lock().keys().cloned().collect();
        let subscriptions: Vec<String> = i.subscriptions.lock().keys().cloned().collect();
        let services: Vec<String> = i.services.lock().keys().cloned().collect();
        for topic in publications {
            let _ = i.master("unregisterPublisher", vec![caller(), topic.as_str().into(), api()]).await;
        }
        for topic in subscriptions {
            let _ = i.master("unregisterSubscriber", vec![caller(), topic.as_str().into(), api()]).await;
        }
        let service_api = format!("rosrpc://{}:{}", i.opts.host, i.tcpros_port);
        for name in services {
            let _ =
                i.master("unregisterService", vec![caller(), name.as_str().into(), service_api.as_str().into()]).await;
        }
        self.stop();
    }

    fn stop(&self) {
        self.tasks.lock().drain(..).for_each(|t| t.abort());
        for s in self.inner.subscriptions.lock().values() {
            s.publishers.lock().drain().for_each(|(_, t)| t.abort());
        }
    }
}

impl Drop for Node {
    fn drop(&mut self) {
        self.stop();
    }
}

/// A topic's publisher.
pub struct Publisher<T> {
    publication: Arc<Publication>,
    _type: std::marker::PhantomData<fn(&T)>,
}

impl<T: Ros1Message> Publisher<T> {
    /// Queues `msg` for every subscriber (a full queue loses this message for that one).
    pub fn put(&self, msg: &T) {
        let frame: Frame = Arc::new(tcpros::framed(&msg.to_ros1()));
        let p = &self.publication;
        if p.latch {
            *p.last.lock() = Some(frame.clone());
        }
        p.links
            .lock()
            .retain(|link| !matches!(link.queue.try_send(frame.clone()), Err(mpsc::error::TrySendError::Closed(_))));
    }

    /// How many subscribers are connected.
    pub fn subscribers(&self) -> usize {
        self.publication.links.lock().len()
    }
}

impl Inner {
    /// Calls the master; its answer's value when its status code is 1.
    async fn master(&self, method: &str, params: Vec<Value>) -> Result<Value, Ros1Error> {
        let answer = xmlrpc::call(&self.opts.master_uri, method, &params)
            .await
            .map_err(|e| Ros1Error::Master { uri: self.opts.master_uri.clone(), why: format!("{method}: {e}") })?;
        match answer.as_array() {
            Some([code, message, value]) if code.as_int() == Some(1) => {
                let _ = message;
                Ok(value.clone())
            }
            Some([_, message, _]) => Err(Ros1Error::Master {
                uri: self.opts.master_uri.clone(),
                why: format!("{method}: {}", message.as_str().unwrap_or("refused")),
            }),
            _ => Err(Ros1Error::Master {
                uri: self.opts.master_uri.clone(),
                why: format!("{method}: not a [code, message, value] answer: {answer:?}"),
            }),
        }
    }

    fn refuse(&self, what: &str, why: &dyn std::fmt::Display) {
        let n = self.refused.fetch_add(1, Ordering::Relaxed) + 1;
        if n <= 10 || n.is_multiple_of(1000) {
            tracing::warn!("ROS 1: {what} refused ({n} so far): {why}");
        }
    }

    /// The slave API: what the master and peers ask of this node.
    fn slave(self: &Arc<Self>, method: &str, params: &[Value]) -> Result<Value, String> {
        let ok = |v: Value| Ok(Value::Array(vec![Value::Int(1), "".into(), v]));
        let fail = |why: String| Ok(Value::Array(vec![Value::Int(-1), why.as_str().into(), Value::Int(0)]));
        let string = |i: usize| params.get(i).and_then(Value::as_str).map(str::to_string);
        match method {
            "getPid" => ok(Value::Int(std::process::id() as i32)),
            "getMasterUri" => ok(self.opts.master_uri.as_str().into()),
            "getBusStats" => ok(Value::Array(vec![Value::Array(vec![]); 3])),
            "getBusInfo" => ok(Value::Array(self.bus_info())),
            "getPublications" => {
                ok(Value::Array(self.publications.lock().values().map(|p| pair(&p.topic, p.info.name)).collect()))
            }
            "getSubscriptions" => {
                ok(Value::Array(self.subscriptions.lock().values().map(|s| pair(&s.topic, s.info.name)).collect()))
            }
            "paramUpdate" => ok(Value::Int(0)),
            "shutdown" => {
                self.shut_down.store(true, Ordering::Relaxed);
                tracing::error!(
                    "ROS 1: the master shut this node down ({}); topics stay unregistered",
                    string(1).unwrap_or_default()
                );
                ok(Value::Int(0))
            }
            "requestTopic" => {
                let Some(topic) = string(1) else { return fail("requestTopic(caller_id, topic, protocols)".into()) };
                let tcpros = params.get(2).and_then(Value::as_array).is_some_and(|protocols| {
                    protocols
                        .iter()
                        .any(|p| p.as_array().and_then(|p| p.first()).and_then(Value::as_str) == Some("TCPROS"))
                });
                match (self.publications.lock().contains_key(&topic), tcpros) {
                    (true, true) => ok(Value::Array(vec![
                        "TCPROS".into(),
                        self.opts.host.as_str().into(),
                        Value::Int(i32::from(self.tcpros_port)),
                    ])),
                    (false, _) => fail(format!("{} does not publish {topic}", self.opts.name)),
                    (true, false) => fail("only TCPROS is offered".into()),
                }
            }
            "publisherUpdate" => {
                let (Some(topic), Some(list)) = (string(1), params.get(2)) else {
                    return fail("publisherUpdate(caller_id, topic, publishers)".into());
                };
                let subscribed = self.subscriptions.lock().get(&topic).cloned();
                if let Some(s) = subscribed {
                    let now = uris(list);
                    s.publishers.lock().retain(|uri, task| {
                        let keep = now.contains(uri);
                        if !keep {
                            task.abort();
                        }
                        keep
                    });
                    connect_publishers(self, &s, &now);
                }
                ok(Value::Int(0))
            }
            other => Err(format!("{other} is not a method of the ROS 1 slave API")),
        }
    }

    fn bus_info(&self) -> Vec<Value> {
        let mut out = Vec::new();
        for p in self.publications.lock().values() {
            for link in p.links.lock().iter() {
                out.push(Value::Array(vec![
                    Value::Int(link.id as i32),
                    link.subscriber.as_str().into(),
                    "o".into(),
                    "TCPROS".into(),
                    p.topic.as_str().into(),
                    Value::Bool(true),
                ]));
            }
        }
        for s in self.subscriptions.lock().values() {
            for (i, uri) in s.publishers.lock().keys().enumerate() {
                out.push(Value::Array(vec![
                    Value::Int(i as i32),
                    uri.as_str().into(),
                    "i".into(),
                    "TCPROS".into(),
                    s.topic.as_str().into(),
                    Value::Bool(true),
                ]));
            }
        }
        out
    }
}

fn pair(topic: &str, ty: &str) -> Value {
    Value::Array(vec![topic.into(), ty.into()])
}

/// The strings of an XML-RPC array (the master's lists of URIs).
fn uris(v: &Value) -> Vec<String> {
    v.as_array().unwrap_or(&[]).iter().filter_map(|u| u.as_str().map(str::to_string)).collect()
}

/// Publishers one topic takes from at once: a robot has one or two of each (VINS, a bag
/// being played), and each is a task that retries while the master lists it.
pub const MAX_PUBLISHERS_PER_TOPIC: usize = 16;

fn connect_publishers(inner: &Arc<Inner>, s: &Arc<Subscribed>, publishers: &[String]) {
    let mut connected = s.publishers.lock();
    let mut over = 0;
    for uri in publishers {
        if connected.contains_key(uri) {
            continue;
        }
        if connected.len() == MAX_PUBLISHERS_PER_TOPIC {
            over += 1;
            continue;
        }
        let task = tokio::spawn(take_from(inner.clone(), s.clone(), uri.clone()));
        connected.insert(uri.clone(), task.abort_handle());
    }
    if over > 0 {
        let why = format!("{over} more publishers of {} than the {MAX_PUBLISHERS_PER_TOPIC} taken", s.topic);
        inner.refuse("a publisher list", &why);
    }
}

/// Subscribes to one publisher of `s`'s topic for as long as the master lists it (a
/// publisherUpdate without it aborts this task): a connection that fails or breaks off is
/// made again, after 1 s doubling to 8 s, as roscpp does.
async fn take_from(inner: Arc<Inner>, s: Arc<Subscribed>, uri: String) {
    let mut backoff = Duration::from_secs(1);
    loop {
        let mut received = 0u64;
        let ended = stream_from(&inner, &s, &uri, &mut received).await;
        match &ended {
            // Said once a publisher that sent something goes; its retries are quiet.
            Err(Ros1Error::Tcpros(TcprosError::Io(_)) | Ros1Error::XmlRpc(_) | Ros1Error::Io(_)) if received > 0 => {
                tracing::info!("ROS 1: {uri} stopped sending {} ({ended:?}); trying again", s.topic)
            }
            Err(Ros1Error::Tcpros(TcprosError::Io(_)) | Ros1Error::XmlRpc(_) | Ros1Error::Io(_)) => {
                tracing::debug!("ROS 1: {uri} does not send {} ({ended:?}); trying again", s.topic)
            }
            Err(e) => inner.refuse(&format!("the publisher {uri} of {}", s.topic), e),
            Ok(()) => {}
        }
        if received > 0 {
            backoff = Duration::from_secs(1);
        }
        tokio::time::sleep(backoff).await;
        backoff = (backoff * 2).min(Duration::from_secs(8));
    }
}

/// One connection to a publisher: the handshake, then each message to the subscription
/// until the connection ends.
async fn stream_from(inner: &Inner, s: &Subscribed, uri: &str, received: &mut u64) -> Result<(), Ros1Error> {
    let answer = xmlrpc::call(
        uri,
        "requestTopic",
        &[
            inner.opts.name.as_str().into(),
            s.topic.as_str().into(),
            Value::Array(vec![Value::Array(vec!["TCPROS".into()])]),
        ],
    )
    .await?;
    let (host, port) = match answer.as_array() {
        Some([code, _, Value::Array(p)]) if code.as_int() == Some(1) => match p.as_slice() {
            [proto, host, port] if proto.as_str() == Some("TCPROS") => {
                (host.as_str().unwrap_or_default().to_string(), port.as_int().unwrap_or_default())
            }
            _ => return Err(Ros1Error::Peer(format!("{uri} offers no TCPROS for {}", s.topic))),
        },
        _ => return Err(Ros1Error::Peer(format!("{uri} answered requestTopic with {answer:?}"))),
    };
    let port = u16::try_from(port).map_err(|_| Ros1Error::Peer(format!("{uri}: port {port}")))?;
    let _endpoint = Endpoint::claim(s, (host.clone(), port))
        .ok_or_else(|| Ros1Error::Peer(format!("{uri} names {host}:{port}, which already sends {}", s.topic)))?;
    let mut stream = TcpStream::connect((host.as_str(), port)).await?;
    stream.set_nodelay(true)?;
    let header = ConnectionHeader::new(&[
        ("callerid", &inner.opts.name),
        ("topic", &s.topic),
        ("md5sum", &s.info.md5),
        ("type", s.info.name),
        ("message_definition", &s.info.definition),
        ("tcp_nodelay", "1"),
    ]);
    tcpros::write_header(&mut stream, &header).await?;
    let theirs = tcpros::read_header(&mut stream).await?;
    if let Some(error) = theirs.get("error") {
        return Err(TcprosError::Refused(error.to_string()).into());
    }
    loop {
        let frame = tcpros::read_frame(&mut stream, "a message", s.limit, None).await?;
        *received += 1;
        (s.on)(&frame);
    }
}

/// A subscription's claim on one TCPROS endpoint, given up when dropped.
struct Endpoint<'a> {
    s: &'a Subscribed,
    key: (String, u16),
}

impl<'a> Endpoint<'a> {
    fn claim(s: &'a Subscribed, key: (String, u16)) -> Option<Endpoint<'a>> {
        // Lazily: an Endpoint made and dropped for a taken key would give that key up.
        let fresh = s.endpoints.lock().insert(key.clone());
        fresh.then(|| Endpoint { s, key })
    }
}

impl Drop for Endpoint<'_> {
    fn drop(&mut self) {
        self.s.endpoints.lock().remove(&self.key);
    }
}

/// XML-RPC calls served at once (each has [`xmlrpc::TIMEOUT`] to arrive and be answered);
/// one more is closed at once and counted.
pub const MAX_XMLRPC_PEERS: usize = 64;
/// TCPROS connections served at once (subscribers of polymap's topics, service callers).
pub const MAX_TCPROS_PEERS: usize = 512;
/// A service request's largest size, bytes: polymap's are a point or nothing.
pub const MAX_REQUEST_BYTES: usize = 64 * 1024;
/// How long a persistent service connection may wait between calls.
pub const PERSISTENT_IDLE: Duration = Duration::from_secs(60);

/// Accepts `listener`'s connections, each served by `serve` on a task of its own while
/// `peers` has permits left.
async fn accept<F, Fut>(
    inner: Arc<Inner>,
    listener: TcpListener,
    peers: Arc<tokio::sync::Semaphore>,
    what: &'static str,
    serve: F,
) where
    F: Fn(Arc<Inner>, TcpStream, std::net::SocketAddr) -> Fut,
    Fut: std::future::Future<Output = ()> + Send + 'static,
{
    loop {
        let (stream, peer) = match listener.accept().await {
            Ok(accepted) => accepted,
            // Out of file descriptors, most likely: wait rather than spin.
            Err(e) => {
                tracing::warn!("ROS 1: accepting {what}: {e}");
                tokio::time::sleep(Duration::from_millis(100)).await;
                continue;
            }
        };
        match peers.clone().try_acquire_owned() {
            Ok(permit) => {
                let served = serve(inner.clone(), stream, peer);
                tokio::spawn(async move {
                    served.await;
                    drop(permit);
                });
            }
            Err(_) => inner.refuse(&format!("{what} from {peer}"), &"too many at once"),
        }
    }
}

async fn serve_xmlrpc(inner: Arc<Inner>, listener: TcpListener) {
    let peers = inner.xmlrpc_peers.clone();
    accept(inner, listener, peers, "an XML-RPC call", |inner, stream, _| async move {
        if let Err(e) = xmlrpc::serve_one(stream, |method, params| inner.slave(method, params)).await {
            inner.refuse("an XML-RPC call", &e);
        }
    })
    .await
}

async fn serve_tcpros(inner: Arc<Inner>, listener: TcpListener) {
    let peers = inner.tcpros_peers.clone();
    accept(inner, listener, peers, "a TCPROS connection", |inner, stream, peer| async move {
        if let Err(e) = connection(&inner, stream).await {
            inner.refuse(&format!("a TCPROS connection from {peer}"), &e);
        }
    })
    .await
}

/// One peer's TCPROS connection: a subscriber of a topic or a caller of a service.
async fn connection(inner: &Arc<Inner>, mut stream: TcpStream) -> Result<(), Ros1Error> {
    stream.set_nodelay(true)?;
    let header = tcpros::read_header(&mut stream).await?;
    if let Some(topic) = header.get("topic") {
        let Some(p) = inner.publications.lock().get(topic).cloned() else {
            return refuse(&mut stream, format!("{} does not publish {topic}", inner.opts.name)).await;
        };
        let md5 = header.require("md5sum")?;
        if md5 != "*" && md5 != p.info.md5 {
            return refuse(&mut stream, format!("{topic} is {} ({}), not md5 {md5}", p.info.name, p.info.md5)).await;
        }
        let latching = if p.latch { "1" } else { "0" };
        let ours = ConnectionHeader::new(&[
            ("callerid", &inner.opts.name),
            ("topic", &p.topic),
            ("md5sum", &p.info.md5),
            ("type", p.info.name),
            ("message_definition", &p.info.definition),
            ("latching", latching),
        ]);
        tcpros::write_header(&mut stream, &ours).await?;
        let subscriber = header.get("callerid").unwrap_or("?").to_string();
        feed(inner, p, stream, subscriber).await;
        Ok(())
    } else if let Some(name) = header.get("service") {
        let Some(s) = inner.services.lock().get(name).cloned() else {
            return refuse(&mut stream, format!("{} does not serve {name}", inner.opts.name)).await;
        };
        let md5 = header.get("md5sum").unwrap_or("*");
        if md5 != "*" && md5 != s.info.md5 {
            return refuse(&mut stream, format!("{name} is {} ({}), not md5 {md5}", s.info.name, s.info.md5)).await;
        }
        let ours = ConnectionHeader::new(&[
            ("callerid", &inner.opts.name),
            ("md5sum", &s.info.md5),
            ("type", s.info.name),
            ("request_type", &s.request_type),
            ("response_type", &s.response_type),
        ]);
        tcpros::write_header(&mut stream, &ours).await?;
        if header.get("probe") == Some("1") {
            return Ok(());
        }
        let persistent = header.get("persistent") == Some("1");
        let mut wait = tcpros::HANDSHAKE_TIMEOUT;
        loop {
            let request =
                match tcpros::read_frame(&mut stream, "a service request", MAX_REQUEST_BYTES, Some(wait)).await {
                    Err(TcprosError::Io(e)) if e.kind() == std::io::ErrorKind::UnexpectedEof => return Ok(()),
                    r => r?,
                };
            let handle = s.handle.clone();
            let answer = tokio::task::spawn_blocking(move || handle(&request))
                .await
                .unwrap_or_else(|e| Err(format!("the service's handler failed: {e}")));
            let reply = match answer {
                Ok(bytes) => [vec![1], tcpros::framed(&bytes)].concat(),
                Err(why) => [vec![0], tcpros::framed(why.as_bytes())].concat(),
            };
            stream.write_all(&reply).await?;
            if !persistent {
                return Ok(());
            }
            wait = PERSISTENT_IDLE;
        }
    } else {
        refuse(&mut stream, "a connection header names neither a topic nor a service".into()).await
    }
}

/// Tells the peer why not (TCPROS's `error` header), and closes.
async fn refuse(stream: &mut TcpStream, why: String) -> Result<(), Ros1Error> {
    let _ = tcpros::write_header(stream, &ConnectionHeader::new(&[("error", &why)])).await;
    Err(Ros1Error::Peer(why))
}

/// Sends a publication's messages to one subscriber until it goes.
async fn feed(inner: &Arc<Inner>, p: Arc<Publication>, mut stream: TcpStream, subscriber: String) {
    let (queue, mut frames) = mpsc::channel::<Frame>(p.depth);
    let id = inner.next_connection.fetch_add(1, Ordering::Relaxed);
    // The latched message first; registered under the same lock, so none is missed between.
    let latched = {
        let mut links = p.links.lock();
        links.push(Link { id, subscriber: subscriber.clone(), queue });
        p.last.lock().clone()
    };
    let mut ignored = [0u8; 256];
    let sent: std::io::Result<()> = async {
        if let Some(frame) = latched {
            stream.write_all(&frame).await?;
        }
        loop {
            tokio::select! {
                frame = frames.recv() => match frame {
                    Some(frame) => stream.write_all(&frame).await?,
                    None => return Ok(()),
                },
                // A subscriber sends nothing after its header: this only sees it go.
                read = stream.read(&mut ignored) => if read? == 0 { return Ok(()) },
            }
        }
    }
    .await;
    if let Err(e) = sent {
        tracing::debug!("ROS 1: {subscriber} left {}: {e}", p.topic);
    }
    p.links.lock().retain(|l| l.id != id);
}

/// Gives memory that peers' large messages held back to the system a while after the
/// last of them (the allocator keeps it otherwise: `keep_freed_memory`).
async fn give_back_memory() {
    let mut tick = tokio::time::interval(Duration::from_secs(1));
    let mut due = false;
    loop {
        tick.tick().await;
        let fresh = super::LARGE_READS.swap(false, Ordering::Relaxed);
        if due && !fresh {
            let _ = tokio::task::spawn_blocking(crate::give_back_freed_memory).await;
        }
        due = fresh;
    }
}
