//! Helpers shared by the multi-process integration tests: unique iceoryx2 namespaces, process fixtures and shared-memory leak checks.
