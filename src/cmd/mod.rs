//! One module per subcommand.

pub mod bench;
pub mod build;
pub mod built;
pub mod cull;
pub mod demo;
pub mod export3dtiles;
pub mod generate;
pub mod inspect;
pub mod loadtest;
pub mod path;
pub mod serve;
pub mod values;
pub mod verify;
pub mod walk;
