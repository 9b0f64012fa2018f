//! The one MJPG AVI writer every verb's video goes through (issue #47): a temporary sibling of the
//! destination under the run's output plan, OpenCV's writer into it, and a check of the finished
//! file before it is handed on. OpenCV reports no failed write (a full disk or a file-size limit
//! truncates the file silently, issue #14), so every frame written is counted and the finished
//! file is read back: its RIFF header's size must be covered by the file and its index must hold
//! every frame; otherwise the video is refused and its temporary sibling removed.

use crate::error::{Error, Result};
use opencv::core::{Mat, Size};
use opencv::prelude::*;
use opencv::videoio;
use std::path::{Path, PathBuf};

fn cv(path: &Path) -> impl Fn(opencv::Error) -> Error + '_ {
    move |e| Error::file(path, format!("OpenCV: {}", e.message))
}

/// An MJPG AVI being written for `path`.
pub struct AviWriter {
    path: PathBuf,
    tmp: tempfile::NamedTempFile,
    writer: videoio::VideoWriter,
    frames: usize,
}

/// A finished, checked video waiting in a temporary sibling of its destination.
pub struct PendingVideo {
    path: PathBuf,
    tmp: tempfile::NamedTempFile,
}

impl PendingVideo {
    /// Renames the video into place (under the run's plan: hands it to the plan).
    pub fn commit(self) -> Result<()> {
        crate::data::atomic::persist(self.tmp, &self.path)
    }
}

impl AviWriter {
    /// Opens an MJPG AVI of `width × height` pixels at `fps` for `path`.
    pub fn create(path: &Path, fps: f64, width: i32, height: i32) -> Result<Self> {
        let tmp = crate::data::atomic::temp_sibling(path, ".avi")?;
        let fourcc = videoio::VideoWriter::fourcc('M', 'J', 'P', 'G').map_err(cv(path))?;
        let name = tmp.path().to_string_lossy().into_owned();
        let writer = videoio::VideoWriter::new(&name, fourcc, fps, Size::new(width, height), true)
            .map_err(cv(path))?;
        if !writer.is_opened().map_err(cv(path))? {
            return Err(Error::file(
                path,
                "OpenCV cannot open an MJPG AVI writer here",
            ));
        }
        Ok(AviWriter {
            path: path.to_path_buf(),
            tmp,
            writer,
            frames: 0,
        })
    }

    /// Appends one frame (BGR, the size given to [`AviWriter::create`]).
    pub fn write(&mut self, frame: &Mat) -> Result<()> {
        self.writer.write(frame).map_err(cv(&self.path))?;
        self.frames += 1;
        Ok(())
    }

    /// Closes the file and checks it; the video waits for [`PendingVideo::commit`].
    pub fn finish(mut self) -> Result<PendingVideo> {
        self.writer.release().map_err(cv(&self.path))?;
        verify(self.tmp.path(), &self.path, self.frames)?;
        Ok(PendingVideo {
            path: self.path,
            tmp: self.tmp,
        })
    }

    /// [`AviWriter::finish`] and [`PendingVideo::commit`].
    pub fn commit(self) -> Result<()> {
        self.finish()?.commit()
    }
}

/// The finished temporary AVI `tmp` must be whole and hold `frames` frames.
fn verify(tmp: &Path, path: &Path, frames: usize) -> Result<()> {
    let short = || Error::file(path, "cannot write: the video is incomplete (disk full?)");
    let len =
        std::fs::metadata(tmp).map_err(|e| Error::file(path, format!("cannot write: {e}")))?;
    // The RIFF header's size (written last, by a seek back) must be covered by the file: a write
    // that failed at the end (the index) leaves the file shorter than its header says.
    let mut head = [0u8; 8];
    let read = std::fs::File::open(tmp).and_then(|mut f| {
        use std::io::Read;
        f.read_exact(&mut head)
    });
    let riff = u32::from_le_bytes([head[4], head[5], head[6], head[7]]) as u64;
    if read.is_err() || &head[..4] != b"RIFF" || riff + 8 > len.len() {
        return Err(short());
    }
    let cap =
        videoio::VideoCapture::from_file(tmp.as_os_str().to_str().unwrap_or(""), videoio::CAP_ANY)
            .map_err(cv(path))?;
    if !cap.is_opened().map_err(cv(path))? {
        return Err(short());
    }
    let n = cap.get(videoio::CAP_PROP_FRAME_COUNT).map_err(cv(path))?;
    if n.round() as usize != frames {
        return Err(short());
    }
    Ok(())
}
