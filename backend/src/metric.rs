//! How far an image is from another: the error metric of the renderer's
//! tests and of the studies (`parallax bench`). Images are premultiplied
//! linear RGBA (docs/design.md "What a pixel means"); every channel counts
//! alike, and PSNR takes a peak of 1.

/// The difference of an image from a reference.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ImageError {
    /// Root mean square over every channel of every pixel.
    pub rmse: f64,
    /// The largest absolute difference of any channel.
    pub max_abs: f64,
    /// Peak signal-to-noise ratio in dB, peak 1 (RMSE floored at 1e-12, so
    /// equal images give 240 dB rather than infinity).
    pub psnr_db: f64,
}

/// The error of `img` against `reference`, pixel by pixel (the shorter of
/// the two decides how many pixels are compared).
pub fn image_error(img: &[[f32; 4]], reference: &[[f64; 4]]) -> ImageError {
    let mut sq = 0.0;
    let mut max_abs = 0f64;
    for (a, b) in img.iter().zip(reference) {
        for c in 0..4 {
            let d = a[c] as f64 - b[c];
            sq += d * d;
            max_abs = max_abs.max(d.abs());
        }
    }
    let rmse = (sq / (4 * img.len().max(1)) as f64).sqrt();
    ImageError {
        rmse,
        max_abs,
        psnr_db: -20.0 * rmse.max(1e-12).log10(),
    }
}

/// A rendered image as a reference for another (f32 → f64).
pub fn as_reference(img: &[[f32; 4]]) -> Vec<[f64; 4]> {
    img.iter().map(|p| p.map(f64::from)).collect()
}

/// The fraction of pixels in which some channel of `a` and `b` differs by
/// more than `tolerance` (1/255: a difference a PNG can show).
pub fn pixels_off(a: &[[f32; 4]], b: &[[f32; 4]], tolerance: f32) -> f64 {
    let off = a
        .iter()
        .zip(b)
        .filter(|(p, q)| (0..4).any(|c| (p[c] - q[c]).abs() > tolerance))
        .count();
    off as f64 / a.len().max(1) as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn equal_images_have_no_error() {
        let img = vec![[0.25f32, 0.5, 0.75, 1.0]; 7];
        let e = image_error(&img, &as_reference(&img));
        assert_eq!((e.rmse, e.max_abs), (0.0, 0.0));
        assert_eq!(e.psnr_db, 240.0);
        assert_eq!(pixels_off(&img, &img, 1.0 / 255.0), 0.0);
    }

    #[test]
    fn one_channel_off_by_a_tenth() {
        let a = vec![[0.0f32; 4]; 4];
        let mut b = a.clone();
        b[1][2] = 0.1;
        let e = image_error(&b, &as_reference(&a));
        // One of 16 channels off by 0.1: RMSE 0.1/4.
        assert!((e.rmse - 0.025).abs() < 1e-9, "{e:?}");
        assert!((e.max_abs - 0.1).abs() < 1e-7, "{e:?}");
        assert!((e.psnr_db - 32.0412).abs() < 1e-3, "{e:?}");
        assert_eq!(pixels_off(&a, &b, 1.0 / 255.0), 0.25);
        assert_eq!(pixels_off(&a, &b, 0.2), 0.0);
    }
}
