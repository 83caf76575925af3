//! Job scripts: a script that starts in the submitting folder, its arguments quoted as shell
//! words ([`workflow::shell`]).

use std::path::Path;

use anyhow::Result;

pub use workflow::shell::{join, quote, split};
use workflow::stage::write_text;

/// Writes the job script `path` (atomically): a `/bin/sh` header naming the command that wrote
/// it (`by`, e.g. "jobs slurm reconstruct") and `what` it runs, a `cd` into `cwd` (relative
/// paths of the arguments are relative to it), then `body`.
pub fn write_script(path: &Path, by: &str, what: &str, cwd: &Path, body: &str) -> Result<()> {
    let head = format!(
        "#!/bin/sh\n# Written by `seasonstereo {by}` for {what}.\ncd {} || exit 1\n",
        quote(&cwd.display().to_string())
    );
    write_text(path, &format!("{head}{body}"))
}
