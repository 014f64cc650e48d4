//! Python bindings of actrack (module `actrack._actrack`).
//!
//! Not implemented yet: see the project's issue "The Python package".
