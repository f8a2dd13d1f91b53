//! The transport conformance suite: every behaviour of the runtime's transport seam written once,
//! generic over the link ([`behaviours`]), as a library that each transport crate instantiates in
//! its own `tests/conformance.rs` with a [`rig::Rig`] and one line, [`conformance_tests!`], as
//! iceoryx2's backends instantiate its conformance tests: one `#[test]` per behaviour, so that
//! `formation-transport-zenoh`'s `conformance::rejoin` is Zenoh's rejoin.
//!
//! | behaviour | what it holds the link to |
//! |---|---|
//! | admission | only an agent proving the launch secret drives, one per robot; the others are refused with the reason |
//! | lagging | a lockstep agent that stops answering is braked and waited for once, and drives again when it answers |
//! | rejoin | an agent that goes is replaced by a new incarnation, which drives from its first answer |
//! | stale_command | a realtime command whose scan is past the stale window is never used |
//! | swap | a model swap is forwarded and done at a tick boundary; a bad model or robot is refused |
//! | shutdown | the world's end stops the agents, and the run leaves nothing behind |
//!
//! The rigs: the in-memory bus with the world and agents on threads ([`rig::MemoryRig`], this
//! crate's own `tests/memory.rs`), iceoryx2 in a namespace of the test's own
//! (`transport-iceoryx2`), Zenoh on a free loopback port with the run's credentials
//! (`transport-zenoh`), and the world as a ROS 2 team with ROS 2 agents (`transport-ros2`). A
//! ROS 2 agent is swapped by restarting it with another model (`formation swap --transport ros2`
//! says so): the ROS 2 world link carries no swap request, so ROS 2 runs no swap test.
//!
//! A new transport's `tests/conformance.rs`:
//!
//! ```ignore
//! struct MyRig { /* the launch, and what the transport needs */ }
//! impl formation_transport_conformance::rig::Rig for MyRig { /* ... */ }
//! formation_transport_conformance::conformance_tests!(MyRig, swap); // `swap` if a `SwapRig`
//! ```

pub mod agent;
pub mod behaviours;
pub mod pilot;
pub mod rig;
pub mod world;

/// The `#[test]`s of the conformance suite for the rig `$rig`: the behaviours every link has,
/// and the `$extra` ones this link has too (`swap`, for a [`rig::SwapRig`]).
#[macro_export]
macro_rules! conformance_tests {
    ($rig:ty $(, $extra:ident)*) => {
        $crate::conformance_tests!(@tests $rig; admission, lagging, rejoin, stale_command, shutdown $(, $extra)*);
    };
    (@tests $rig:ty; $($behaviour:ident),*) => {
        $(
            #[test]
            fn $behaviour() {
                $crate::behaviours::$behaviour::<$rig>();
            }
        )*
    };
}
