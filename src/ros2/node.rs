//! A ROS 2 node on Zenoh: its publishers, subscriptions, service servers and clients, each
//! on the key and with the liveliness token its wire convention gives it
//! ([`super::graph`]), samples in CDR with rmw_zenoh's attachment where that convention
//! wants one.
//!
//! rmw_zenoh carries every topic with zenoh-ext's advanced publisher and subscriber: a
//! volatile one behaves as a plain Zenoh publisher; a transient-local one keeps its last
//! `depth` samples in a cache that late subscribers query, and a reliable one announces its
//! last sequence number (a sporadic heartbeat) so subscribers notice what they missed.

use std::sync::atomic::{AtomicI64, AtomicU32, Ordering};
use std::time::Duration;

use zenoh::Wait;
use zenoh::bytes::Encoding as ZEncoding;
use zenoh::liveliness::LivelinessToken;
use zenoh::qos::CongestionControl;
use zenoh::query::{ConsolidationMode, QueryTarget};
use zenoh_ext::{
    AdvancedPublisher, AdvancedPublisherBuilderExt, AdvancedSubscriber, AdvancedSubscriberBuilderExt, CacheConfig,
    HistoryConfig, MissDetectionConfig, RecoveryConfig,
};

use super::attachment::{Attachment, Gid, gid_of};
use super::cdr::{self, CdrError};
use super::graph::{self, Endpoint, EntityKind, NodeId};
use super::msg;
use super::qos::{Durability, History, Qos, Reliability};
use super::types::{self, RosMessage, RosService};
use super::{Encoding, Mode, Ros2Error, RosName, Service, Topic};

/// Who the node is and how it speaks.
#[derive(Clone, Debug)]
pub struct NodeOptions {
    pub mode: Mode,
    pub domain: u32,
    /// The node's namespace (`/polymap/leju`, or `/`).
    pub namespace: RosName,
    pub name: String,
    pub encoding: Encoding,
}

/// The QoS rmw_zenoh announces for services (the services default profile).
const SERVICE_QOS: Qos = Qos::reliable(10);

/// rmw_zenoh's heartbeat period for reliable transient-local publishers.
const HEARTBEAT: Duration = Duration::from_millis(500);

pub struct Node {
    session: zenoh::Session,
    opts: NodeOptions,
    zid: String,
    next_id: AtomicU32,
    _token: Option<LivelinessToken>,
}

/// What an entity was declared as: where its data goes and how it is announced.
struct Declared {
    key: String,
    token: Option<LivelinessToken>,
    gid: Gid,
}

fn now_ns() -> i64 {
    crate::clock::now_ns() as i64
}

impl Node {
    pub async fn new(session: &zenoh::Session, opts: NodeOptions) -> Result<Node, Ros2Error> {
        let zid = session.zid().to_string();
        let mut node = Node { session: session.clone(), opts, zid, next_id: AtomicU32::new(0), _token: None };
        if let Mode::RmwZenoh(distro) = node.opts.mode {
            let id = node.next_id.fetch_add(1, Ordering::Relaxed);
            let token = graph::rmw_zenoh_token(distro, &node.id(id), None);
            node._token = Some(node.declare_token(&token).await?);
        }
        Ok(node)
    }

    pub fn options(&self) -> &NodeOptions {
        &self.opts
    }

    pub fn session(&self) -> &zenoh::Session {
        &self.session
    }

    fn id(&self, id: u32) -> NodeId<'_> {
        NodeId { domain: self.opts.domain, zid: &self.zid, id, namespace: &self.opts.namespace, name: &self.opts.name }
    }

    async fn declare_token(&self, key: &str) -> Result<LivelinessToken, Ros2Error> {
        self.session.liveliness().declare_token(key.to_string()).await.map_err(|e| Ros2Error::zenoh(key, e))
    }

    /// The key `endpoint`'s data goes on.
    pub fn data_key(&self, e: &Endpoint) -> String {
        graph::data_key(self.opts.mode, self.opts.domain, e)
    }

    /// Declares an entity's token (the node's ids count up from the node's own).
    async fn declare(&self, kind: EntityKind, e: &Endpoint<'_>, qos: Qos) -> Result<Declared, Ros2Error> {
        let token = match self.opts.mode {
            Mode::RmwZenoh(distro) => {
                let id = self.next_id.fetch_add(1, Ordering::Relaxed);
                graph::rmw_zenoh_token(distro, &self.id(0), Some((id, kind, e, &qos.rmw_zenoh_key())))
            }
            Mode::Bridge => {
                let qos = matches!(kind, EntityKind::Publisher | EntityKind::Subscription)
                    .then(|| qos.bridge_key(Some(e.type_hash)));
                graph::bridge_token(&self.zid, kind, e, qos.as_deref())
            }
        };
        Ok(Declared { key: self.data_key(e), gid: gid_of(&token), token: Some(self.declare_token(&token).await?) })
    }

    fn encoding(&self) -> ZEncoding {
        match self.opts.encoding {
            Encoding::Cdr => ZEncoding::APPLICATION_CDR,
            Encoding::Json => ZEncoding::APPLICATION_JSON,
        }
    }

    /// rmw_zenoh wants an attachment on every sample, query and reply; the bridge none.
    fn attaches(&self) -> bool {
        matches!(self.opts.mode, Mode::RmwZenoh(_))
    }

    pub async fn publisher<T: RosMessage>(&self, topic: &Topic<T>) -> Result<Publisher<T>, Ros2Error> {
        let hash = types::message_hash::<T>();
        let e = Endpoint { name: &topic.name, type_name: T::TYPE_NAME, type_hash: &hash };
        let declared = self.declare(EntityKind::Publisher, &e, topic.qos).await?;
        let q = topic.qos;
        // As rmw_zenoh: samples wait for room only when every one must arrive (reliable,
        // keep all); otherwise a congested link drops them.
        let congestion = match (q.reliability, q.history) {
            (Reliability::Reliable, History::KeepAll) => CongestionControl::Block,
            _ => CongestionControl::Drop,
        };
        let mut builder = self
            .session
            .declare_publisher(declared.key.clone())
            .congestion_control(congestion)
            .encoding(self.encoding())
            .advanced();
        if q.durability == Durability::TransientLocal {
            builder = builder.cache(CacheConfig::default().max_samples(q.depth() as usize)).publisher_detection();
            if q.reliability == Reliability::Reliable {
                builder = builder.sample_miss_detection(MissDetectionConfig::default().sporadic_heartbeat(HEARTBEAT));
            }
        }
        let publisher = builder.await.map_err(|e| Ros2Error::zenoh(&declared.key, e))?;
        Ok(Publisher {
            publisher,
            encoding: self.opts.encoding,
            attach: self.attaches().then_some(declared.gid),
            seq: AtomicI64::new(1),
            key: declared.key,
            _token: declared.token,
            _type: std::marker::PhantomData,
        })
    }

    /// Calls `on` with each message on `topic`, or why it did not decode. With rmw_zenoh the
    /// type hash is not matched (a Humble publisher writes none).
    pub async fn subscribe<T: RosMessage>(
        &self,
        topic: &Topic<T>,
        on: impl Fn(Result<T, CdrError>) + Send + Sync + 'static,
    ) -> Result<Subscription, Ros2Error> {
        let hash = types::message_hash::<T>();
        let e = Endpoint { name: &topic.name, type_name: T::TYPE_NAME, type_hash: &hash };
        let declared = self.declare(EntityKind::Subscription, &e, topic.qos).await?;
        let key = match self.opts.mode {
            Mode::RmwZenoh(_) => format!("{}/*", declared.key.rsplit_once('/').map_or(&*declared.key, |(k, _)| k)),
            Mode::Bridge => declared.key.clone(),
        };
        let q = topic.qos;
        let mut builder = self
            .session
            .declare_subscriber(key.clone())
            .callback(move |sample| on(cdr::from_slice(&sample.payload().to_bytes())))
            .advanced();
        if q.durability == Durability::TransientLocal {
            builder = builder
                .history(HistoryConfig::default().detect_late_publishers().max_samples(q.depth() as usize))
                .query_timeout(Duration::from_secs(10))
                .subscriber_detection();
            if q.reliability == Reliability::Reliable {
                builder = builder.recovery(RecoveryConfig::default().heartbeat());
            }
        }
        let subscriber = builder.await.map_err(|e| Ros2Error::zenoh(&key, e))?;
        Ok(Subscription { _subscriber: subscriber, _token: declared.token })
    }

    /// Serves `service`: `handler` answers each request (or says why it cannot). Requests
    /// that do not decode get an error reply naming what was wrong, and reach `handler` as
    /// the error so it can count them.
    pub async fn serve<S: RosService>(
        &self,
        service: &Service<S>,
        handler: impl Fn(Result<S::Request, CdrError>) -> Result<S::Response, String> + Send + Sync + 'static,
    ) -> Result<ServiceServer, Ros2Error> {
        let hash = msg::service_hash::<S>();
        let e = Endpoint { name: &service.name, type_name: S::TYPE_NAME, type_hash: &hash };
        let declared = self.declare(EntityKind::ServiceServer, &e, SERVICE_QOS).await?;
        let attaches = self.attaches();
        let reply_key = declared.key.clone();
        let queryable = self
            .session
            .declare_queryable(declared.key.clone())
            // rmw_zenoh's clients ask complete queryables only.
            .complete(true)
            .callback(move |query| {
                let request = match query.payload() {
                    Some(p) => cdr::from_slice::<S::Request>(&p.to_bytes()),
                    None => Err(CdrError::Invalid("a request without a payload".into())),
                };
                let sent = match handler(request) {
                    Ok(response) => {
                        let mut reply =
                            query.reply(reply_key.clone(), cdr::to_vec(&response)).encoding(ZEncoding::APPLICATION_CDR);
                        // The reply names the request: the client's sequence number and GID.
                        let asked = query.attachment().and_then(|a| Attachment::from_bytes(&a.to_bytes()));
                        if let (true, Some(asked)) = (attaches, asked) {
                            let answer = Attachment { source_timestamp_ns: now_ns(), ..asked };
                            reply = reply.attachment(answer.to_bytes());
                        }
                        reply.wait()
                    }
                    Err(why) => query.reply_err(why).wait(),
                };
                if let Err(e) = sent {
                    tracing::warn!("replying on {reply_key}: {e}");
                }
            })
            .await
            .map_err(|e| Ros2Error::zenoh(&declared.key, e))?;
        Ok(ServiceServer { _queryable: queryable, _token: declared.token })
    }

    pub async fn client<S: RosService>(&self, service: &Service<S>) -> Result<Client<S>, Ros2Error> {
        let hash = msg::service_hash::<S>();
        let e = Endpoint { name: &service.name, type_name: S::TYPE_NAME, type_hash: &hash };
        let declared = self.declare(EntityKind::ServiceClient, &e, SERVICE_QOS).await?;
        Ok(Client {
            session: self.session.clone(),
            attach: self.attaches().then_some(declared.gid),
            seq: AtomicI64::new(1),
            key: declared.key,
            name: service.name.to_string(),
            _token: declared.token,
            _type: std::marker::PhantomData,
        })
    }
}

/// A topic's publisher.
pub struct Publisher<T> {
    publisher: AdvancedPublisher<'static>,
    encoding: Encoding,
    /// rmw_zenoh: the GID every sample's attachment carries.
    attach: Option<Gid>,
    seq: AtomicI64,
    key: String,
    _token: Option<LivelinessToken>,
    _type: std::marker::PhantomData<fn(&T)>,
}

impl<T: RosMessage> Publisher<T> {
    pub async fn put(&self, msg: &T) -> Result<(), Ros2Error> {
        let payload = match self.encoding {
            Encoding::Cdr => cdr::to_vec(msg),
            Encoding::Json => serde_json::to_vec(msg).map_err(|e| Ros2Error::zenoh(&self.key, e))?,
        };
        let mut put = self.publisher.put(payload);
        if let Some(gid) = self.attach {
            let sequence_number = self.seq.fetch_add(1, Ordering::Relaxed);
            put = put.attachment(Attachment { sequence_number, source_timestamp_ns: now_ns(), gid }.to_bytes());
        }
        put.await.map_err(|e| Ros2Error::zenoh(&self.key, e))
    }

    /// The Zenoh key its samples go on.
    pub fn key(&self) -> &str {
        &self.key
    }
}

/// A subscription: messages reach its callback until it is dropped.
pub struct Subscription {
    _subscriber: AdvancedSubscriber<()>,
    _token: Option<LivelinessToken>,
}

/// A service server: requests reach its handler until it is dropped.
pub struct ServiceServer {
    _queryable: zenoh::query::Queryable<()>,
    _token: Option<LivelinessToken>,
}

/// A service client.
pub struct Client<S> {
    session: zenoh::Session,
    attach: Option<Gid>,
    seq: AtomicI64,
    key: String,
    name: String,
    _token: Option<LivelinessToken>,
    _type: std::marker::PhantomData<fn(&S)>,
}

impl<S: RosService> Client<S> {
    /// The service's answer to `request`, within `timeout`.
    pub async fn call(&self, request: &S::Request, timeout: Duration) -> Result<S::Response, Ros2Error> {
        let fail = |why: String| Ros2Error::Call { service: self.name.clone(), why };
        let mut get = self
            .session
            .get(self.key.clone())
            .payload(cdr::to_vec(request))
            .encoding(ZEncoding::APPLICATION_CDR)
            .target(QueryTarget::AllComplete)
            .consolidation(ConsolidationMode::None)
            .timeout(timeout);
        if let Some(gid) = self.attach {
            let sequence_number = self.seq.fetch_add(1, Ordering::Relaxed);
            get = get.attachment(Attachment { sequence_number, source_timestamp_ns: now_ns(), gid }.to_bytes());
        }
        let asked = std::time::Instant::now();
        let replies = get.await.map_err(|e| fail(e.to_string()))?;
        // The replies end at once when no server is known, else at the timeout.
        let reply = replies.recv_async().await.map_err(|_| {
            if asked.elapsed() < timeout {
                fail("no server of it is reachable".into())
            } else {
                fail(format!("no reply within {timeout:?}"))
            }
        })?;
        match reply.result() {
            Ok(sample) => Ok(cdr::from_slice(&sample.payload().to_bytes())?),
            Err(e) => Err(fail(format!("refused: {}", String::from_utf8_lossy(&e.payload().to_bytes())))),
        }
    }
}
