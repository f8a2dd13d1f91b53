//! The in-memory bus held to the conformance suite: the reference every transport is compared
//! with, and the suite's own check that its behaviours pass where nothing can go wrong in I/O.

formation_transport_conformance::conformance_tests!(
    formation_transport_conformance::rig::MemoryRig,
    swap
);
