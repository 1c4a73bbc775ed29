//! One module per subcommand: clap arguments and a `run` that calls the libraries.

pub mod apply;
pub mod camera;
pub mod campaign;
pub mod convert;
pub mod diagnose;
pub mod diagnose_figures;
pub mod fit;
pub mod generate;
pub mod rain;
