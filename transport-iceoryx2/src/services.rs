//! How every process of a run gets an iceoryx2 service, defined once: the world creates the
//! run's services ([`Access::Create`]); an agent and `formation swap` only open them
//! ([`Access::Open`]), with the same limits, so that opening never disagrees with creating.
//!
//! A publish-subscribe service keeps no history and overwrites the oldest unread sample when a
//! reader falls behind; its event service of the same name (publishing wakes nobody in iceoryx2)
//! has one notifier per publisher and one listener per subscriber.

use iceoryx2::node::NodeView;
use iceoryx2::port::subscriber::{Subscriber, SubscriberCreateError};
use iceoryx2::prelude::*;

use crate::error::{IceoryxCause, IceoryxError};
use crate::naming::ServiceLimits;

/// A publish-subscribe service's port factory.
pub(crate) type PubSubService<T> =
    iceoryx2::service::port_factory::publish_subscribe::PortFactory<ipc::Service, T, ()>;
/// An event service's port factory.
pub(crate) type EventService = iceoryx2::service::port_factory::event::PortFactory<ipc::Service>;

/// Whether this process makes the service or expects it to exist.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Access {
    /// Create it, or open it if it exists (the world).
    Create,
    /// Open it only; a service that does not exist (yet) is [`ServiceErrorKind::Unavailable`].
    Open,
}

/// Why a service could not be had.
#[derive(Debug)]
pub(crate) struct ServiceError {
    /// The service's name.
    pub name: String,
    /// What went wrong.
    pub kind: ServiceErrorKind,
    /// iceoryx2's error.
    pub source: IceoryxCause,
}

/// What went wrong with a service.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum ServiceErrorKind {
    /// The name is not a valid iceoryx2 service name.
    Name,
    /// It does not exist (with [`Access::Open`]), or iceoryx2 refused to create or open it.
    Unavailable,
}

impl ServiceError {
    /// What could not be done, for a message: `name service NAME` or `ACTION service NAME`.
    pub(crate) fn action(&self, verb: &str) -> String {
        match self.kind {
            ServiceErrorKind::Name => format!("name service {}", self.name),
            ServiceErrorKind::Unavailable => format!("{verb} service {}", self.name),
        }
    }

    /// The error as the world reports it when creating the service failed.
    pub(crate) fn create_failed(self) -> IceoryxError {
        IceoryxError::Create {
            action: self.action("create"),
            source: self.source,
        }
    }

    /// The error as a process that only opens services reports a name iceoryx2 refused.
    pub(crate) fn open_failed(self) -> IceoryxError {
        IceoryxError::Refused {
            action: self.action("open"),
            source: self.source,
        }
    }
}

fn service_name(name: &str) -> Result<ServiceName, ServiceError> {
    ServiceName::new(name).map_err(|e| ServiceError {
        name: name.to_owned(),
        kind: ServiceErrorKind::Name,
        source: Box::new(e),
    })
}

fn unavailable<E: std::error::Error + Send + Sync + 'static>(
    name: &str,
) -> impl FnOnce(E) -> ServiceError + '_ {
    move |e| ServiceError {
        name: name.to_owned(),
        kind: ServiceErrorKind::Unavailable,
        source: Box::new(e),
    }
}

/// The publish-subscribe service `name` of payload `T` with `limits`, created or opened as
/// `access` says.
pub(crate) fn pubsub_service<T: std::fmt::Debug + ZeroCopySend + IceoryxSend>(
    node: &Node<ipc::Service>,
    name: &str,
    limits: ServiceLimits,
    access: Access,
) -> Result<PubSubService<T>, ServiceError> {
    let builder = node
        .service_builder(&service_name(name)?)
        .publish_subscribe::<T>()
        .max_publishers(limits.max_publishers)
        .max_subscribers(limits.max_subscribers)
        .subscriber_max_buffer_size(limits.subscriber_buffer)
        .max_nodes(limits.max_nodes)
        .history_size(0)
        .enable_safe_overflow(true);
    match access {
        Access::Create => builder.open_or_create().map_err(unavailable(name)),
        Access::Open => builder.open().map_err(unavailable(name)),
    }
}

/// A subscriber of `service` (a service of `limits`) that keeps as many unread samples as the
/// service lets it.
pub(crate) fn subscriber<T: std::fmt::Debug + ZeroCopySend + IceoryxSend>(
    service: &PubSubService<T>,
    limits: ServiceLimits,
) -> Result<Subscriber<ipc::Service, T, ()>, SubscriberCreateError> {
    service
        .subscriber_builder()
        .buffer_size(limits.subscriber_buffer)
        .create()
}

/// The event service `name` paired with a publish-subscribe service of `limits`, created or
/// opened as `access` says.
pub(crate) fn event_service(
    node: &Node<ipc::Service>,
    name: &str,
    limits: ServiceLimits,
    access: Access,
) -> Result<EventService, ServiceError> {
    let builder = node
        .service_builder(&service_name(name)?)
        .event()
        .max_notifiers(limits.max_publishers)
        .max_listeners(limits.max_subscribers)
        .max_nodes(limits.max_nodes);
    match access {
        Access::Create => builder.open_or_create().map_err(unavailable(name)),
        Access::Open => builder.open().map_err(unavailable(name)),
    }
}

/// Hands every sample waiting on `subscriber`, decoded by `decode`, to `sink`, oldest first; a
/// sample that does not decode is logged as a malformed `what` and skipped. The error is
/// iceoryx2's, when receiving failed.
pub(crate) fn drain_decoded<T, U, E: std::fmt::Display>(
    subscriber: &Subscriber<ipc::Service, T, ()>,
    what: &dyn std::fmt::Display,
    decode: impl Fn(&T) -> Result<U, E>,
    sink: &mut dyn FnMut(U),
) -> Result<(), IceoryxError>
where
    T: std::fmt::Debug + ZeroCopySend,
{
    let failed = |e| IceoryxError::Refused {
        action: format!("receive a {what}"),
        source: Box::new(e),
    };
    while let Some(sample) = subscriber.receive().map_err(failed)? {
        match decode(sample.payload()) {
            Ok(decoded) => sink(decoded),
            Err(e) => tracing::warn!("ignoring a malformed {what}: {e}"),
        }
    }
    Ok(())
}

/// A node of a run named `name` in iceoryx2's `config`, whose waits hand on termination requests
/// (SIGINT, SIGTERM).
pub(crate) fn run_node(
    config: &iceoryx2::config::Config,
    name: &str,
) -> Result<Node<ipc::Service>, IceoryxError> {
    let node_name =
        NodeName::new(name).map_err(crate::error::iox(format!("name the node {name}")))?;
    NodeBuilder::new()
        .name(&node_name)
        .config(config)
        .signal_handling_mode(SignalHandlingMode::HandleTerminationRequests)
        .create::<ipc::Service>()
        .map_err(crate::error::iox(format!("create the node {name}")))
}

/// Lists the nodes of `node`'s run and finds the first alive one named `name`: `None` when there
/// is none, else `Some` of its process id, `None` inside when it could not be read.
pub(crate) fn alive_node(
    node: &Node<ipc::Service>,
    name: &str,
) -> Result<Option<Option<i32>>, IceoryxError> {
    let mut found = None;
    Node::<ipc::Service>::list(node.config(), |state| {
        if let NodeState::Alive(view) = &state
            && view
                .details()
                .as_ref()
                .is_some_and(|d| d.name().as_str() == name)
        {
            found = Some(view.id().pid::<ipc::Service>().ok().map(|pid| pid.value()));
            return CallbackProgression::Stop;
        }
        CallbackProgression::Continue
    })
    .map_err(crate::error::iox("list the run's nodes"))?;
    Ok(found)
}
