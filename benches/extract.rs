//! Extraction throughput at 1280×720 (criterion): a synthetic overhead video of 1000 agents,
//! 50 frames through a moving camera, extracted with three CSRT anchors (stabilisation,
//! segmentation, Farneback flow, fields), with no settings at all (automatic calibration and
//! feature registration, issue #16), and as if the camera were static (no stabilisation).
//! Frames per second = 50 / time per iteration.
//!
//! `cargo bench --bench extract`

use criterion::{criterion_group, criterion_main, Criterion};
use herdfit::backend::{cpu_device, Precision};
use herdfit::data::Grid;
use herdfit::herd::params::Params;
use herdfit::herd::synth::{synthesise, SynthConfig};
use herdfit::video::extract::{extract, ExtractConfig};
use herdfit::video::{render_video, RenderConfig};
use std::time::Duration;

fn bench(c: &mut Criterion) {
    let device = cpu_device(Precision::F32).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let video = dir.path().join("hd.avi");
    let grid = Grid {
        origin: [0.0, 0.0],
        cell_size: 2.5,
        nx: 32,
        ny: 18,
    };
    let cfg = SynthConfig {
        params: Params::default(),
        agents: 1000,
        frame_count: 50,
        fps: 25.0,
        grid,
        obstacles: ndarray::Array2::zeros((18, 32)),
        seed: 2,
        heading_deg: 0.0,
        precision: Precision::F32,
        density: 0.5,
        random_headings: false,
    };
    let syn = synthesise(&cfg, &device, || {}).unwrap();
    let render = RenderConfig {
        px_per_bl: 16.0,
        body_rgb: [235, 235, 225],
        camera_motion: true,
        seed: 2,
    };
    let (_, pending) = render_video(
        &video,
        &syn.frames,
        &grid,
        &syn.clip.obstacles,
        25.0,
        &render,
        || {},
    )
    .unwrap();
    pending.commit().unwrap();
    let ex = ExtractConfig {
        grid: Some(32),
        body_length_px: Some(16.0),
        body_colour: Some([235, 235, 225]),
        anchors: vec![[850, 60, 80, 80], [850, 580, 80, 80], [950, 320, 80, 80]],
        ..ExtractConfig::default()
    };
    let mut g = c.benchmark_group("extract_1280x720");
    g.sample_size(10).measurement_time(Duration::from_secs(30));
    g.bench_function("50_frames_3_anchors", |b| {
        b.iter(|| extract(&video, &ex, None, |_, _, _| {}).unwrap())
    });
    // No settings at all: threshold, body size, grid estimated; the camera registered on the
    // background's features (issue #16).
    let auto = ExtractConfig::default();
    g.bench_function("50_frames_automatic", |b| {
        b.iter(|| extract(&video, &auto, None, |_, _, _| {}).unwrap())
    });
    let still = ExtractConfig {
        anchors: vec![],
        stabilise: false,
        ..ex.clone()
    };
    g.bench_function("50_frames_static", |b| {
        b.iter(|| extract(&video, &still, None, |_, _, _| {}).unwrap())
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
