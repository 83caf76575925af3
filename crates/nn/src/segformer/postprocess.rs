//! SegFormer's logits to the masks: the CPU post-processing of [`dataset::segmentation`] on the
//! network's output tensor.

use burn::tensor::Tensor;
use dataset::segmentation::{
    argmax_classes, class_mask, softmax_classes, upsample_scores, MaskKind, MaskOptions,
    Segmentation,
};
use raster::Image;

use super::error::SegformerError;

/// The whole post-processing of the logits (1×L×h×w) of a `width`×`height` original image.
/// `options` are for water, tree, building in that order.
pub fn postprocess(
    logits: Tensor<4>,
    width: usize,
    height: usize,
    options: &[MaskOptions; 3],
) -> Result<Segmentation, SegformerError> {
    if width == 0 || height == 0 {
        return Err(SegformerError::Input("the image is empty".into()));
    }
    let [b, classes, h, w] = logits.dims();
    if b != 1 {
        return Err(SegformerError::Input(format!(
            "postprocess takes the logits of one image, got a batch of {b}"
        )));
    }
    let logits = logits
        .into_data()
        .convert::<f32>()
        .try_into_vec::<f32>()
        .map_err(|e| SegformerError::Input(format!("logits are not f32: {e:?}")))?;
    if let Some(bad) = logits.iter().find(|v| !v.is_finite()) {
        return Err(SegformerError::Input(format!(
            "the network produced a non-finite logit ({bad}): corrupt weights?"
        )));
    }
    let scores = upsample_scores(&logits, classes, (w, h), (width, height));
    let probs = softmax_classes(&scores, classes);
    drop(scores);
    let pred = argmax_classes(&probs, classes);
    let [water, tree, building] =
        [0, 1, 2].map(|i| class_mask(MaskKind::ALL[i], &options[i], &probs, &pred, width, height));
    Ok(Segmentation {
        classes: Image::new(width, height, 1, pred.iter().map(|&c| c as f32).collect())?,
        water: water?,
        tree: tree?,
        building: building?,
    })
}
