//! Frame sources: a directory of PNG/JPEG frames (natural order), a YUV4MPEG2 (`.y4m`) file or
//! `-` for y4m on stdin, and any other video through an `ffmpeg` subprocess that decodes to y4m on
//! a pipe (parsed by the same reader).
//!
//! Every frame comes out as RGB8. Errors name the source and the frame (0-based index and, for
//! image directories, the file). With `skip_bad_frames`, corrupt frames and frames of another
//! size are skipped and reported by [`FrameSource::skipped`].
//!
//! Live sources (a camera device such as `/dev/video0`, always live, or any stream opened with
//! [`FrameOptions::live`]) are read by a thread that keeps only the newest frame: a tracker slower
//! than the camera drops frames instead of falling behind, and [`LiveStats`] counts them.

use std::io::{BufRead, BufReader, Read, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::time::Duration;

use image::RgbImage;

use crate::error::{Error, Result};

/// Default frame rate when the source has none (image directories) and `--fps` is not given.
pub const DEFAULT_FPS: f64 = 30.0;

/// One decoded frame.
#[derive(Clone, Debug)]
pub struct Frame {
    /// 0-based index in the source (skipped frames keep their index).
    pub index: usize,
    /// Time in seconds from the first frame (index / fps).
    pub time: f64,
    /// The pixels.
    pub image: RgbImage,
}

/// Options of [`FrameSource::open`].
#[derive(Clone, Debug, Default)]
pub struct FrameOptions {
    /// Override of the frame rate.
    pub fps: Option<f64>,
    /// Skip corrupt frames and frames of another size instead of failing.
    pub skip_bad_frames: bool,
    /// Read the stream live: keep only the newest frame and drop the ones the tracker has no
    /// time for (camera devices are always live; image directories cannot be).
    pub live: bool,
}

enum Inner {
    Dir { files: Vec<PathBuf>, next: usize },
    Y4m(Box<Y4mReader>, Option<Ffmpeg>),
    Live(Live),
}

/// Counters of a live source, shared with whoever displays them while the tracker runs.
#[derive(Debug, Default)]
pub struct LiveStats {
    received: AtomicUsize,
    dropped: AtomicUsize,
}

impl LiveStats {
    /// Frames that arrived from the source so far.
    pub fn received(&self) -> usize {
        self.received.load(Ordering::Relaxed)
    }

    /// Frames dropped so far: a newer frame arrived before the tracker took the previous one.
    pub fn dropped(&self) -> usize {
        self.dropped.load(Ordering::Relaxed)
    }
}

/// What the reader thread of a live source hands over.
#[derive(Default)]
struct LiveSlot {
    /// The newest frame not yet taken (index in the source, pixels).
    newest: Option<(usize, RgbImage)>,
    /// The stream ended: cleanly (`Ok`) or with the message of a broken frame.
    end: Option<std::result::Result<(), String>>,
}

#[derive(Default)]
struct LiveShared {
    slot: Mutex<LiveSlot>,
    ready: Condvar,
    stats: Arc<LiveStats>,
}

/// A y4m stream read by its own thread, newest frame wins.
struct Live {
    shared: Arc<LiveShared>,
    child: Option<Ffmpeg>,
    taken: usize,
}

impl Live {
    fn start(mut reader: Y4mReader, child: Option<Ffmpeg>) -> Self {
        let shared = Arc::new(LiveShared::default());
        let theirs = Arc::clone(&shared);
        // The thread ends at the end of the stream, or when the decoder is killed on drop; a
        // thread blocked on stdin ends with the process.
        std::thread::spawn(move || {
            loop {
                let index = reader.frames_read;
                let got = reader.read_frame();
                let Ok(mut slot) = theirs.slot.lock() else {
                    return;
                };
                match got {
                    Ok(Some(img)) => {
                        theirs.stats.received.fetch_add(1, Ordering::Relaxed);
                        if slot.newest.replace((index, img)).is_some() {
                            theirs.stats.dropped.fetch_add(1, Ordering::Relaxed);
                        }
                    }
                    Ok(None) => slot.end = Some(Ok(())),
                    Err(msg) => slot.end = Some(Err(format!("frame {index}: {msg}"))),
                }
                let done = slot.end.is_some();
                drop(slot);
                theirs.ready.notify_one();
                if done {
                    return;
                }
            }
        });
        Self {
            shared,
            child,
            taken: 0,
        }
    }

    /// The newest frame, waiting for one; `None` at the end of the stream.
    fn next(&mut self, name: &Path) -> Result<Option<(usize, RgbImage)>> {
        let poisoned = || Error::invalid(name, "the frame reader thread failed");
        let mut slot = self.shared.slot.lock().map_err(|_| poisoned())?;
        loop {
            if let Some(f) = slot.newest.take() {
                self.taken += 1;
                return Ok(Some(f));
            }
            match slot.end.take() {
                Some(Ok(())) => {
                    drop(slot);
                    if let Some(c) = self.child.as_mut() {
                        c.finish(name, self.shared.stats.received(), false)?;
                    }
                    if self.taken == 0 {
                        return Err(Error::invalid(
                            name,
                            "no frames: the y4m stream ends after its header",
                        ));
                    }
                    return Ok(None);
                }
                Some(Err(msg)) => {
                    drop(slot);
                    if let Some(c) = self.child.as_mut() {
                        c.stop();
                    }
                    return Err(Error::invalid(name, msg));
                }
                None => {}
            }
            slot = self
                .shared
                .ready
                .wait_timeout(slot, Duration::from_millis(500))
                .map_err(|_| poisoned())?
                .0;
        }
    }
}

impl Drop for Live {
    fn drop(&mut self) {
        if let Some(child) = &mut self.child {
            child.stop();
        }
    }
}

/// Whether `input` names a camera device that ffmpeg reads through Video4Linux2.
pub fn is_capture_device(input: &Path) -> bool {
    cfg!(target_os = "linux")
        && input
            .to_str()
            .is_some_and(|s| s.starts_with("/dev/video") && s.len() > "/dev/video".len())
}

/// A sequence of frames from a directory, a y4m stream or ffmpeg.
pub struct FrameSource {
    inner: Inner,
    name: PathBuf,
    fps: f64,
    skip_bad: bool,
    size: Option<(u32, u32)>,
    skipped: Vec<(usize, String)>,
}

/// The most pixels a y4m frame may have (8K UHD): larger headers are refused before a frame
/// buffer is allocated.
pub const MAX_FRAME_PIXELS: usize = 7680 * 4320;

/// How to install ffmpeg, for messages.
pub const FFMPEG_HINT: &str = "ffmpeg is not installed (or not on PATH); install it \
(Debian/Ubuntu: `sudo apt-get install ffmpeg`, Fedora: `sudo dnf install ffmpeg`, macOS: \
`brew install ffmpeg`, Windows: `winget install ffmpeg`), or convert the video to a directory of \
PNG frames or a .y4m file";

impl FrameSource {
    /// Opens `input`: `-` (y4m on stdin), a directory of PNG/JPEG images, a `.y4m` file, or any
    /// other video file through ffmpeg.
    pub fn open(input: &Path, opts: &FrameOptions) -> Result<Self> {
        if let Some(f) = opts.fps
            && !(f.is_finite() && f > 0.0)
        {
            return Err(Error::Config(format!("--fps must be positive, got {f}")));
        }
        let device = is_capture_device(input);
        let (inner, fps) = if input.as_os_str() == "-" {
            let r = Y4mReader::new(Box::new(BufReader::new(std::io::stdin())), input)?;
            let fps = r.fps;
            (Inner::Y4m(Box::new(r), None), fps)
        } else if input.is_dir() {
            if opts.live {
                return Err(Error::invalid(
                    input,
                    "a directory of images cannot be read live: give a camera device, a video \
                     or `-` for a y4m stream",
                ));
            }
            (
                Inner::Dir {
                    files: list_images(input)?,
                    next: 0,
                },
                None,
            )
        } else if !device && !input.exists() {
            return Err(Error::read(
                input,
                std::io::Error::new(std::io::ErrorKind::NotFound, "no such file or directory"),
            ));
        } else if input
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("y4m"))
        {
            let f = std::fs::File::open(input).map_err(|e| Error::read(input, e))?;
            let r = Y4mReader::new(Box::new(BufReader::new(f)), input)?;
            let fps = r.fps;
            (Inner::Y4m(Box::new(r), None), fps)
        } else {
            let (r, child) = spawn_ffmpeg(input, device)?;
            let fps = r.fps;
            (Inner::Y4m(Box::new(r), Some(child)), fps)
        };
        let inner = match inner {
            Inner::Y4m(r, child) if opts.live || device => Inner::Live(Live::start(*r, child)),
            other => other,
        };
        Ok(Self {
            inner,
            name: input.to_path_buf(),
            fps: opts.fps.or(fps).unwrap_or(DEFAULT_FPS),
            skip_bad: opts.skip_bad_frames,
            size: None,
            skipped: Vec::new(),
        })
    }

    /// Frames per second (the source's, the override, or [`DEFAULT_FPS`]).
    pub fn fps(&self) -> f64 {
        self.fps
    }

    /// Number of frames when known in advance (image directories).
    pub fn len_hint(&self) -> Option<usize> {
        match &self.inner {
            Inner::Dir { files, .. } => Some(files.len()),
            Inner::Y4m(..) | Inner::Live(_) => None,
        }
    }

    /// The counters of a live source (`None` when the source is not live).
    pub fn live_stats(&self) -> Option<Arc<LiveStats>> {
        match &self.inner {
            Inner::Live(l) => Some(Arc::clone(&l.shared.stats)),
            Inner::Dir { .. } | Inner::Y4m(..) => None,
        }
    }

    /// Frames skipped so far (index, reason).
    pub fn skipped(&self) -> &[(usize, String)] {
        &self.skipped
    }

    /// The input's path (`-` for stdin).
    pub fn name(&self) -> &Path {
        &self.name
    }

    /// The input directory of an image-directory source.
    pub fn directory(&self) -> Option<&Path> {
        match self.inner {
            Inner::Dir { .. } => Some(&self.name),
            Inner::Y4m(..) | Inner::Live(_) => None,
        }
    }

    /// The next frame, `None` at the end.
    pub fn next_frame(&mut self) -> Result<Option<Frame>> {
        loop {
            let (index, got) = match &mut self.inner {
                Inner::Dir { files, next } => {
                    let Some(file) = files.get(*next) else {
                        return Ok(None);
                    };
                    let index = *next;
                    *next += 1;
                    let img = image::open(file).map(|i| i.to_rgb8()).map_err(|e| {
                        (
                            format!(
                                "frame {index} ({}): corrupt or unreadable image: {e}",
                                file.display()
                            ),
                            true,
                        )
                    });
                    (index, img)
                }
                Inner::Y4m(r, child) => {
                    let index = r.frames_read;
                    match r.read_frame() {
                        Ok(Some(img)) => (index, Ok(img)),
                        Ok(None) => {
                            if let Some(c) = child.as_mut() {
                                c.finish(&self.name, index, self.skip_bad)?;
                            }
                            if index == 0 {
                                return Err(Error::invalid(
                                    &self.name,
                                    "no frames: the y4m stream ends after its header",
                                ));
                            }
                            return Ok(None);
                        }
                        Err(msg) => {
                            // A truncated stream cannot be resynchronised: always an error.
                            if let Some(c) = child.as_mut() {
                                c.stop();
                            }
                            return Err(Error::invalid(
                                &self.name,
                                format!("frame {index}: {msg}"),
                            ));
                        }
                    }
                }
                Inner::Live(live) => match live.next(&self.name)? {
                    Some((index, img)) => (index, Ok(img)),
                    None => return Ok(None),
                },
            };
            let img = match got {
                Ok(img) => img,
                Err((msg, _)) => {
                    if self.skip_bad {
                        self.skipped.push((index, msg));
                        continue;
                    }
                    return Err(Error::invalid(&self.name, msg));
                }
            };
            let dims = img.dimensions();
            match self.size {
                None => self.size = Some(dims),
                Some(s) if s != dims => {
                    let msg = format!(
                        "frame {index}{}: size {}×{} differs from the first frame's {}×{}",
                        self.frame_file(index)
                            .map(|f| format!(" ({})", f.display()))
                            .unwrap_or_default(),
                        dims.0,
                        dims.1,
                        s.0,
                        s.1
                    );
                    if self.skip_bad {
                        self.skipped.push((index, msg));
                        continue;
                    }
                    return Err(Error::invalid(&self.name, msg));
                }
                Some(_) => {}
            }
            return Ok(Some(Frame {
                index,
                time: index as f64 / self.fps,
                image: img,
            }));
        }
    }

    fn frame_file(&self, index: usize) -> Option<&Path> {
        match &self.inner {
            Inner::Dir { files, .. } => files.get(index).map(PathBuf::as_path),
            Inner::Y4m(..) | Inner::Live(_) => None,
        }
    }
}

impl Drop for FrameSource {
    fn drop(&mut self) {
        if let Inner::Y4m(_, Some(child)) = &mut self.inner {
            child.stop();
        }
    }
}

/// The PNG/JPEG files of a directory in natural order.
pub fn list_images(dir: &Path) -> Result<Vec<PathBuf>> {
    let rd = std::fs::read_dir(dir).map_err(|e| Error::read(dir, e))?;
    let mut files = Vec::new();
    for entry in rd {
        let entry = entry.map_err(|e| Error::read(dir, e))?;
        let p = entry.path();
        let ok = p.extension().and_then(|e| e.to_str()).is_some_and(|e| {
            ["png", "jpg", "jpeg"]
                .iter()
                .any(|x| e.eq_ignore_ascii_case(x))
        });
        if ok && p.is_file() {
            files.push(p);
        }
    }
    if files.is_empty() {
        return Err(Error::invalid(
            dir,
            "no frames: the directory has no .png, .jpg or .jpeg files",
        ));
    }
    files.sort_by(|a, b| {
        let a = a
            .file_name()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        let b = b
            .file_name()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        natord::compare(&a, &b)
    });
    Ok(files)
}

fn spawn_ffmpeg(input: &Path, device: bool) -> Result<(Y4mReader, Ffmpeg)> {
    let mut cmd = Command::new("ffmpeg");
    cmd.args(["-hide_banner", "-loglevel", "error", "-nostdin"]);
    if device {
        // A camera: Video4Linux2, without buffering frames ahead.
        cmd.args(["-f", "v4l2", "-fflags", "nobuffer"]);
    }
    let mut child = cmd
        .arg("-i")
        .arg(input)
        .args([
            "-f",
            "yuv4mpegpipe",
            "-pix_fmt",
            "yuv444p",
            "-color_range",
            "pc",
            "-strict",
            "-1",
            "-",
        ])
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|e| {
            if e.kind() == std::io::ErrorKind::NotFound {
                Error::invalid(input, FFMPEG_HINT)
            } else {
                Error::read(input, e)
            }
        })?;
    let Some(out) = child.stdout.take() else {
        return Err(Error::invalid(input, "ffmpeg: no output pipe"));
    };
    let mut child = Ffmpeg::new(child);
    match Y4mReader::new(Box::new(BufReader::new(out)), input) {
        Ok(r) => Ok((r, child)),
        Err(e) => {
            let _ = child.child.kill();
            let status = child.child.wait();
            let msg = child.errors();
            if msg.trim().is_empty() {
                Err(e)
            } else {
                let code = status.ok().and_then(|s| s.code()).unwrap_or(-1);
                Err(Error::invalid(
                    input,
                    format!("ffmpeg cannot decode it (exit {code}): {}", msg.trim()),
                ))
            }
        }
    }
}

/// A running ffmpeg decoder and the thread that collects its error output (drained as it
/// comes, so that a stream of decoding errors cannot fill the pipe and stall the frames).
struct Ffmpeg {
    child: Child,
    errors: Option<std::thread::JoinHandle<String>>,
}

impl Ffmpeg {
    fn new(mut child: Child) -> Self {
        let errors = child.stderr.take().map(|mut s| {
            std::thread::spawn(move || {
                let mut msg = String::new();
                let _ = s.read_to_string(&mut msg);
                msg
            })
        });
        Self { child, errors }
    }

    /// What ffmpeg wrote to its error output (after it exited).
    fn errors(&mut self) -> String {
        self.errors
            .take()
            .and_then(|h| h.join().ok())
            .unwrap_or_default()
    }

    fn stop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }

    /// At the end of the stream after `frames` frames: an error when ffmpeg failed, or when it
    /// reported decoding errors (a video cut short or damaged decodes "successfully" up to the
    /// break), unless `tolerate` (skipping bad frames was asked for).
    fn finish(&mut self, input: &Path, frames: usize, tolerate: bool) -> Result<()> {
        let status = self.child.wait().map_err(|e| Error::read(input, e))?;
        let msg = self.errors();
        let first: Vec<&str> = msg
            .lines()
            .filter(|l| !l.trim().is_empty())
            .take(3)
            .collect();
        if !status.success() {
            return Err(Error::invalid(
                input,
                format!("ffmpeg failed after {frames} frames: {}", first.join("; ")),
            ));
        }
        if !first.is_empty() && !tolerate {
            return Err(Error::invalid(
                input,
                format!(
                    "ffmpeg reported decoding errors, so the video is cut short or damaged; \
                     {frames} frames were decoded: {}",
                    first.join("; ")
                ),
            ));
        }
        Ok(())
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Chroma {
    C420,
    C422,
    C444,
    Mono,
}

/// A YUV4MPEG2 stream reader (8-bit 4:2:0, 4:2:2, 4:4:4 and mono), converting to RGB8 with
/// BT.601 coefficients (limited range unless the header says `XCOLORRANGE=FULL`).
pub struct Y4mReader {
    r: Box<dyn BufRead + Send>,
    width: usize,
    height: usize,
    chroma: Chroma,
    full_range: bool,
    /// Frame rate from the header's `F` parameter.
    pub fps: Option<f64>,
    frames_read: usize,
    buf: Vec<u8>,
    /// The conversion's tables, made at the first frame.
    tables: Option<Box<Ycc>>,
    /// Every pixel's chroma terms (R, G, B) of one row ([`ChromaTerms`]).
    terms: [Vec<u32>; 3],
    /// One row of R, G and B, before they are interleaved.
    planes: [Vec<u8>; 3],
}

impl Y4mReader {
    /// Reads the stream header; `name` is used in messages.
    pub fn new(mut r: Box<dyn BufRead + Send>, name: &Path) -> Result<Self> {
        let mut line = Vec::new();
        r.read_until(b'\n', &mut line)
            .map_err(|e| Error::read(name, e))?;
        if line.is_empty() {
            return Err(Error::invalid(
                name,
                "empty input: expected a YUV4MPEG2 stream",
            ));
        }
        let text = String::from_utf8_lossy(&line);
        let text = text.trim_end();
        let mut it = text.split(' ');
        if it.next() != Some("YUV4MPEG2") {
            return Err(Error::invalid(
                name,
                "not a YUV4MPEG2 stream (the header must start with `YUV4MPEG2`)",
            ));
        }
        let (mut w, mut h, mut fps, mut chroma, mut full) =
            (0usize, 0usize, None, Chroma::C420, false);
        for tok in it {
            // The key is the first character, which need not be one byte.
            let (k, v) = tok.split_at(tok.chars().next().map_or(0, char::len_utf8));
            match k {
                "W" => w = v.parse().unwrap_or(0),
                "H" => h = v.parse().unwrap_or(0),
                "F" => {
                    if let Some((a, b)) = v.split_once(':') {
                        let (a, b): (f64, f64) =
                            (a.parse().unwrap_or(0.0), b.parse().unwrap_or(0.0));
                        if a > 0.0 && b > 0.0 {
                            fps = Some(a / b);
                        }
                    }
                }
                "C" => {
                    chroma = match v {
                        "420" | "420jpeg" | "420paldv" | "420mpeg2" => Chroma::C420,
                        "422" => Chroma::C422,
                        "444" => Chroma::C444,
                        "mono" => Chroma::Mono,
                        other => {
                            return Err(Error::invalid(
                                name,
                                format!(
                                    "unsupported y4m colour space C{other} (8-bit 420, 422, 444 and mono are supported)"
                                ),
                            ));
                        }
                    }
                }
                "X" if v.eq_ignore_ascii_case("COLORRANGE=FULL") => full = true,
                _ => {}
            }
        }
        if w == 0 || h == 0 {
            return Err(Error::invalid(
                name,
                "y4m header without a valid width (W) and height (H)",
            ));
        }
        if w.saturating_mul(h) > MAX_FRAME_PIXELS {
            return Err(Error::invalid(
                name,
                format!(
                    "y4m header announces {w}×{h} frames, more than the {MAX_FRAME_PIXELS} \
                     pixels (8K UHD) a frame may have"
                ),
            ));
        }
        Ok(Self {
            r,
            width: w,
            height: h,
            chroma,
            full_range: full,
            fps,
            frames_read: 0,
            buf: Vec::new(),
            tables: None,
            terms: Default::default(),
            planes: Default::default(),
        })
    }

    fn plane_sizes(&self) -> (usize, usize, usize) {
        let (w, h) = (self.width, self.height);
        match self.chroma {
            Chroma::C420 => (w * h, w.div_ceil(2), h.div_ceil(2)),
            Chroma::C422 => (w * h, w.div_ceil(2), h),
            Chroma::C444 => (w * h, w, h),
            Chroma::Mono => (w * h, 0, 0),
        }
    }

    /// Reads the next frame; `Ok(None)` at a clean end, `Err(message)` on truncation.
    pub fn read_frame(&mut self) -> std::result::Result<Option<RgbImage>, String> {
        let mut line = Vec::new();
        let n = self
            .r
            .read_until(b'\n', &mut line)
            .map_err(|e| format!("read error: {e}"))?;
        if n == 0 {
            return Ok(None);
        }
        if !line.starts_with(b"FRAME") || line.last() != Some(&b'\n') {
            return Err("truncated or corrupt y4m stream: expected a FRAME header".into());
        }
        let (ysz, cw, ch) = self.plane_sizes();
        let total = ysz + 2 * cw * ch;
        self.buf.resize(total, 0);
        let mut got = 0;
        while got < total {
            match self.r.read(&mut self.buf[got..]) {
                Ok(0) => break,
                Ok(k) => got += k,
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e) => return Err(format!("read error: {e}")),
            }
        }
        if got < total {
            return Err(format!(
                "truncated y4m stream: frame data has {got} of {total} bytes"
            ));
        }
        self.frames_read += 1;
        Ok(Some(self.convert_frame()))
    }

    fn convert_frame(&mut self) -> RgbImage {
        let (w, h) = (self.width, self.height);
        let (ysz, cw, _) = self.plane_sizes();
        let full = self.full_range;
        let ycc = self.tables.get_or_insert_with(|| Box::new(Ycc::new(full)));
        let mut data = vec![0u8; 3 * w * h];
        let (luma, chroma) = self.buf.split_at(ysz);
        pulp::Arch::new().dispatch(ConvertOp {
            ycc,
            chroma: self.chroma,
            full_range: full,
            luma,
            chroma_planes: chroma.split_at(chroma.len() / 2),
            chroma_width: cw,
            terms: &mut self.terms,
            planes: &mut self.planes,
            out: &mut data,
            width: w,
        });
        // The buffer holds exactly w·h pixels.
        RgbImage::from_raw(w as u32, h as u32, data).unwrap_or_default()
    }
}

/// The conversion of one frame's planes into RGB rows, as a [`pulp::WithSimd`] operation: its
/// loops are compiled for AVX-512 and AVX2 as well as the baseline, and the variant the CPU
/// supports runs.
struct ConvertOp<'a> {
    ycc: &'a Ycc,
    chroma: Chroma,
    full_range: bool,
    luma: &'a [u8],
    /// The Cb and Cr planes.
    chroma_planes: (&'a [u8], &'a [u8]),
    chroma_width: usize,
    terms: &'a mut [Vec<u32>; 3],
    planes: &'a mut [Vec<u8>; 3],
    out: &'a mut [u8],
    width: usize,
}

impl pulp::WithSimd for ConvertOp<'_> {
    type Output = ();

    // Inlined into the dispatched function.
    #[allow(clippy::inline_always)]
    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _simd: S) {
        let (w, cw, t) = (self.width, self.chroma_width, self.ycc);
        let (up, vp) = self.chroma_planes;
        let shift = usize::from(matches!(self.chroma, Chroma::C420 | Chroma::C422));
        for k in self.terms.iter_mut() {
            k.resize(w, 0);
        }
        // Every pixel's chroma terms for the chroma row last expanded (4:2:0 shares one
        // between two rows).
        let mut terms_row = usize::MAX;
        for (y, (out, yrow)) in self
            .out
            .chunks_exact_mut(3 * w)
            .zip(self.luma.chunks_exact(w))
            .enumerate()
        {
            let crow = match self.chroma {
                Chroma::Mono => {
                    for (px, &yv) in out.chunks_exact_mut(3).zip(yrow) {
                        px.fill(t.grey(yv));
                    }
                    continue;
                }
                Chroma::C444 | Chroma::C422 => y,
                Chroma::C420 => y / 2,
            };
            if crow != terms_row {
                let urow = &up[crow * cw..(crow + 1) * cw];
                let vrow = &vp[crow * cw..(crow + 1) * cw];
                if shift == 1 {
                    expand_terms::<2>(t, urow, vrow, self.terms);
                } else {
                    expand_terms::<1>(t, urow, vrow, self.terms);
                }
                terms_row = crow;
            }
            if self.full_range {
                convert_row::<1>(yrow, self.terms, self.planes, out);
            } else {
                convert_row::<219>(yrow, self.terms, self.planes, out);
            }
        }
    }
}

/// Every pixel's chroma terms in `terms` (R, G, B) from one row of chroma samples, each of
/// which covers `N` pixels of the row.
// Inlined into the dispatched `ConvertOp`.
#[allow(clippy::inline_always)]
#[inline(always)]
fn expand_terms<const N: usize>(t: &Ycc, urow: &[u8], vrow: &[u8], terms: &mut [Vec<u32>; 3]) {
    let [kr, kg, kb] = terms;
    let w = kr.len();
    // Whole samples first, then the last pixel of an odd row.
    let whole = w / N;
    for ((((r, g), b), &u), &v) in kr[..whole * N]
        .chunks_exact_mut(N)
        .zip(kg[..whole * N].chunks_exact_mut(N))
        .zip(kb[..whole * N].chunks_exact_mut(N))
        .zip(urow)
        .zip(vrow)
    {
        let k = t.chroma(u, v);
        r.copy_from_slice(&[k.r; N]);
        g.copy_from_slice(&[k.g; N]);
        b.copy_from_slice(&[k.b; N]);
    }
    if whole * N < w {
        let k = t.chroma(urow[whole], vrow[whole]);
        kr[whole * N..].fill(k.r);
        kg[whole * N..].fill(k.g);
        kb[whole * N..].fill(k.b);
    }
}

/// The offset that makes every sum q + K of the conversion non-negative, in units of D.
const BIAS_UNITS: u32 = 1024;

/// Converts one row of pixels with every pixel's chroma terms ([`Ycc::chroma`]) in `terms`
/// (R, G, B); `D` is the conversion's luma scale: 1 (full range) or 219 (limited range). Each
/// channel is computed into its own plane (`planes`, scratch) by a loop the compiler
/// vectorises (no lookups, no branches), then the planes are interleaved.
// Inlined into the dispatched `ConvertOp`.
#[allow(clippy::inline_always)]
#[inline(always)]
fn convert_row<const D: u32>(
    yrow: &[u8],
    terms: &[Vec<u32>; 3],
    planes: &mut [Vec<u8>; 3],
    out: &mut [u8],
) {
    // q + 255·16 = 255·Y (D = 219; the terms hold the −255·16) or q = Y (D = 1).
    let m = if D == 1 { 1 } else { 255 };
    for (plane, k) in planes.iter_mut().zip(terms) {
        plane.resize(yrow.len(), 0);
        for ((o, &yv), &k) in plane.iter_mut().zip(yrow).zip(k) {
            // ⌊(q + K)/D⌋ + BIAS_UNITS, an unsigned division by a constant.
            let v = ((u32::from(yv) * m + k) / D).clamp(BIAS_UNITS, BIAS_UNITS + 255);
            #[allow(clippy::cast_possible_truncation)]
            let byte = (v - BIAS_UNITS) as u8;
            *o = byte;
        }
    }
    let [r, g, b] = planes;
    for (((px, &r), &g), &b) in out.chunks_exact_mut(3).zip(&*r).zip(&*g).zip(&*b) {
        px.copy_from_slice(&[r, g, b]);
    }
}

/// The chroma terms of one chroma sample (Cb, Cr): K of R, G and B in [`Ycc`], plus
/// [`BIAS_UNITS`]·D and minus q's offset (255·16 in limited range), so that a pixel's sum is
/// non-negative and its q is a multiple of Y.
#[derive(Clone, Copy, Debug, Default)]
struct ChromaTerms {
    r: u32,
    g: u32,
    b: u32,
}

/// The YCbCr → RGB conversion of BT.601, full or limited range, exactly in integers:
/// R = Y′ + 1.402·Cr, G = Y′ − 0.344136·Cb − 0.714136·Cr, B = Y′ + 1.772·Cb, each rounded half
/// away from zero and clamped to a byte, where Y′ = Y and Cb, Cr = byte − 128 (full range), or
/// Y′ = (Y − 16)·255/219 and C = (byte − 128)·255/224 (limited range).
///
/// With Y′ = q/D for an integer q and a channel's chroma part c, the rounded value is
/// ⌊q/D + c + ½⌋ = ⌊(q + K)/D⌋ for the integer K = ⌊D·(c + ½)⌋ (⌊(n + x)/D⌋ = ⌊(n + ⌊x⌋)/D⌋
/// for integers n and D > 0). Rounding halves up rather than away from zero differs only below
/// zero, where both clamp to 0. K is found once per chroma sample from tables of the bytes;
/// each pixel adds its q and divides by the constant D.
///
/// The tables hold K with the bias of [`ChromaTerms`], so sums are unsigned (two's complement
/// wraps back to the non-negative result).
struct Ycc {
    /// K of R by the Cr byte.
    r_cr: [u32; 256],
    /// K of B by the Cb byte.
    b_cb: [u32; 256],
    /// G's K is ⌊(A(Cb) + B(Cr))/den⌋ for integers A and B, which are held divided by den:
    /// (quotient, remainder) of A (½ and the bias included) and of B.
    g_cb: [(u32, i32); 256],
    g_cr: [(u32, i32); 256],
    /// The denominator of A and B.
    den: i32,
    /// The grey byte of a mono stream: round(Y′), clamped.
    mono: [u8; 256],
}

/// BT.601's coefficients have six decimals: integers over this scale.
const COEF_SCALE: i64 = 1_000_000;

impl Ycc {
    fn new(full_range: bool) -> Self {
        // Y′ = q/D and C = (byte − 128)·m/f.
        let (d, m, f): (i64, i64, i64) = if full_range {
            (1, 1, 1)
        } else {
            (219, 255, 224)
        };
        // D·(c + ½) for c = coef·C is the numerator half + coef·SCALE·D·(byte − 128)·m over
        // den = f·SCALE.
        let den = f * COEF_SCALE;
        let half = d * den / 2;
        let bias = i64::from(BIAS_UNITS) * d - if full_range { 0 } else { 16 * 255 };
        // Every value below fits: |K| < 2¹⁶ and the bias < 2¹⁸.
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let word = |x: i64| x as u32;
        #[allow(clippy::cast_possible_truncation)]
        let rem = |x: i64| x.rem_euclid(den) as i32;
        let mut t = Self {
            r_cr: [0; 256],
            b_cb: [0; 256],
            g_cb: [(0, 0); 256],
            g_cr: [(0, 0); 256],
            #[allow(clippy::cast_possible_truncation)]
            den: den as i32,
            mono: [0; 256],
        };
        for i in 0..256 {
            let byte = i as i64;
            let q = if full_range { byte } else { (byte - 16) * 255 };
            let dc = d * (byte - 128) * m;
            let (g_cb, g_cr) = (half - 344_136 * dc, -714_136 * dc);
            t.r_cr[i] = word((half + 1_402_000 * dc).div_euclid(den) + bias);
            t.b_cb[i] = word((half + 1_772_000 * dc).div_euclid(den) + bias);
            t.g_cb[i] = (word(g_cb.div_euclid(den) + bias), rem(g_cb));
            t.g_cr[i] = (word(g_cr.div_euclid(den)), rem(g_cr));
            #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
            let grey = (q + d / 2).div_euclid(d).clamp(0, 255) as u8;
            t.mono[i] = grey;
        }
        t
    }

    /// The K of R, G and B for one chroma sample.
    #[inline]
    fn chroma(&self, u: u8, v: u8) -> ChromaTerms {
        let (a1, a0) = self.g_cb[usize::from(u)];
        let (b1, b0) = self.g_cr[usize::from(v)];
        ChromaTerms {
            r: self.r_cr[usize::from(v)],
            g: a1
                .wrapping_add(b1)
                .wrapping_add(u32::from(a0 + b0 >= self.den)),
            b: self.b_cb[usize::from(u)],
        }
    }

    fn grey(&self, y: u8) -> u8 {
        self.mono[usize::from(y)]
    }

    /// One pixel (for tests; frames go through [`convert_row`]).
    #[cfg(test)]
    fn pixel(&self, y: u8, u: u8, v: u8, full_range: bool) -> [u8; 3] {
        let mut px = [0u8; 3];
        let k = self.chroma(u, v);
        let terms = [vec![k.r], vec![k.g], vec![k.b]];
        let mut planes = Default::default();
        if full_range {
            convert_row::<1>(&[y], &terms, &mut planes, &mut px);
        } else {
            convert_row::<219>(&[y], &terms, &mut planes, &mut px);
        }
        px
    }
}

/// Writes frames as a YUV4MPEG2 stream: `Cmono` when every frame is grey (lossless), else full-range
/// 4:4:4 BT.601.
pub fn write_y4m<W: Write>(mut w: W, frames: &[RgbImage], fps: f64) -> std::io::Result<()> {
    let Some(first) = frames.first() else {
        return Ok(());
    };
    let grey = frames
        .iter()
        .all(|f| f.pixels().all(|p| p.0[0] == p.0[1] && p.0[1] == p.0[2]));
    let (num, den) = ((fps * 1000.0).round() as u64, 1000);
    let c = if grey {
        "Cmono XCOLORRANGE=FULL"
    } else {
        "C444 XCOLORRANGE=FULL"
    };
    writeln!(
        w,
        "YUV4MPEG2 W{} H{} F{num}:{den} Ip A1:1 {c}",
        first.width(),
        first.height()
    )?;
    for f in frames {
        w.write_all(b"FRAME\n")?;
        if grey {
            let y: Vec<u8> = f.pixels().map(|p| p.0[0]).collect();
            w.write_all(&y)?;
        } else {
            let mut planes = [Vec::new(), Vec::new(), Vec::new()];
            for p in f.pixels() {
                let [r, g, b] = p.0.map(f64::from);
                let y = 0.299 * r + 0.587 * g + 0.114 * b;
                let cb = 128.0 + (b - y) / 1.772;
                let cr = 128.0 + (r - y) / 1.402;
                for (pl, v) in planes.iter_mut().zip([y, cb, cr]) {
                    pl.push(v.round().clamp(0.0, 255.0) as u8);
                }
            }
            for pl in &planes {
                w.write_all(pl)?;
            }
        }
    }
    w.flush()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frames(n: usize, w: u32, h: u32) -> Vec<RgbImage> {
        (0..n)
            .map(|k| {
                RgbImage::from_fn(w, h, |x, y| {
                    image::Rgb([(x * 7 + k as u32) as u8, (y * 5) as u8, ((x + y) * 3) as u8])
                })
            })
            .collect()
    }

    #[test]
    fn image_dir_natural_order_and_errors() {
        let d = tempfile::tempdir().unwrap();
        let f = frames(3, 8, 6);
        for (i, name) in ["f10.png", "f2.png", "f1.png"].iter().enumerate() {
            f[i].save(d.path().join(name)).unwrap();
        }
        let mut s = FrameSource::open(d.path(), &FrameOptions::default()).unwrap();
        assert!((s.fps() - DEFAULT_FPS).abs() < 1e-12);
        let order: Vec<_> = std::iter::from_fn(|| s.next_frame().unwrap())
            .map(|fr| fr.image)
            .collect();
        assert_eq!(order, vec![f[2].clone(), f[1].clone(), f[0].clone()]);
        // Changing size names the frame.
        RgbImage::new(4, 4).save(d.path().join("f3.png")).unwrap();
        let mut s = FrameSource::open(d.path(), &FrameOptions::default()).unwrap();
        let e = loop {
            match s.next_frame() {
                Ok(Some(_)) => {}
                Ok(None) => panic!("no error"),
                Err(e) => break e.to_string(),
            }
        };
        assert!(
            e.contains("frame 2") && e.contains("f3.png") && e.contains("differs"),
            "{e}"
        );
        // Corrupt image, skipped on request.
        std::fs::write(d.path().join("f3.png"), b"not a png").unwrap();
        let mut s = FrameSource::open(
            d.path(),
            &FrameOptions {
                fps: Some(10.0),
                skip_bad_frames: true,
                live: false,
            },
        )
        .unwrap();
        let n = std::iter::from_fn(|| s.next_frame().unwrap()).count();
        assert_eq!(n, 3);
        assert_eq!(s.skipped().len(), 1);
        assert!(s.skipped()[0].1.contains("corrupt"));
        let empty = tempfile::tempdir().unwrap();
        let e = FrameSource::open(empty.path(), &FrameOptions::default())
            .err()
            .unwrap();
        assert!(e.is_input_error() && e.to_string().contains("no frames"));
    }

    #[test]
    fn live_source_drops_what_a_slow_consumer_misses() {
        let d = tempfile::tempdir().unwrap();
        let f = frames(40, 9, 5);
        let p = d.path().join("a.y4m");
        write_y4m(std::fs::File::create(&p).unwrap(), &f, 25.0).unwrap();
        let live = FrameOptions {
            live: true,
            ..FrameOptions::default()
        };
        let mut s = FrameSource::open(&p, &live).unwrap();
        let stats = s.live_stats().unwrap();
        let mut got = Vec::new();
        while let Some(frame) = s.next_frame().unwrap() {
            // Slower than the reader: it delivers the whole file meanwhile.
            std::thread::sleep(Duration::from_millis(20));
            got.push(frame.index);
        }
        assert!(got.windows(2).all(|w| w[0] < w[1]), "{got:?}");
        assert_eq!(got.last(), Some(&39), "the last frame is never dropped");
        assert_eq!(stats.received(), 40);
        assert_eq!(stats.dropped() + got.len(), 40);
        assert!(stats.dropped() > 0, "{got:?}");
        // Frame times keep the source's clock across drops.
        let mut s = FrameSource::open(&p, &live).unwrap();
        std::thread::sleep(Duration::from_millis(100));
        let last = std::iter::from_fn(|| s.next_frame().unwrap())
            .last()
            .unwrap();
        assert!((last.time - 39.0 / 25.0).abs() < 1e-9);
        // A truncated live stream is an error naming the frame.
        let mut bytes = std::fs::read(&p).unwrap();
        bytes.truncate(bytes.len() - 10);
        let q = d.path().join("cut.y4m");
        std::fs::write(&q, bytes).unwrap();
        let mut s = FrameSource::open(&q, &live).unwrap();
        let err = loop {
            match s.next_frame() {
                Ok(Some(_)) => {}
                Ok(None) => panic!("a truncated stream must not end cleanly"),
                Err(e) => break e.to_string(),
            }
        };
        assert!(err.contains("cut.y4m") && err.contains("frame 39"), "{err}");
        // Directories are not live.
        let err = FrameSource::open(d.path(), &live)
            .err()
            .unwrap()
            .to_string();
        assert!(err.contains("cannot be read live"), "{err}");
        assert!(is_capture_device(Path::new("/dev/video0")) == cfg!(target_os = "linux"));
        assert!(!is_capture_device(Path::new("/dev/video")));
        assert!(!is_capture_device(Path::new("video0.mp4")));
    }

    #[test]
    fn y4m_roundtrip_and_truncation() {
        let d = tempfile::tempdir().unwrap();
        let f = frames(3, 9, 5);
        let p = d.path().join("a.y4m");
        write_y4m(std::fs::File::create(&p).unwrap(), &f, 25.0).unwrap();
        let mut s = FrameSource::open(&p, &FrameOptions::default()).unwrap();
        assert!((s.fps() - 25.0).abs() < 1e-9);
        let got: Vec<_> = std::iter::from_fn(|| s.next_frame().unwrap()).collect();
        assert_eq!(got.len(), 3);
        for (a, b) in got.iter().zip(&f) {
            for (pa, pb) in a.image.pixels().zip(b.pixels()) {
                for c in 0..3 {
                    assert!((i32::from(pa.0[c]) - i32::from(pb.0[c])).abs() <= 2);
                }
            }
        }
        // Grey frames are lossless (Cmono).
        let g: Vec<_> = f
            .iter()
            .map(|i| image::DynamicImage::ImageRgb8(i.clone()).to_luma8())
            .map(|l| image::DynamicImage::ImageLuma8(l).to_rgb8())
            .collect();
        let mut bytes = Vec::new();
        write_y4m(&mut bytes, &g, 30.0).unwrap();
        let mut r = Y4mReader::new(
            Box::new(std::io::Cursor::new(bytes.clone())),
            Path::new("-"),
        )
        .unwrap();
        assert_eq!(r.read_frame().unwrap().unwrap(), g[0]);
        // Truncated.
        let cut = bytes.len() - 10;
        std::fs::write(&p, &bytes[..cut]).unwrap();
        let mut s = FrameSource::open(&p, &FrameOptions::default()).unwrap();
        let e = loop {
            match s.next_frame() {
                Ok(Some(_)) => {}
                Ok(None) => panic!("no error"),
                Err(e) => break e.to_string(),
            }
        };
        assert!(e.contains("frame 2") && e.contains("truncated"), "{e}");
    }

    #[test]
    fn y4m_420_limited() {
        // 2×2 4:2:0 limited range: Y=235 (white), neutral chroma.
        let data = b"YUV4MPEG2 W2 H2 F30:1 C420jpeg\nFRAME\n\xeb\xeb\x10\x10\x80\x80".to_vec();
        let mut r = Y4mReader::new(Box::new(std::io::Cursor::new(data)), Path::new("x")).unwrap();
        let img = r.read_frame().unwrap().unwrap();
        assert_eq!(img.get_pixel(0, 0).0, [255, 255, 255]);
        assert_eq!(img.get_pixel(0, 1).0, [0, 0, 0]);
        assert!(r.read_frame().unwrap().is_none());
    }

    /// BT.601 in exact rational arithmetic: each channel's value as a fraction, rounded half
    /// away from zero and clamped (`mono`: Y′ alone).
    fn reference_rgb(yv: u8, u: u8, v: u8, full: bool, mono: bool) -> [u8; 3] {
        let (y, cb, cr) = (i128::from(yv), i128::from(u) - 128, i128::from(v) - 128);
        // Y′·den and C·den/10⁶ over the common denominator den.
        let (luma, chroma, den) = if full {
            (y * 1_000_000, 1, 1_000_000)
        } else {
            (
                (y - 16) * 255 * 224 * 1_000_000,
                255 * 219,
                219 * 224 * 1_000_000,
            )
        };
        let round = |n: i128| -> u8 {
            let r = n.signum() * ((2 * n.abs() + den) / (2 * den));
            u8::try_from(r.clamp(0, 255)).unwrap()
        };
        if mono {
            return [round(luma); 3];
        }
        [
            round(luma + 1_402_000 * chroma * cr),
            round(luma - 344_136 * chroma * cb - 714_136 * chroma * cr),
            round(luma + 1_772_000 * chroma * cb),
        ]
    }

    #[test]
    fn ycc_conversion_is_exact_for_every_input() {
        for full in [true, false] {
            let t = Ycc::new(full);
            for y in 0..=255u8 {
                assert_eq!(t.grey(y), reference_rgb(y, 128, 128, full, true)[0]);
                for u in 0..=255u8 {
                    for v in 0..=255u8 {
                        let got = t.pixel(y, u, v, full);
                        let want = reference_rgb(y, u, v, full, false);
                        assert_eq!(got, want, "full={full} Y={y} Cb={u} Cr={v}");
                    }
                }
            }
        }
        // A tie, 93 − 0.5 exactly, that the f64 formula (Y − 0.344136·Cb) − 0.714136·Cr
        // rounds down.
        assert_eq!(Ycc::new(true).pixel(111, 78, 178, true)[1], 93);
    }

    #[test]
    fn y4m_conversion_matches_the_formula_for_every_chroma() {
        // 6×4 frames with varied bytes, every chroma layout and both ranges.
        let (w, h) = (6usize, 4usize);
        for (tag, cw, ch) in [
            ("420jpeg", 3, 2),
            ("422", 3, 4),
            ("444", 6, 4),
            ("mono", 0, 0),
        ] {
            for full in [true, false] {
                let header = format!(
                    "YUV4MPEG2 W{w} H{h} F30:1 C{tag}{}\nFRAME\n",
                    if full { " XCOLORRANGE=FULL" } else { "" }
                );
                let planes: Vec<u8> = (0..w * h + 2 * cw * ch)
                    .map(|i| ((i * 73 + 11) % 256) as u8)
                    .collect();
                let mut data = header.into_bytes();
                data.extend(&planes);
                let mut r =
                    Y4mReader::new(Box::new(std::io::Cursor::new(data)), Path::new("x")).unwrap();
                let img = r.read_frame().unwrap().unwrap();
                for y in 0..h {
                    for x in 0..w {
                        let (u, v) = match tag {
                            "mono" => (128, 128),
                            "444" => (
                                planes[w * h + y * cw + x],
                                planes[w * h + cw * ch + y * cw + x],
                            ),
                            "422" => (
                                planes[w * h + y * cw + x / 2],
                                planes[w * h + cw * ch + y * cw + x / 2],
                            ),
                            _ => (
                                planes[w * h + (y / 2) * cw + x / 2],
                                planes[w * h + cw * ch + (y / 2) * cw + x / 2],
                            ),
                        };
                        let want = reference_rgb(planes[y * w + x], u, v, full, tag == "mono");
                        assert_eq!(
                            img.get_pixel(x as u32, y as u32).0,
                            want,
                            "{tag} full={full} ({x}, {y})"
                        );
                    }
                }
            }
        }
    }

    /// Fuzzing found a header token starting with a multi-byte character splitting inside it.
    #[test]
    fn y4m_header_token_with_multibyte_key() {
        let data = "YUV4MPEG2 W2 H2 é30 Xü F30:1\nFRAME\n\u{10}\u{10}\u{10}\u{10}\u{7f}\u{7f}"
            .as_bytes()
            .to_vec();
        let mut r = Y4mReader::new(Box::new(std::io::Cursor::new(data)), Path::new("x")).unwrap();
        assert!(r.read_frame().unwrap().is_some());
    }
}
