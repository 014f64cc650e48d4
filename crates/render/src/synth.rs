//! Scene synthesis: renders an RGB frame of a given arm pose for synthetic experiments.
