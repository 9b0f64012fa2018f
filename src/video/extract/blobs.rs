//! Connected components of a herd mask ("blobs"), with the area and axes of each: what the
//! calibration measures bodies from ([`super::calibrate`], [`super::body_size`]) and what the
//! field pass removes specks with ([`super::fields`]).

/// Smallest component (processing pixels) the body-size estimate looks at.
pub(super) const MIN_COMPONENT: usize = 4;

/// One connected component of a herd mask.
#[derive(Clone, Copy, Debug)]
pub(super) struct Blob {
    /// Pixels.
    pub area: f64,
    /// Full major and minor axes of the ellipse with the same second moments (pixels).
    pub major: f64,
    pub minor: f64,
}

/// The 8-connected components of `mask` (non-zero = on), `w` pixels wide, of at least
/// `min_area` pixels; with `keep`, the mask is rewritten without the smaller ones.
pub(super) fn blobs(mask: &mut [u8], w: usize, min_area: usize, keep: bool) -> Vec<Blob> {
    let h = mask.len() / w.max(1);
    let mut seen = vec![false; mask.len()];
    let mut out = Vec::new();
    let mut stack = Vec::new();
    let mut members = Vec::new();
    for start in 0..mask.len() {
        if mask[start] == 0 || seen[start] {
            continue;
        }
        seen[start] = true;
        stack.push(start);
        members.clear();
        let (mut sx, mut sy, mut sxx, mut syy, mut sxy) = (0.0, 0.0, 0.0, 0.0, 0.0);
        while let Some(p) = stack.pop() {
            members.push(p);
            let (x, y) = ((p % w) as f64, (p / w) as f64);
            sx += x;
            sy += y;
            sxx += x * x;
            syy += y * y;
            sxy += x * y;
            let (px, py) = (p % w, p / w);
            for dy in -1i64..=1 {
                for dx in -1i64..=1 {
                    let (nx, ny) = (px as i64 + dx, py as i64 + dy);
                    if nx < 0 || ny < 0 || nx >= w as i64 || ny >= h as i64 {
                        continue;
                    }
                    let q = ny as usize * w + nx as usize;
                    if mask[q] != 0 && !seen[q] {
                        seen[q] = true;
                        stack.push(q);
                    }
                }
            }
        }
        let n = members.len() as f64;
        if members.len() < min_area {
            if keep {
                for &p in &members {
                    mask[p] = 0;
                }
            }
            continue;
        }
        // Covariance of the pixel centres (+1/12 for the pixel's own extent).
        let (mx, my) = (sx / n, sy / n);
        let cxx = sxx / n - mx * mx + 1.0 / 12.0;
        let cyy = syy / n - my * my + 1.0 / 12.0;
        let cxy = sxy / n - mx * my;
        let tr = cxx + cyy;
        let disc = ((cxx - cyy).powi(2) / 4.0 + cxy * cxy).sqrt();
        let (l1, l2) = (tr / 2.0 + disc, (tr / 2.0 - disc).max(0.0));
        out.push(Blob {
            area: n,
            major: 4.0 * l1.sqrt(),
            minor: 4.0 * l2.sqrt(),
        });
    }
    out
}
