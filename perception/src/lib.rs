//! What a robot makes of its own raw LIDAR scan before its policy sees it.
//!
//! * [`occupancy`]: the occupancy image of one scan, in the robot's body frame. The single
//!   renderer used both when collecting demonstrations (`formation-expert`) and by the running
//!   agent (`formation-robot-agent`), so a policy sees at run time exactly the pixels it was
//!   trained on.
//! * [`ranges`]: the scan's ranges pooled into sectors, the float input beside the image of a
//!   model that declares one (`formation_proto::RangeInput`).
//! * [`beams`]: the direction of each beam of the LIDAR ring, computed once.
//! * [`neighbours`]: the neighbours a robot detects in its own scan, each one's centre in its body
//!   frame, fitted with a circle of the known body radius.
//! * [`hidden_pairs`]: the pairs of those detections the robot hides from each other with its
//!   own body, and the side it would step to (the law on one robot's scan steps aside).
//! * [`neighbour_input`]: those detections as a model takes them beside its image, with the
//!   Gabriel rule's verdict on each (`formation_proto::NeighbourInput`).
//! * [`policy_input`]: a goal checked where it enters a robot, and the policy's declared output
//!   turned into wheel speeds (the scalars beside the image are `formation_proto::PolicyIo`'s).
//! * [`stopping`]: the agent's stopping governor, a command slowed under a wheel acceleration
//!   limit to one the robot can stop from before it touches what its scan shows in its path.
//!
//! Pure functions of one robot's own scan and the model's declared settings: no I/O, no ONNX, no
//! transport, so the expert, the agent and the Python bindings share them without building any of
//! those.

pub mod beams;
pub mod hidden_pairs;
pub mod neighbour_input;
pub mod neighbours;
pub mod occupancy;
pub mod policy_input;
pub mod ranges;
pub mod stopping;
