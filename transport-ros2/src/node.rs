//! A ROS 2 node on a Zenoh session, as rmw_zenoh makes one: its liveliness token, and typed
//! publishers and subscriptions that speak rmw_zenoh's wire format (see `formation_ros2`).
//!
//! A [`Node`] declares its `NN` token; [`Node::publisher`] declares an `MP` token and a Zenoh
//! publisher on the topic's data key, and stamps every sample with the attachment rmw_zenoh
//! expects (sequence number from 1, source timestamp, the publisher's GID, derived from its token
//! as every rmw_zenoh process derives it); [`Node::subscription`] declares an `MS` token and
//! subscribes to every type and hash on the topic (`<domain>/<topic>/*/*`), so that a publisher of
//! another type or hash, a sample without attachment or a payload that is not the message's CDR
//! is reported as a typed [`InputError`] rather than silently missed.
//!
//! Samples are delivered to the subscription's callback on Zenoh's threads; the callers queue them
//! and ring a bell (see [`super::agent`] and [`super::world`]).

use std::sync::Arc;
use std::sync::atomic::{AtomicI64, AtomicU64, Ordering};

use ::zenoh::Wait;
use ::zenoh::liveliness::LivelinessToken as ZenohToken;
use ::zenoh::pubsub::{Publisher, Subscriber};
use ::zenoh::qos::{CongestionControl, Priority};
use ::zenoh::sample::Sample;
use formation_ros2::attachment::GID_LEN;
use formation_ros2::{
    Attachment, AttachmentError, CdrError, EntityKind, HashConvention, KeyExprError,
    LivelinessToken, Namespace, NodeIdentity, NodeName, Qos, RosMessage, TopicEndpoint, TopicKey,
    TopicName,
};

/// A failure to set up or use a node.
#[derive(Debug, thiserror::Error)]
pub enum NodeError {
    /// Zenoh refused an operation.
    #[error("zenoh could not {action} ({detail})")]
    Zenoh {
        /// What the node was doing.
        action: String,
        /// Zenoh's error.
        detail: String,
    },
    /// A liveliness token could not be built (a name the key expressions cannot carry).
    #[error("ROS 2 liveliness token for {what}")]
    Token {
        /// The entity.
        what: String,
        /// Why.
        #[source]
        source: formation_ros2::liveliness::LivelinessError,
    },
    /// A message could not be encoded.
    #[error("encoding a {type_name} for {topic}")]
    Encode {
        /// The topic.
        topic: String,
        /// The ROS type.
        type_name: &'static str,
        /// Why.
        #[source]
        source: formation_ros2::CdrEncodeError,
    },
}

/// Why a received sample was not a usable message.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum InputError {
    /// The sample's key names another type or hash, or is malformed.
    #[error(transparent)]
    Key(#[from] KeyExprError),
    /// No attachment: rmw_zenoh subscribers drop such samples, and so does this one.
    #[error(
        "a sample on {topic} has no attachment; rmw_zenoh publishers always attach sequence \
         number, timestamp and GID (is the publisher an rmw_zenoh node?)"
    )]
    NoAttachment {
        /// The topic.
        topic: String,
    },
    /// A malformed attachment.
    #[error("a sample on {topic} has a malformed attachment")]
    Attachment {
        /// The topic.
        topic: String,
        /// Why.
        #[source]
        source: AttachmentError,
    },
    /// The payload is not the message's CDR.
    #[error("a sample on {topic} is not a valid {type_name} (CDR)")]
    Cdr {
        /// The topic.
        topic: String,
        /// The ROS type expected.
        type_name: &'static str,
        /// Why.
        #[source]
        source: CdrError,
    },
}

/// A decoded sample with its metadata.
#[derive(Debug, Clone, PartialEq)]
pub struct Received<M> {
    /// The message.
    pub message: M,
    /// Its attachment (sequence number, source timestamp, publisher GID).
    pub attachment: Attachment,
}

/// How a publisher sends: sensor streams and commands are express and of real-time priority, so
/// that every message of a node leaves in the order it was published and none waits for a batch.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Delivery {
    /// Dropped under congestion (a late scan or command is worthless).
    Realtime,
    /// Blocks under congestion (goals and rare messages must arrive).
    Reliable,
}

/// A ROS 2 node: a Zenoh session, the node's identity and its liveliness token.
pub struct Node {
    session: Arc<::zenoh::Session>,
    identity: NodeIdentity,
    next_entity: AtomicU64,
    _token: ZenohToken,
}

impl Node {
    /// Declares node `name` in `namespace` of ROS domain `domain_id` on `session`.
    pub fn new(
        session: Arc<::zenoh::Session>,
        domain_id: u32,
        namespace: Namespace,
        name: NodeName,
        node_id: u64,
    ) -> Result<Node, NodeError> {
        let identity = NodeIdentity {
            domain_id,
            zid: session.zid().to_string(),
            node_id,
            enclave: Namespace::root(),
            namespace,
            name,
        };
        let token = LivelinessToken::node(identity.clone()).map_err(|source| NodeError::Token {
            what: format!("node {}", identity.name.as_str()),
            source,
        })?;
        let token = declare_token(&session, &token)?;
        Ok(Node {
            session,
            // Entity ids are unique within the session; nodes take theirs from the caller and
            // their entities count on from well above any node id.
            next_entity: AtomicU64::new(node_id.saturating_mul(1000).saturating_add(1)),
            identity,
            _token: token,
        })
    }

    /// The node's identity (domain, session id, names).
    pub fn identity(&self) -> &NodeIdentity {
        &self.identity
    }

    /// The session the node lives on.
    pub fn session(&self) -> &Arc<::zenoh::Session> {
        &self.session
    }

    fn endpoint_token<M: RosMessage>(
        &self,
        kind: EntityKind,
        topic: &TopicName,
        qos: Qos,
    ) -> Result<LivelinessToken, NodeError> {
        let endpoint = TopicEndpoint {
            topic: topic.clone(),
            type_name: M::DDS_TYPE_NAME.to_owned(),
            type_hash: formation_ros2::TypeHashField::Rihs01(M::type_hash()),
            qos,
        };
        let entity_id = self.next_entity.fetch_add(1, Ordering::Relaxed);
        LivelinessToken::endpoint(kind, self.identity.clone(), entity_id, endpoint).map_err(
            |source| NodeError::Token {
                what: format!("{} on {}", M::ROS_NAME, topic.as_str()),
                source,
            },
        )
    }

    /// A publisher of `M` on `topic`, announced with QoS `qos`.
    pub fn publisher<M: RosMessage>(
        &self,
        topic: &TopicName,
        qos: Qos,
        delivery: Delivery,
    ) -> Result<RosPublisher<M>, NodeError> {
        let token = self.endpoint_token::<M>(EntityKind::Publisher, topic, qos)?;
        let key = TopicKey::for_message::<M>(
            self.identity.domain_id,
            topic.clone(),
            HashConvention::Rihs01,
        )
        .to_string();
        let builder = self.session.declare_publisher(key.clone());
        let builder = match delivery {
            Delivery::Realtime => builder
                .congestion_control(CongestionControl::Drop)
                .priority(Priority::RealTime)
                .express(true),
            Delivery::Reliable => builder
                .congestion_control(CongestionControl::Block)
                .priority(Priority::RealTime)
                .express(true),
        };
        let publisher = builder.wait().map_err(|e| NodeError::Zenoh {
            action: format!("declare a publisher on {key}"),
            detail: e.to_string(),
        })?;
        let gid = token.gid();
        let zenoh_token = declare_token(&self.session, &token)?;
        Ok(RosPublisher {
            topic: topic.as_str().to_owned(),
            publisher,
            gid,
            sequence: AtomicI64::new(0),
            _token: zenoh_token,
            _message: std::marker::PhantomData,
        })
    }

    /// A subscription to `M` on `topic`, announced with QoS `qos`; `deliver` gets each sample,
    /// decoded, or the reason it is not a usable `M`.
    pub fn subscription<M: RosMessage + Send + 'static>(
        &self,
        topic: &TopicName,
        qos: Qos,
        deliver: impl Fn(Result<Received<M>, InputError>) + Send + Sync + 'static,
    ) -> Result<RosSubscription, NodeError> {
        let token = self.endpoint_token::<M>(EntityKind::Subscription, topic, qos)?;
        let key = TopicKey::wildcard(self.identity.domain_id, topic);
        let name = topic.as_str().to_owned();
        let subscriber = self
            .session
            .declare_subscriber(key.clone())
            .callback(move |sample| deliver(decode_sample::<M>(&name, &sample)))
            .wait()
            .map_err(|e| NodeError::Zenoh {
                action: format!("subscribe to {key}"),
                detail: e.to_string(),
            })?;
        let zenoh_token = declare_token(&self.session, &token)?;
        Ok(RosSubscription {
            _subscriber: subscriber,
            _token: zenoh_token,
        })
    }
}

fn declare_token(
    session: &::zenoh::Session,
    token: &LivelinessToken,
) -> Result<ZenohToken, NodeError> {
    let key = token.to_string();
    session
        .liveliness()
        .declare_token(key.clone())
        .wait()
        .map_err(|e| NodeError::Zenoh {
            action: format!("declare the liveliness token {key}"),
            detail: e.to_string(),
        })
}

/// Decodes one sample of `M` on `topic`: key (type and hash), attachment, CDR.
pub fn decode_sample<M: RosMessage>(
    topic: &str,
    sample: &Sample,
) -> Result<Received<M>, InputError> {
    TopicKey::parse(sample.key_expr().as_str())?.expect_message::<M>()?;
    let attachment = sample
        .attachment()
        .ok_or_else(|| InputError::NoAttachment {
            topic: topic.to_owned(),
        })?;
    let attachment =
        Attachment::decode(&attachment.to_bytes()).map_err(|source| InputError::Attachment {
            topic: topic.to_owned(),
            source,
        })?;
    let message = M::from_cdr(&sample.payload().to_bytes()).map_err(|source| InputError::Cdr {
        topic: topic.to_owned(),
        type_name: M::ROS_NAME,
        source,
    })?;
    Ok(Received {
        message,
        attachment,
    })
}

/// A typed publisher with rmw_zenoh's attachment on every sample.
pub struct RosPublisher<M> {
    topic: String,
    publisher: Publisher<'static>,
    gid: [u8; GID_LEN],
    sequence: AtomicI64,
    _token: ZenohToken,
    _message: std::marker::PhantomData<fn(M)>,
}

impl<M: RosMessage> RosPublisher<M> {
    /// Publishes `message`, its attachment carrying `source_timestamp_ns`.
    pub fn publish(&self, message: &M, source_timestamp_ns: i64) -> Result<(), NodeError> {
        let payload = message.to_cdr().map_err(|source| NodeError::Encode {
            topic: self.topic.clone(),
            type_name: M::ROS_NAME,
            source,
        })?;
        let attachment = Attachment {
            sequence_number: self.sequence.fetch_add(1, Ordering::Relaxed) + 1,
            source_timestamp_ns,
            source_gid: self.gid,
        };
        self.publisher
            .put(payload)
            .attachment(attachment.encode().to_vec())
            .wait()
            .map_err(|e| NodeError::Zenoh {
                action: format!("publish on {}", self.topic),
                detail: e.to_string(),
            })
    }

    /// The publisher's GID (what its attachments carry).
    pub fn gid(&self) -> [u8; GID_LEN] {
        self.gid
    }
}

/// A subscription; dropping it undeclares it and its token.
pub struct RosSubscription {
    _subscriber: Subscriber<()>,
    _token: ZenohToken,
}

/// Nanoseconds since the Unix epoch on the system clock (what rmw_zenoh stamps attachments with).
pub fn system_time_ns() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| i64::try_from(d.as_nanos()).unwrap_or(i64::MAX))
        .unwrap_or(0)
}
