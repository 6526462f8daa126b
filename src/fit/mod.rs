//! Spin from a trajectory and prediction (paper §IV).
