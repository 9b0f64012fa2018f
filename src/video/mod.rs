//! Video I/O through OpenCV (cargo feature `video`, on by default): rendering synthetic overhead
//! videos with known truth; extraction of clip fields from video follows.

pub mod avi;
pub mod extract;
pub mod render;

pub use avi::{AviWriter, PendingVideo};
pub use render::{camera_at, render_video, Camera, RenderConfig};
