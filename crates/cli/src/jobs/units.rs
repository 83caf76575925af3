//! What the jobs say of their unfinished units: the list, the command that resubmits them and
//! the exit code.

use std::path::Path;

use anyhow::Result;
use seasonstereo::jobs::quote;
use seasonstereo::outputs::first_names;
use seasonstereo::{Incomplete, Units};

/// One line per failed (with its error) and missing unit.
pub(super) fn print_units(units: &Units) {
    for (id, task, error) in &units.failed {
        println!("failed  {id} (task {task}): {error}");
    }
    for (id, task) in &units.missing {
        println!("missing {id} (task {task})");
    }
}

/// The command that resubmits the failed and missing units' tasks, and exit code 2 naming
/// them (`what`: "tiles", "teacher shards").
pub(super) fn incomplete(units: &Units, what: &str, work: &Path) -> Result<()> {
    println!(
        "resubmit only these (array tasks {}): seasonstereo jobs resubmit --work {}",
        units.rerun_array(),
        quote(&work.display().to_string())
    );
    let names = units.unfinished();
    Err(Incomplete::Partial {
        message: format!(
            "{} of {} {what} failed or missing ({}): resubmit them as above",
            names.len(),
            units.len(),
            first_names(&names)
        ),
        failed: names,
    }
    .into())
}
