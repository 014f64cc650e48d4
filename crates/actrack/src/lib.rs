//! actrack: track a human arm in video by tracking the action it performs.
//!
//! This crate owns I/O and pipelines: the tracking configuration ([`TrackConfig`]) and the one
//! tracking loop ([`Session`]), the scene (cameras, table, actor), mocap importers, frame sources,
//! MCAP/CSV writers, evaluation metrics and the `track` pipeline. The numeric kernels are in
//! `actrack-phmm`, `actrack-render` and `actrack-pf`.

pub mod bench;
pub mod calibrate;
pub mod config;
pub mod demo;
pub mod error;
pub mod eval;
pub mod frames;
pub mod gate;
pub mod manifest;
pub mod mcap_out;
pub mod mocap;
pub mod model;
pub mod motion;
pub mod observation;
pub mod pipeline;
pub mod plots;
pub mod scene;
pub mod session;
pub mod style;
pub mod synth;
pub mod track_csv;
pub mod train;

#[cfg(test)]
mod fuzz_tests;

/// The numeric kernels the facade is built on, for users who need them directly (the HMM and
/// PHMM, the renderer and edge image, the action-space particle filter).
pub use actrack_pf as pf;
pub use actrack_phmm as phmm;
pub use actrack_render as render;
pub use config::TrackConfig;
pub use error::{Error, Result};
pub use model::ActionModel;
pub use scene::Scene;
pub use session::{FrameResult, Session};
