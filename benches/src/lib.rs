//! Shared fixtures for the criterion benches (workload loading lives here).
