//! One robot's decision: its own scan to an occupancy image to the policy to wheel commands; and the agent process.
