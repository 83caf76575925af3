//! Procedural satellite worlds with exact ground truth (`seasonstereo world`): one rendered
//! pair in the public release's layout, its raw views with RPC cameras, or one scene on six
//! dates of a year for `reconstruct_many`.

pub use ::world::{generate, Neutral, World, WorldParams};
pub use eval::world_dates::{write_dated_stack, DatedStack, ACQUISITIONS};
pub use eval::world_io::{save_raw_views, save_world};
