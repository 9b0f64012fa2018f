//! Open boundaries (paper §7.1.3, issue #46): a stream of animals through a corridor keeps the
//! video's count; entries appear only at the entry gates, outside the view; a closed clip runs as
//! before.

use herdfit::data::boundary::{Gate, Gates, Side};
use herdfit::data::{ClipFields, ClipMeta, ClipSpeed, Grid};
use herdfit::herd::boundary::{gates_of_clip, Agents, BoundaryChoice, Stream};
use herdfit::herd::params::{Params, SpeedModel};
use herdfit::herd::validate::{validate, ValidateConfig};
use ndarray::{Array2, Array3, Array4};

/// A corridor clip: `frames` frames at 10 fps of a 20 × 8 grid of 1-BL cells, rows 2..6 holding
/// `rho` agents/BL² in every column, all moving at `vx` BL/s (a stream from right to left when
/// `vx` < 0; standing when 0).
fn corridor(frames: usize, rho: f32, vx: f32) -> ClipFields {
    let (nx, ny) = (20, 8);
    let mut d = Array3::zeros((frames, ny, nx));
    let mut v = Array4::zeros((frames, ny, nx, 2));
    let mut var = Array3::zeros((frames, ny, nx));
    for f in 0..frames {
        for iy in 2..6 {
            for ix in 0..nx {
                d[[f, iy, ix]] = rho;
                v[[f, iy, ix, 0]] = vx;
                var[[f, iy, ix]] = 0.01;
            }
        }
    }
    ClipFields {
        meta: ClipMeta::of_grid(
            &Grid {
                origin: [0.0, 0.0],
                cell_size: 1.0,
                nx,
                ny,
            },
            10.0,
            frames,
            ClipSpeed {
                mean: vx.abs().max(1.0) as f64,
                std: 0.2,
                density_table: vec![],
            },
        ),
        density: d,
        velocity: v,
        dir_variance: var,
        obstacles: Array2::zeros((ny, nx)),
    }
}

fn gate(ix: usize, iy: usize, side: Side) -> Gate {
    Gate {
        cell: [ix, iy],
        side,
    }
}

#[test]
fn a_stream_has_entries_upstream_and_exits_downstream() {
    let clip = corridor(50, 0.6, -3.0);
    let g = gates_of_clip(&clip);
    assert_eq!(
        g.entries,
        (2..6)
            .map(|iy| gate(19, iy, Side::Right))
            .collect::<Vec<_>>()
    );
    assert_eq!(
        g.exits,
        (2..6).map(|iy| gate(0, iy, Side::Left)).collect::<Vec<_>>()
    );
}

#[test]
fn a_standing_herd_is_a_closed_clip() {
    assert!(!gates_of_clip(&corridor(50, 0.6, 0.0)).is_open());
}

/// The per-frame count inside the view of a validation run of `clip` with the neutral set
/// through `boundary`, and the video's.
fn counts(clip: &ClipFields, boundary: BoundaryChoice) -> (Vec<f64>, Vec<f64>) {
    let cfg = ValidateConfig {
        split: 0.0,
        seeds: 1,
        boundary,
        ..Default::default()
    };
    let sets = vec![("neutral".to_string(), Params::neutral())];
    let (report, runs) = validate(clip, "corridor", &sets, &cfg, || {}).unwrap();
    let sim: Vec<f64> = (0..clip.frames())
        .map(|k| runs[0][0].fields.count(k))
        .collect();
    let video: Vec<f64> = (0..clip.frames()).map(|f| clip.count(f)).collect();
    if let Some(p) = &report.sets[0].population {
        assert_eq!(p.count, sim, "the report's count is the run's");
    }
    (sim, video)
}

#[test]
fn a_stream_keeps_its_count_over_500_frames_in_validate() {
    // 20 × 4 cells × 0.5 = 40 animals in view, each crossing the 20-BL corridor in 6.7 s while the
    // run lasts 50 s: the whole herd is replaced about 7 times.
    let clip = corridor(500, 0.5, -3.0);
    let (sim, video) = counts(&clip, BoundaryChoice::Auto);
    assert_eq!(video[0], 40.0);
    for (f, (s, v)) in sim.iter().zip(&video).enumerate() {
        assert!(
            (s - v).abs() <= 0.1 * v,
            "frame {f}: {s} agents in view, the video holds {v}"
        );
    }
    // Closed, the same stream drains out of the corridor within its crossing time.
    let (closed, _) = counts(&clip, BoundaryChoice::Closed);
    assert!(closed[499] < 0.1 * 40.0, "closed: {} left", closed[499]);
}

#[test]
fn entries_appear_only_outside_the_grid_at_entry_gates_heading_in() {
    let clip = corridor(20, 0.5, -3.0);
    let gates = Gates::new(vec![gate(19, 3, Side::Right)], vec![gate(0, 3, Side::Left)]);
    let speed = SpeedModel {
        mean: 3.0,
        std: 0.2,
        max: 6.0,
        ..SpeedModel::default()
    };
    let mut s = Stream::new(&clip, &gates, speed, 7, 100);
    let (mut pos, mut head, mut sp, mut ids) = (vec![], vec![], vec![], vec![]);
    let mut a = Agents {
        pos: &mut pos,
        head: &mut head,
        speed: &mut sp,
        ids: &mut ids,
    };
    // Nobody in view: the whole count (40) enters.
    assert!(s.apply(5, 0.1, &mut a));
    assert_eq!(a.ids.len(), 40);
    assert_eq!(s.crossings.entered, 40);
    assert_eq!(a.ids[0], 100, "new ids continue from next_id");
    for (p, h) in a.pos.iter().zip(a.head.iter()) {
        assert!(p[0] >= 20.0, "an entrant stands inside the view at {p:?}");
        assert!(p[0] <= 20.0 + 0.1 * 6.0, "too far out: {p:?}");
        assert!((3.0..4.0).contains(&p[1]), "not at its gate's edge: {p:?}");
        assert!(h[0] < -0.19, "heading {h:?} does not point in");
    }
    // Leaving: an agent past the left edge heading out is removed (counted on the left); one
    // outside the right edge heading in (an entrant) stays.
    a.pos[0] = [-0.1, 3.5];
    a.head[0] = [-1.0, 0.0];
    assert_eq!(s.leave(&mut a), 1);
    assert_eq!(s.crossings.left, [1, 0, 0, 0]);
    assert_eq!(a.ids.len(), 39);
}

#[test]
fn the_excess_over_the_videos_count_leaves_from_the_exit_cells_nearest_the_edge_first() {
    // The corridor's video holds 40 animals; the run holds 43: 36 in the middle of the view,
    // 5 in the exit cell (0, 3) heading out at x = 0.1 … 0.9, one there heading in, and one
    // heading out in cell (0, 6), which is no exit gate.
    let clip = corridor(20, 0.5, -3.0);
    let gates = Gates::new(vec![gate(19, 3, Side::Right)], vec![gate(0, 3, Side::Left)]);
    let mut pos: Vec<[f64; 2]> = (0..36).map(|i| [5.0 + 0.25 * i as f64, 3.5]).collect();
    pos.extend([[0.9, 3.2], [0.5, 3.4], [0.1, 3.6], [0.3, 3.5], [0.7, 3.3]]);
    let mut head = vec![[-1.0, 0.0]; pos.len()];
    pos.extend([[0.05, 3.5], [0.2, 6.5]]);
    head.extend([[1.0, 0.0], [-1.0, 0.0]]);
    let mut sp = vec![3.0; pos.len()];
    let mut ids: Vec<u64> = (0..pos.len() as u64).collect();
    assert_eq!(ids.len(), 43);
    let mut s = Stream::new(&clip, &gates, SpeedModel::default(), 3, 100);
    let mut a = Agents {
        pos: &mut pos,
        head: &mut head,
        speed: &mut sp,
        ids: &mut ids,
    };
    // 43 − 40 = 3 leave early: the three heading out nearest the left edge (ids 38, 39, 37).
    assert_eq!(s.trim(5, &mut a), 3);
    assert_eq!(a.ids.len(), 40);
    for gone in [37, 38, 39] {
        assert!(!a.ids.contains(&gone), "agent {gone} at the edge stayed");
    }
    for kept in [36, 40, 41, 42] {
        assert!(a.ids.contains(&kept), "agent {kept} was removed");
    }
    assert_eq!(s.crossings.early, 3);
    assert_eq!(s.crossings.left, [3, 0, 0, 0]);
    // At the video's count, nobody more leaves early.
    assert_eq!(s.trim(5, &mut a), 0);
    assert_eq!(a.ids.len(), 40);
}

#[test]
fn a_count_that_falls_faster_than_the_stream_drains_is_followed_in_validate() {
    // The video's count falls by 12.5 % in one frame (40 → 35: a detection drop, no flux) and
    // stays there; the run follows it within ±10 % in every frame.
    let mut clip = corridor(200, 0.5, -3.0);
    clip.density
        .slice_mut(ndarray::s![100.., 2..6, ..])
        .fill(0.4375);
    let (sim, video) = counts(&clip, BoundaryChoice::Auto);
    assert_eq!((video[99], video[100]), (40.0, 35.0));
    for (f, (s, v)) in sim.iter().zip(&video).enumerate() {
        assert!(
            (s - v).abs() <= 0.1 * v,
            "frame {f}: {s} agents in view, the video holds {v}"
        );
    }
}

#[test]
fn a_boundary_file_overrides_the_derived_gates_and_is_checked() {
    let dir = tempfile::tempdir().unwrap();
    let clip = corridor(20, 0.6, -3.0);
    let p = dir.path().join("b.json");
    Gates::new(vec![gate(19, 2, Side::Right)], vec![])
        .save(&p)
        .unwrap();
    let g = BoundaryChoice::File(p.clone()).gates(&clip).unwrap();
    assert_eq!(g.entries, vec![gate(19, 2, Side::Right)]);
    std::fs::write(
        &p,
        r#"{"schema": "herdfit.boundary/1", "entries": [{"cell": [5, 2], "side": "right"}], "exits": []}"#,
    )
    .unwrap();
    let e = BoundaryChoice::File(p.clone())
        .gates(&clip)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("b.json") && e.contains("entries[0]") && e.contains("not on the Right side"),
        "{e}"
    );
}

/// A caller that asks validate to stop (the Python package's Ctrl-C) gets `Error::Interrupted`
/// after the seed in progress, and no further seed is run.
#[test]
fn validate_stops_after_the_seed_in_progress_when_asked() {
    let clip = corridor(30, 0.6, -2.0);
    let cfg = ValidateConfig {
        split: 0.5,
        seeds: 4,
        ..Default::default()
    };
    let sets = vec![("neutral".to_string(), Params::neutral())];
    let mut seeds_run = 0;
    let r = validate(&clip, "corridor", &sets, &cfg, || {
        seeds_run += 1;
        Err::<(), _>(herdfit::error::Error::Interrupted)
    });
    assert!(matches!(r, Err(herdfit::error::Error::Interrupted)));
    assert_eq!(seeds_run, 1, "no seed after the interrupt");
}
