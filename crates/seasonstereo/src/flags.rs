//! The options as people type them, for every front end (the command line's flags, the Python
//! package's keywords): plain numbers where 0 turns a filter off, a census window as `"WxH"`, a
//! method or a gridding by name, memory in GiB. Each becomes the library's typed option here,
//! once, so the front ends share their defaults, what "0" means and their error messages.

pub use reconstruct::flags::{
    census_window, fill_cells, format_census, grid, gridding, heights, median_cells, memory_bytes,
    method, ortho_blend, utm_zone, ClassicalFlags, RESOLUTION,
};
