//! The `topspin` command line (DESIGN §8): one module per subcommand, each
//! a thin shell over the layer crates (`topspin-core`, `topspin-daemon`,
//! `topspin-sim`, `topspin-lab`; ARCHITECTURE.md).
//!
//! `DESIGN §n` in these docs cites section n of `docs/design.md`.

pub mod cli;
