//! Exit codes that scripts can trust, and the global safety flags.
//!
//! 0: all done. 1: an error before (or instead of) any work, including a malformed command
//! line. 2: partial (some tiles or items failed; the output lists them); `--allow-partial` turns
//! it into 0 with a warning. 3: nothing produced.

use std::path::Path;
use std::process::ExitCode;
use std::sync::OnceLock;

use seasonstereo::outputs::{check_output_file, first_names};
use seasonstereo::{error_line, Incomplete};

/// The text of `--help` on exit codes.
pub const EXIT_CODES_HELP: &str = "Exit codes: 0 all done; 1 error before any work (a missing \
    or wrong input, a refused output, a malformed command line); 2 partial: some tiles or items \
    failed and are named (--allow-partial makes it 0 with a warning); 3 nothing produced.\n\
    Outputs: an output that is one of the run's inputs is refused; an existing DSM, disparity or \
    report is only replaced with --overwrite, atomically (written beside, then renamed); a DSM \
    is written as .tif or .tiff only; a work folder of another run (command, inputs or options) \
    is refused, or cleared with --overwrite.";

/// The global flags every subcommand obeys.
#[derive(Clone, Copy, Debug, Default)]
pub struct Safety {
    /// Replace existing final outputs (DSMs, disparities, reports).
    pub overwrite: bool,
    /// Exit 0 (with a warning) when some items failed.
    pub allow_partial: bool,
}

static SAFETY: OnceLock<Safety> = OnceLock::new();

/// Records the global flags, once, before the subcommand runs.
pub fn set(safety: Safety) {
    let _ = SAFETY.set(safety);
}

pub fn safety() -> Safety {
    SAFETY.get().copied().unwrap_or_default()
}

/// Whether `--overwrite` was given.
pub fn overwrite() -> bool {
    safety().overwrite
}

/// Refuses `output` (of option `flag`) when it is one of `inputs`, a folder, or an existing file
/// without `--overwrite`.
pub fn guard_output(flag: &str, output: &Path, inputs: &[&Path]) -> anyhow::Result<()> {
    check_output_file(flag, output, inputs, safety().overwrite)
}

/// The exit code of a run's result, its error printed: one line per cause, no repeats.
pub fn exit_code(result: anyhow::Result<()>) -> ExitCode {
    let Err(e) = result else {
        return ExitCode::SUCCESS;
    };
    if let Some(incomplete) = e.downcast_ref::<Incomplete>() {
        if let (Incomplete::Partial { .. }, true) = (incomplete, safety().allow_partial) {
            eprintln!("warning: {e:#} (--allow-partial: exit code 0)");
            return ExitCode::SUCCESS;
        }
        eprintln!("error: {}", message(&e));
        return ExitCode::from(incomplete.exit_code());
    }
    eprintln!("error: {}", message(&e));
    ExitCode::from(1)
}

/// The error chain as one line, a context already contained in its cause left out.
pub fn message(e: &anyhow::Error) -> String {
    error_line(e)
}

/// Clap's errors: help and version exit 0, a malformed command line 1 (2 means partial).
pub fn parse_error(e: clap::Error) -> ExitCode {
    let _ = e.print();
    if e.use_stderr() {
        ExitCode::from(1)
    } else {
        ExitCode::SUCCESS
    }
}

/// The end of a run that wrote its output: exit code 2 when its `failed` items (of `total`
/// `what`) are missing from it, the first ones named and how to `retry`; `Ok` when none failed.
pub fn partial_if_any(
    what: &str,
    total: usize,
    failed: Vec<String>,
    retry: &str,
) -> anyhow::Result<()> {
    if failed.is_empty() {
        return Ok(());
    }
    Err(Incomplete::Partial {
        message: format!(
            "{} of {total} {what} failed ({}); the output holds the others: {retry}",
            failed.len(),
            first_names(&failed)
        ),
        failed,
    }
    .into())
}
