//! One module per subcommand.

pub mod build;
pub mod cull;
pub mod generate;
pub mod inspect;
pub mod path;
pub mod serve;
pub mod verify;
pub mod walk;
