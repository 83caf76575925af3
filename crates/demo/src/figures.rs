//! Pictures of the demo's report: season thumbnails (the DSMs in colour over a hillshade are
//! `products`' quicklook).

use raster::Image;

/// `image` shrunk (antialiased) so that its longer side is at most `max` pixels.
pub fn thumbnail(image: &Image, max: usize) -> anyhow::Result<Image> {
    let (w, h) = image.size();
    let long = w.max(h);
    if long <= max {
        return Ok(image.clone());
    }
    let (tw, th) = ((w * max / long).max(1), (h * max / long).max(1));
    Ok(raster::resize::resize_antialias_bilinear(image, tw, th)?)
}
