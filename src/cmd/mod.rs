//! One module per subcommand.

pub mod build;
pub mod cull;
pub mod generate;
pub mod inspect;
pub mod verify;
