//! Wake-up listeners that stay attached to a wait set for as long as they live.
//!
//! Attaching a listener to an iceoryx2 wait set is an `epoll_ctl` and, in iceoryx2 0.10, an
//! open of `/proc/sys/fs/epoll/max_user_watches`; detaching is another `epoll_ctl`. Done around
//! every wait, that was a third of an agent's time at 256 agents on 2 cores. Attached once, a
//! wait is one `epoll_wait`, and only the listeners that fired are asked for their wake-ups.

use std::collections::HashSet;
use std::rc::Rc;

use iceoryx2::port::listener::Listener;
use iceoryx2::prelude::*;
use iceoryx2::waitset::{WaitSetAttachmentId, WaitSetGuard};

use crate::error::{IceoryxError, iox};

/// The attachments a wait woke on.
pub(crate) type Fired = HashSet<WaitSetAttachmentId<ipc::Service>>;

/// Listeners with the wait set they are attached to.
pub(crate) struct Listeners {
    waitset: Rc<WaitSet<ipc::Service>>,
    listeners: Vec<Listener<ipc::Service>>,
}

type Attachments<'a> = Vec<WaitSetGuard<'a, 'a, ipc::Service>>;

self_cell::self_cell!(
    /// Listeners that stay attached to a wait set until they are dropped: the attachment guards
    /// borrow the listeners and the wait set they are kept beside.
    pub(crate) struct AttachedListeners {
        owner: Listeners,
        #[not_covariant]
        dependent: Attachments,
    }
);

impl AttachedListeners {
    /// Attaches every one of `listeners` to `waitset`.
    pub(crate) fn attach(
        waitset: &Rc<WaitSet<ipc::Service>>,
        listeners: Vec<Listener<ipc::Service>>,
    ) -> Result<Self, IceoryxError> {
        let owner = Listeners {
            waitset: Rc::clone(waitset),
            listeners,
        };
        AttachedListeners::try_new(owner, |owner| {
            owner
                .listeners
                .iter()
                .map(|listener| {
                    owner
                        .waitset
                        .attach_notification(listener)
                        .map_err(iox("attach a wake-up to a wait set"))
                })
                .collect()
        })
    }

    /// Consumes the pending wake-ups of the listeners among `fired` (the samples themselves are
    /// drained by the caller). Only those: a wake-up is a system call, and a world of 256 robots
    /// that asked every listener after each wait made some 3,000 calls a tick.
    pub(crate) fn consume(&self, fired: &Fired) {
        if fired.is_empty() {
            return;
        }
        self.with_dependent(|owner, guards| {
            for (listener, guard) in owner.listeners.iter().zip(guards.iter()) {
                if fired.contains(&WaitSetAttachmentId::from_guard(guard)) {
                    let _ = listener.try_wait(|_| {});
                }
            }
        });
    }
}

/// Waits on `waitset` up to `timeout` and collects the attachments that fired into `fired`
/// (cleared first).
pub(crate) fn wait_collecting(
    waitset: &WaitSet<ipc::Service>,
    timeout: std::time::Duration,
    fired: &mut Fired,
) -> Result<iceoryx2::waitset::WaitSetRunResult, iceoryx2::waitset::WaitSetRunError> {
    fired.clear();
    waitset.wait_and_process_once_with_timeout(
        |attachment| {
            fired.insert(attachment);
            CallbackProgression::Continue
        },
        timeout,
    )
}
