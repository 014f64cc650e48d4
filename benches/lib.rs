//! Criterion benches of actrack; the benches live in `benches/benches/`.
