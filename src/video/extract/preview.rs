//! Preview PNGs of an extraction: what the fields are made of, over the stabilised frame.

use super::background::{CellGrid, Geometry};
use super::decode::cv;
use crate::error::Result;
use opencv::core::{Mat, Point, Rect, Scalar};
use opencv::imgcodecs;
use opencv::imgproc;
use opencv::prelude::*;

/// Preview: the stabilised frame, herd pixels tinted red, a density heat map per cell and mean
/// velocity arrows.
pub(super) fn preview_png(
    st: &Mat,
    herd: &[u8],
    count: &[f64],
    flow: &[[f64; 2]],
    grid: &CellGrid,
    geom: &Geometry,
) -> Result<Vec<u8>> {
    let (nx, ny, cell_px) = (grid.nx, grid.ny, grid.cell_px);
    let (scale, h) = (geom.scale, geom.h);
    let fail = cv(geom.path);
    let mut img = st.try_clone().map_err(&fail)?;
    {
        let data = img.data_bytes_mut().map_err(&fail)?;
        for (p, &on) in herd.iter().enumerate() {
            if on > 0 {
                data[p * 3] = 0;
                data[p * 3 + 1] = 0;
                data[p * 3 + 2] = 255;
            }
        }
    }
    let max = count.iter().cloned().fold(0.0, f64::max).max(1.0);
    for iy in 0..ny {
        for ix in 0..nx {
            let c = iy * nx + ix;
            let x0 = ix as f64 * cell_px * scale;
            let y1 = (h as f64 - iy as f64 * cell_px) * scale;
            let y0 = (h as f64 - (iy + 1) as f64 * cell_px) * scale;
            let r = Rect::new(
                x0 as i32,
                y0.max(0.0) as i32,
                (cell_px * scale) as i32,
                (y1 - y0.max(0.0)) as i32,
            );
            let a = count[c] / max;
            if a > 0.0 {
                imgproc::rectangle(
                    &mut img,
                    r,
                    Scalar::new(0.0, 255.0 * a, 255.0 * (1.0 - a), 0.0),
                    1,
                    imgproc::LINE_8,
                    0,
                )
                .map_err(&fail)?;
                let f = flow[c];
                let l = (f[0] * f[0] + f[1] * f[1]).sqrt();
                if l > 1e-9 {
                    let cx = x0 + cell_px * scale / 2.0;
                    let cy = (y0 + y1) / 2.0;
                    let k = cell_px * scale * 0.45 / l;
                    imgproc::arrowed_line(
                        &mut img,
                        Point::new(cx as i32, cy as i32),
                        Point::new((cx + f[0] * k) as i32, (cy - f[1] * k) as i32),
                        Scalar::new(255.0, 255.0, 0.0, 0.0),
                        1,
                        imgproc::LINE_AA,
                        0,
                        0.3,
                    )
                    .map_err(&fail)?;
                }
            }
        }
    }
    let mut buf = opencv::core::Vector::<u8>::new();
    imgcodecs::imencode(".png", &img, &mut buf, &opencv::core::Vector::new()).map_err(&fail)?;
    Ok(buf.to_vec())
}
