//! The simulated world: differential-drive robots, LIDAR ray casting, scenarios, episodes and the paper's metrics.
