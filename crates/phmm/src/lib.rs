//! Left-right Gaussian HMMs and linear parametric HMMs (Wilson & Bobick, PAMI 1999).
//!
//! This crate is the action model of actrack (SPEC.md §1–§2). It does no I/O.
//!
//! Not implemented yet: see the project's issue "Workspace foundation and the parametric HMM crate".
