//! Helpers shared by the end-to-end tests: run the built `ferret` binary and read what it said.
#![allow(dead_code)]

use std::path::Path;
use std::process::{Command, Output};

/// Runs the `ferret` binary built for these tests with `args`.
pub fn ferret(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_ferret"))
        .args(args)
        .output()
        .expect("the ferret binary runs")
}

/// Standard error as text.
pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Standard output then standard error, as text.
pub fn text(o: &Output) -> String {
    format!("{}{}", String::from_utf8_lossy(&o.stdout), stderr(o))
}

/// A temporary path as the `&str` an argument list wants.
pub fn s(p: &Path) -> &str {
    p.to_str().expect("temp paths are UTF-8")
}
