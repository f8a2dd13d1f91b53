//! Peers whose link dropped and that may come back on their own ([`ReconnectGrace`]): the one
//! bookkeeping of a network transport's world for agents that are *unreachable* — their session
//! dropped and the transport reconnects it by itself — until they return or the grace runs out.
//!
//! Pure: the caller passes the time, so the rule is unit-tested without a network. The Zenoh and
//! ROS 2 worlds both use it, with their own keys (a liveliness token) and values.

use std::collections::HashMap;
use std::hash::Hash;
use std::time::{Duration, Instant};

/// One unreachable peer: what the transport keeps of it, how it is named in log lines, and when
/// its link went.
#[derive(Debug)]
struct Unreachable<V> {
    value: V,
    who: String,
    went: Instant,
}

/// Peers unreachable since their link went, by key, each counted gone once `grace` has passed.
#[derive(Debug)]
pub struct ReconnectGrace<K, V> {
    grace: Duration,
    unreachable: HashMap<K, Unreachable<V>>,
}

impl<K: Eq + Hash + Clone, V> ReconnectGrace<K, V> {
    /// No one unreachable; a peer gets `grace` to come back.
    pub fn new(grace: Duration) -> Self {
        ReconnectGrace {
            grace,
            unreachable: HashMap::new(),
        }
    }

    /// The grace a peer gets.
    pub fn grace(&self) -> Duration {
        self.grace
    }

    /// Peer `key` (named `who` in log lines, e.g. `robot 2: agent pid 77`) became unreachable at
    /// `now` because `why` (e.g. `its liveliness token went`); logged once.
    pub fn went(&mut self, key: K, value: V, who: String, why: &str, now: Instant) {
        tracing::warn!(
            "{who} is unreachable ({why}); waiting up to {:.0} s for it to reconnect",
            self.grace.as_secs_f64()
        );
        self.unreachable.insert(
            key,
            Unreachable {
                value,
                who,
                went: now,
            },
        );
    }

    /// Peer `key` came back at `now`: its value, logged with how long it was away; `None` if it
    /// was not unreachable.
    pub fn came_back(&mut self, key: &K, now: Instant) -> Option<V> {
        let peer = self.unreachable.remove(key)?;
        tracing::warn!(
            "{} reconnected after {:.1} s",
            peer.who,
            now.saturating_duration_since(peer.went).as_secs_f64()
        );
        Some(peer.value)
    }

    /// The peers unreachable for the whole grace at `now`, removed and logged as gone.
    pub fn expire(&mut self, now: Instant) -> Vec<(K, V)> {
        let expired: Vec<K> = self
            .unreachable
            .iter()
            .filter(|(_, peer)| now.saturating_duration_since(peer.went) >= self.grace)
            .map(|(key, _)| key.clone())
            .collect();
        expired
            .into_iter()
            .filter_map(|key| {
                let peer = self.unreachable.remove(&key)?;
                tracing::warn!(
                    "{} has been unreachable for {:.0} s; counting it gone",
                    peer.who,
                    self.grace.as_secs_f64()
                );
                Some((key, peer.value))
            })
            .collect()
    }

    /// Whether an unreachable peer satisfies `matches`.
    pub fn any(&self, mut matches: impl FnMut(&K, &V) -> bool) -> bool {
        self.unreachable
            .iter()
            .any(|(key, peer)| matches(key, &peer.value))
    }

    /// Forgets, without a log line, the unreachable peers for which `keep` is false (a successor
    /// replaced them).
    pub fn retain(&mut self, mut keep: impl FnMut(&K, &V) -> bool) {
        self.unreachable.retain(|key, peer| keep(key, &peer.value));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const GRACE: Duration = Duration::from_secs(5);

    #[test]
    fn a_peer_back_within_the_grace_is_not_counted_gone() {
        let start = Instant::now();
        let mut peers = ReconnectGrace::new(GRACE);
        peers.went(
            (1, 77),
            "driver",
            "robot 1: agent pid 77".into(),
            "its token went",
            start,
        );
        assert!(peers.any(|&(robot, _), _| robot == 1));
        assert!(!peers.any(|&(robot, _), _| robot == 0));
        assert!(peers.expire(start + Duration::from_secs(4)).is_empty());
        assert_eq!(
            peers.came_back(&(1, 77), start + Duration::from_secs(4)),
            Some("driver")
        );
        assert!(!peers.any(|_, _| true));
        assert!(peers.expire(start + Duration::from_secs(60)).is_empty());
        assert_eq!(peers.came_back(&(1, 77), start), None);
    }

    #[test]
    fn a_peer_away_for_the_whole_grace_is_gone_once() {
        let start = Instant::now();
        let mut peers = ReconnectGrace::new(GRACE);
        peers.went(3u32, (), "a".into(), "gone", start);
        peers.went(4u32, (), "b".into(), "gone", start + Duration::from_secs(2));
        let gone = peers.expire(start + GRACE);
        assert_eq!(gone, vec![(3, ())]);
        assert!(peers.expire(start + GRACE).is_empty());
        assert_eq!(peers.expire(start + Duration::from_secs(7)), vec![(4, ())]);
        assert_eq!(peers.came_back(&3, start + GRACE), None);
    }

    #[test]
    fn a_replaced_peer_is_forgotten() {
        let start = Instant::now();
        let mut peers = ReconnectGrace::new(GRACE);
        peers.went((0, 1u64), 'x', "old".into(), "gone", start);
        peers.went((0, 2u64), 'y', "new".into(), "gone", start);
        peers.retain(|&(_, incarnation), _| incarnation == 2);
        assert_eq!(peers.expire(start + GRACE), vec![((0, 2), 'y')]);
    }
}
