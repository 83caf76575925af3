//! The outputs' guards and writes that every front end shares: an output is never one of the
//! run's inputs nor replaced without `overwrite`, a text is written atomically, a list of
//! failed items is named in one line.

pub use workflow::outputs::{check_output_file, first_names};
pub use workflow::stage::write_text;
