//! The MonSter++ accuracy model, module by module (`../shared/design/monsterpp.md`).

pub mod context;
pub mod cost;
pub mod dpt;
pub mod features;
pub mod geometry;
pub mod model;
pub mod remp;
pub mod scale_shift;
pub mod update;
pub mod upsample;
pub mod vit;
pub mod warp;

pub use model::{Monster, MonsterOutput};
