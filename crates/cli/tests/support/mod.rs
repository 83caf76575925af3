//! What every command-line test does: run the binary this package built and read its answer.
#![allow(dead_code)]

use std::process::{Command, Output};

/// Runs `seasonstereo ARGS…` to the end.
pub fn seasonstereo(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_seasonstereo"))
        .args(args)
        .output()
        .expect("the binary runs")
}

/// Its standard error, as text.
pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Its exit code (a test fails when it was killed instead).
pub fn code(o: &Output) -> i32 {
    o.status.code().expect("exited, not killed")
}
