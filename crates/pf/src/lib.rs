//! The action-space particle filter of "Tracking in Action Space" (SPEC.md §3): particles
//! ω = (a, θ, k), propagation with the loop grammar and the cooling schedule, weighting in log
//! space, resampling and per-frame estimates. Generic over the observation model; no I/O.
//!
//! Not implemented yet: see the project's issue "The action-space particle filter".
