//! The folder of `herdfit flock animate`: 3D tracks, per-bird power reduction per steady frame
//! (`savings.csv` and its sidecar), `report.json`, two PNG plots ([`super::figures`]) and
//! (feature `video`) an AVI from above ([`super::render`]), written all-or-nothing.

use super::animate::{animate, AnimateConfig, Animation, AnimationReport};
use super::extract::ShapeParams;
use crate::error::{Error, Result};
use crate::progress::Progress;
use std::path::Path;

/// Schema tag of the savings CSV's sidecar.
pub const SAVINGS_SCHEMA: &str = "herdfit.flock-savings/1";

/// The savings CSV: `frame,time,id,e,xi` (e: the bird's induced-power saving in units of a lone
/// bird's induced power, eq. 1 with C = 1; see `write_outputs`).
pub fn savings_csv(rows: &[(u64, f64, u64, f64, f64)]) -> String {
    use std::fmt::Write as _;
    let mut s = String::from("frame,time,id,e,xi\n");
    for (f, t, id, e, xi) in rows {
        let _ = writeln!(s, "{f},{t},{id},{e},{xi}");
    }
    s
}

/// Reads `shape` (a `herdfit.flock-shape/1` file), animates it and writes the folder `out`
/// (all-or-nothing): `tracks.csv`/`tracks.json`, `savings.csv`/`savings.json`, `report.json`,
/// `shapes.png`, `savings.png` and, with the `video` feature and `video`, `flock.avi`.
pub fn animate_file(
    shape: &Path,
    out: &Path,
    cfg: &AnimateConfig,
    progress: &mut dyn Progress,
) -> Result<AnimationReport> {
    let params = ShapeParams::load(shape)?;
    let anim = animate(&params, &shape.display().to_string(), cfg, progress)?;
    write_outputs(&anim, out, progress)?;
    Ok(anim.report)
}

/// Writes an animation's folder atomically.
pub fn write_outputs(anim: &Animation, out: &Path, progress: &mut dyn Progress) -> Result<()> {
    let dir = crate::data::atomic::AtomicDir::create(out)?;
    anim.tracks.save(&dir.path("tracks.csv"))?;
    dir.write("savings.csv", savings_csv(&anim.savings).as_bytes())?;
    let side = serde_json::json!({
        "schema": SAVINGS_SCHEMA,
        "columns": {
            "frame": "frame of tracks.csv",
            "time": "seconds",
            "id": "bird id of tracks.csv",
            "e": "induced-power saving e_i = Σ_j g_ij (Klotsman & Tal eq. 1 with the drag ratio C = 1; Hummel 1983): the induced power (induced drag × speed) the other birds' upwash removes from bird i, in units of the induced power of the same bird flying alone. Hummel's horseshoe-vortex model is linear and has no ceiling: e exceeds 1 where wing tips overlap (neighbours less than one wingspan apart laterally), the upwash there more than cancelling the bird's own induced drag. It is not the fraction of the bird's total flight power: that is C·e with C the induced share of its flight power at cruise (Cutts & Speakman 1994 estimate C ≈ 0.17 for pink-footed geese: 14 % of induced power, 2.4 % of total).",
      "flock mean": "report.json flock_mean_saving: e averaged over birds and steady frames, the figure field studies estimate from photographed skeins (14 %: Cutts & Speakman 1994, pink-footed geese; 36 %: Hainsworth 1987, Canada geese; both of induced power, with Lissaman & Shollenberger's model)",
            "xi": "relative power reduction ξ_i = e_i / Σ e (§5 Step 3)",
        },
        "frames": "the F steady-flight frames after the hand-over (the model assumes steady formation flight)",
    });
    dir.write(
        "savings.json",
        format!(
            "{}\n",
            serde_json::to_string_pretty(&side).map_err(|e| Error::Internal(e.to_string()))?
        )
        .as_bytes(),
    )?;
    let rep = serde_json::to_string_pretty(&anim.report)
        .map_err(|e| Error::Internal(format!("report: {e}")))?;
    dir.write("report.json", format!("{rep}\n").as_bytes())?;
    super::figures::shapes_png(&dir.path("shapes.png"), &anim.report)?;
    super::figures::savings_png(&dir.path("savings.png"), &anim.savings, anim.report.birds)?;
    #[cfg(feature = "video")]
    if anim.report.config.video {
        super::render::render(&dir.path("flock.avi"), anim, progress)?;
    }
    let _ = &progress;
    dir.commit()
}
