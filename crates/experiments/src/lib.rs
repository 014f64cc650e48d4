//! Experiments of the actrack project, outside the library: the paper's experiment on real
//! motion ([`reproduce`]), whose conditions are [`actrack::TrackConfig`]s plus the rendering
//! conditions, each video tracked by [`actrack::Session`]; and the generalisation benchmark
//! ([`generalisation`]): held-out trials in randomised scene styles. [`prose`] puts a
//! configuration into the words of the pages they write.

pub mod generalisation;
pub mod prose;
pub mod reproduce;
