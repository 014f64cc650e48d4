//! actrack: track a human arm in video by tracking the action it performs.
//!
//! This crate owns I/O and pipelines: configuration (scene, cameras, table), mocap importers, frame
//! sources, MCAP/CSV writers, evaluation metrics and the `track` pipeline. The numeric kernels are
//! in `actrack-phmm`, `actrack-render` and `actrack-pf`.
//!
//! Not implemented yet: see the project's issues.

pub mod bench;
pub mod demo;
pub mod error;
pub mod eval;
pub mod frames;
pub mod manifest;
pub mod mcap_out;
pub mod mocap;
pub mod model;
pub mod motion;
pub mod pipeline;
pub mod plots;
pub mod reproduce;
pub mod scene;
pub mod synth;
pub mod track_csv;
pub mod train;
pub use error::{Error, Result};
