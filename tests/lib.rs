//! End-to-end and real-data tests across actrack's crates; the tests live in `tests/tests/`.
