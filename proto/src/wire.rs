//! Zero-copy messages exchanged between the world process and the robot-agent processes over
//! iceoryx2, and the per-run service names. (Filled in by the runtime work.)
