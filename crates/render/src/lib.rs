//! The observation model of actrack (SPEC.md §4): camera, arm geometry, silhouette and contour
//! rendering, the edge image and the contour likelihood. It does no I/O.
//!
//! Not implemented yet: see the project's issue "The observation model".
