//! Reading the video: opening it (with FFmpeg's diagnostics silenced), frame by frame, and the
//! hand-over between the producer and consumer threads of the passes.

use crate::error::{Error, Result};
use opencv::core::Mat;
use opencv::prelude::*;
use opencv::videoio;
use std::path::{Path, PathBuf};

/// An OpenCV error as a one-line error naming `path`.
pub(super) fn cv(path: &Path) -> impl Fn(opencv::Error) -> Error + '_ {
    move |e| Error::file(path, format!("OpenCV: {}", e.message))
}

/// `frame` scaled by `scale` with area averaging (the processing-size copy that tracking and
/// registration work on).
pub(super) fn downscaled(frame: &Mat, scale: f64, path: &Path) -> Result<Mat> {
    let mut small = Mat::default();
    opencv::imgproc::resize(
        frame,
        &mut small,
        opencv::core::Size::new(0, 0),
        scale,
        scale,
        opencv::imgproc::INTER_AREA,
    )
    .map_err(cv(path))?;
    Ok(small)
}

/// glibc's allocator, set once per process for extraction: blocks up to 32 MiB come from the
/// heap rather than from their own mappings, and up to 256 MiB of free heap is kept rather than
/// returned to the kernel. OpenCV allocates and frees buffers of several MiB in every optical
/// flow, warp and decode; with glibc's defaults (a threshold that adapts, trimming of the
/// threads' heaps) each frame's buffers were mapped and faulted in afresh (BENCHMARKS.md
/// "Extraction throughput"). Memory stays bounded: it is reused, not grown.
pub(super) fn tune_allocator() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        static ONCE: std::sync::Once = std::sync::Once::new();
        // SAFETY: mallopt only sets allocator parameters; it is called once, before the
        // extraction's threads start.
        ONCE.call_once(|| unsafe {
            libc::mallopt(libc::M_MMAP_THRESHOLD, 32 << 20);
            libc::mallopt(libc::M_TRIM_THRESHOLD, 256 << 20);
        });
    }
}

/// Full-resolution frames one pass keeps for a later one: (index within the range, frame), in
/// frame order.
pub(super) type Kept = Vec<(usize, Mat)>;

/// An open video and its size, frame rate and (reported) frame count.
pub(super) struct Video {
    pub cap: videoio::VideoCapture,
    pub path: PathBuf,
    pub w: usize,
    pub h: usize,
    pub fps: f64,
    pub count: usize,
}

/// Runs `f` with the process's stderr sent to /dev/null: FFmpeg and OpenCV print multi-line
/// diagnostics while probing corrupt files, and herdfit's errors are one line.
pub fn quietly<T>(f: impl FnOnce() -> T) -> T {
    #[cfg(unix)]
    // SAFETY: plain descriptor juggling on fd 2; restored before returning.
    unsafe {
        let saved = libc::dup(2);
        let null = libc::open(c"/dev/null".as_ptr(), libc::O_WRONLY);
        if saved >= 0 && null >= 0 {
            libc::dup2(null, 2);
            let r = f();
            libc::dup2(saved, 2);
            libc::close(null);
            libc::close(saved);
            return r;
        }
        if null >= 0 {
            libc::close(null);
        }
        if saved >= 0 {
            libc::close(saved);
        }
    }
    f()
}

/// Opens `path` as a video (errors name the file).
pub(super) fn open(path: &Path) -> Result<Video> {
    if path.is_dir() {
        return Err(Error::file(path, "is a folder, not a video file"));
    }
    if !path.is_file() {
        return Err(Error::file(path, "cannot read: no such file"));
    }
    crate::data::atomic::note_input(path);
    std::fs::File::open(path).map_err(|e| Error::file(path, format!("cannot read: {e}")))?;
    let _ = opencv::core::set_log_level(opencv::core::LogLevel::LOG_LEVEL_SILENT);
    let cap = quietly(|| videoio::VideoCapture::from_file(path.as_os_str(), videoio::CAP_FFMPEG))
        .map_err(cv(path))?;
    if !cap.is_opened().map_err(cv(path))? {
        return Err(Error::file(
            path,
            "cannot open as a video (corrupt or unknown format)",
        ));
    }
    let w = cap.get(videoio::CAP_PROP_FRAME_WIDTH).map_err(cv(path))? as usize;
    let h = cap.get(videoio::CAP_PROP_FRAME_HEIGHT).map_err(cv(path))? as usize;
    let fps = cap.get(videoio::CAP_PROP_FPS).map_err(cv(path))?;
    let count = cap
        .get(videoio::CAP_PROP_FRAME_COUNT)
        .map_err(cv(path))?
        .max(0.0) as usize;
    if w == 0 || h == 0 {
        return Err(Error::file(path, "the video has no frames of a known size"));
    }
    Ok(Video {
        cap,
        path: path.to_path_buf(),
        w,
        h,
        fps: if fps.is_finite() && fps > 0.0 {
            fps
        } else {
            25.0
        },
        count,
    })
}

impl Video {
    /// Back to frame 0 (by opening the file again).
    pub fn rewind(&mut self) -> Result<()> {
        *self = open(&self.path)?;
        Ok(())
    }

    /// Next BGR frame, or None at the end.
    pub fn next(&mut self) -> Result<Option<Mat>> {
        let mut m = Mat::default();
        let ok = quietly(|| self.cap.read(&mut m)).map_err(cv(&self.path))?;
        if !ok || m.empty() {
            return Ok(None);
        }
        if m.cols() as usize != self.w || m.rows() as usize != self.h || m.channels() != 3 {
            return Err(Error::file(
                &self.path,
                "a frame has another size or is not colour",
            ));
        }
        Ok(Some(m))
    }

    /// Reads and drops the first `first` frames; `false` when the video ends before.
    pub fn skip(&mut self, first: usize) -> Result<bool> {
        for _ in 0..first {
            if self.next()?.is_none() {
                return Ok(false);
            }
        }
        Ok(true)
    }
}

/// Hands one item of a producer thread to its consumer: `true` to go on; `false` when the stream
/// has ended (`Ok(None)`), failed (the error is passed on) or the consumer has gone.
pub(super) fn forward<T>(
    tx: &std::sync::mpsc::SyncSender<Result<T>>,
    item: Result<Option<T>>,
) -> bool {
    match item {
        Ok(Some(x)) => tx.send(Ok(x)).is_ok(),
        Ok(None) => false,
        Err(e) => {
            let _ = tx.send(Err(e));
            false
        }
    }
}
