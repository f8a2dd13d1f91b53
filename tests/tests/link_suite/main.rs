//! The link suite (issue 23): every behaviour of the runtime's transport seam written once,
//! generic over the link ([`behaviours`]), and instantiated for each transport as iceoryx2 does
//! for its own services: one module per transport, one `#[test]` per behaviour, so that
//! `link_suite::zenoh::rejoin` is Zenoh's rejoin.
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
//! The transports ([`rig`]): the in-memory bus with the world and agents on threads, iceoryx2 in
//! a namespace of the test's own, Zenoh on a free loopback port with the run's credentials, and
//! the world as a ROS 2 team with ROS 2 agents. A ROS 2 agent is swapped by restarting it with
//! another model (`formation swap --transport ros2` says so): the ROS 2 world link carries no
//! swap request, so the ROS 2 module has no swap test.

mod agent;
mod behaviours;
mod pilot;
mod rig;
mod world;

/// One module of `#[test]`s for the rig `$rig`: the behaviours every link has, and the `$extra`
/// ones this link has too.
macro_rules! instantiate {
    ($module:ident, $rig:ty $(, $extra:ident)*) => {
        mod $module {
            instantiate!(@tests $rig; admission, lagging, rejoin, stale_command, shutdown $(, $extra)*);
        }
    };
    (@tests $rig:ty; $($behaviour:ident),*) => {
        $(
            #[test]
            fn $behaviour() {
                crate::behaviours::$behaviour::<$rig>();
            }
        )*
    };
}

instantiate!(memory, crate::rig::MemoryRig, swap);
instantiate!(iceoryx2, crate::rig::IceoryxRig, swap);
instantiate!(zenoh, crate::rig::ZenohRig, swap);
instantiate!(ros2, crate::rig::Ros2Rig);
