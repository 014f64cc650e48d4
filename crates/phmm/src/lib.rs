//! Left-right Gaussian HMMs and linear parametric HMMs (Wilson & Bobick, PAMI 1999).
//!
//! This crate is the action model of actrack (SPEC.md §1–§2). It does no I/O.
//!
//! Work in progress: the model type, its validation and accessors are in place; inference and
//! training follow.
#![deny(missing_docs)]
// Temporary while the inference and training modules land (they use the crate-private helpers).
#![allow(dead_code)]

mod error;
mod linalg;
mod model;

pub use error::PhmmError;
pub use model::{CovarianceKind, EndMode, Phmm};
