//! Simulated launcher and tracker.
