//! One module per subcommand.

pub mod bench;
pub mod calibrate;
pub mod deploy;
pub mod eval;
pub mod generate;
pub mod houses;
pub mod llm;
pub mod llm_setup;
pub mod merge;
pub mod prior;
pub mod prompts;
pub mod scene;
pub mod select;
pub mod serve;
