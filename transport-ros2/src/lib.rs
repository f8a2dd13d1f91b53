//! ROS 2 over rmw_zenoh (with the `zenoh` feature): an agent that drives a ROS 2 robot
//! ([`agent`]), and the world as a team of ROS 2 robots ([`world`]), both speaking rmw_zenoh's
//! wire format from `formation_ros2` over a Zenoh session ([`node`]), with no ROS installation.
//!
//! The simulated team's topics ([`TeamTopics`]) are those a multi-robot ROS 2 setup uses:
//! robot i's `/robot_<i>/scan` (`sensor_msgs/LaserScan`), `/robot_<i>/odom`
//! (`nav_msgs/Odometry`) and `/robot_<i>/cmd_vel` (`geometry_msgs/Twist`), and the team's goal on
//! `/formation/goal/heading`, `/formation/goal/distance` and `/formation/goal/speed`
//! (`std_msgs/Float64`: φ\* \[rad\], d\* \[m\], v\* \[m/s\]).
//!
//! Who may talk: on a `tcp/` endpoint a ROS 2 graph has no per-robot access control (as in ROS 2
//! without SROS2): any process that reaches the router can publish on a robot's `cmd_vel`. On a
//! `tls/` endpoint (feature `tls`, [`secure`]) every node shows a certificate of the team's
//! authority and the router's rules let robot i's certificate publish only on `/robot_<i>/cmd_vel`
//! and read only its own sensors, `/tf` and the goal. The simulated team takes Twists only from
//! the first node that publishes on each robot's `cmd_vel` (by its GID); a real robot's drivers
//! take every publisher's, as ROS 2 does.

pub mod agent;
pub mod decider;
pub mod node;
#[cfg(feature = "tls")]
pub mod secure;
pub mod world;

use formation_ros2::TopicName;

pub use agent::{OrientationKind, Ros2AgentError, Ros2AgentSettings, run_agent};
pub use decider::{Decider, DeciderSettings, GoalValue};
pub use world::Ros2WorldLink;

/// The simulated team as the world serves it over ROS 2.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ros2Team {
    /// Robots.
    pub n_robots: usize,
    /// ROS domain id.
    pub domain_id: u32,
    /// The robots' wheel separation \[m\] (Twists become wheel speeds with it).
    pub wheel_separation: f64,
    /// The LIDAR's maximum range \[m\] (readings at it are published as +inf, no return).
    pub max_range: f64,
    /// Whether every sensor message must arrive (lockstep: a dropped scan would brake its robot
    /// and change the run); in realtime a late one is worthless and is dropped under congestion.
    pub lossless: bool,
}

/// One simulated robot's topics.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TeamTopics {
    /// `sensor_msgs/LaserScan`.
    pub scan: TopicName,
    /// `nav_msgs/Odometry`.
    pub odometry: TopicName,
    /// `geometry_msgs/Twist`.
    pub cmd_vel: TopicName,
}

impl TeamTopics {
    /// Robot `robot`'s topics, `/robot_<i>/{scan,odom,cmd_vel}`.
    pub fn robot(robot: usize) -> TeamTopics {
        let topic = |name: &str| {
            TopicName::new(&format!("/robot_{robot}/{name}")).expect("a valid ROS topic name")
        };
        TeamTopics {
            scan: topic("scan"),
            odometry: topic("odom"),
            cmd_vel: topic("cmd_vel"),
        }
    }

    /// The team's goal topics: heading φ\*, distance d\*, speed v\*.
    pub fn goal() -> [TopicName; 3] {
        ["heading", "distance", "speed"].map(|name| {
            TopicName::new(&format!("/formation/goal/{name}")).expect("a valid ROS topic name")
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn team_topics_follow_the_multi_robot_convention() {
        let topics = TeamTopics::robot(12);
        assert_eq!(topics.scan.as_str(), "/robot_12/scan");
        assert_eq!(topics.odometry.as_str(), "/robot_12/odom");
        assert_eq!(topics.cmd_vel.as_str(), "/robot_12/cmd_vel");
        let goal = TeamTopics::goal().map(|t| t.as_str().to_owned());
        assert_eq!(
            goal,
            [
                "/formation/goal/heading",
                "/formation/goal/distance",
                "/formation/goal/speed"
            ]
        );
    }
}
