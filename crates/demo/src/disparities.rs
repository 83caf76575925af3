//! The disparity half of the demo's scores: each predicted disparity against the world's exact
//! one, over the pixels visible in both views and per class of the left view.

use anyhow::Result;
use raster::{Image, Mask};
use world::{class, World};

use workflow::metrics::{error_map, score_disparity, DisparityScores};

/// The world's OpenEarthMap classes the disparity scores are split by.
const CLASSES: [u8; 6] = [
    class::BUILDING,
    class::ROAD,
    class::DEVELOPED,
    class::RANGELAND,
    class::TREE,
    class::WATER,
];

/// How one predicted disparity scores against the truth.
pub struct DisparityResult {
    /// Over the pixels visible in both views.
    pub visible: DisparityScores,
    /// Per class of the left view (visible pixels).
    pub by_class: Vec<(String, DisparityScores)>,
    /// |error| on the visible pixels, NaN on the occluded ones.
    pub errors: Image,
}

/// Scores `predicted` on the pixels of the left view that the right view sees too: occluded
/// pixels have no true match to find.
pub fn score_disparities(world: &World, predicted: &Image) -> Result<DisparityResult> {
    let visible = Mask::from_fn(world.disparity.width(), world.disparity.height(), |x, y| {
        !world.occluded.get(x, y)
    });
    Ok(DisparityResult {
        visible: score_disparity(predicted, &world.disparity, &visible)?,
        by_class: scores_by_class(world, predicted, &visible)?,
        errors: visible_errors(world, predicted, &visible)?,
    })
}

/// The scores per class of [`CLASSES`], visible pixels only.
fn scores_by_class(
    world: &World,
    predicted: &Image,
    visible: &Mask,
) -> Result<Vec<(String, DisparityScores)>> {
    let classes = &world.left.classes;
    CLASSES
        .iter()
        .map(|&c| {
            let region = Mask::from_fn(visible.width(), visible.height(), |x, y| {
                visible.get(x, y) && classes.get(x, y, 0) as u8 == c
            });
            Ok((
                class::NAMES[c as usize].to_string(),
                score_disparity(predicted, &world.disparity, &region)?,
            ))
        })
        .collect()
}

/// The error map with the occluded pixels blanked (NaN).
fn visible_errors(world: &World, predicted: &Image, visible: &Mask) -> Result<Image> {
    let errors = error_map(predicted, &world.disparity)?;
    Ok(Image::new(
        errors.width(),
        errors.height(),
        1,
        errors
            .data()
            .iter()
            .zip(visible.data())
            .map(|(&e, &v)| if v { e } else { f32::NAN })
            .collect(),
    )?)
}
