//! Figures for milliEgo: what a reader looks at instead of a table.
//!
//! * [`trajectory_top_view`]: x-y of the ground truth (grey) and of the aligned estimate coloured by
//!   its absolute trajectory error per pose, equal axis scaling, start and end marked.
//! * [`error_over_time`]: x, y and z error of the aligned estimate against time.
//! * [`ate_cdf`]: cumulative distribution of ATE for one or more estimators (the paper's figure).
//! * [`radar_frame`]: top view of one radar frame, points coloured by Doppler velocity.
//!
//! Every function writes PNG or SVG, chosen by the output file's extension (`.png`, `.svg`), and
//! creates the file's directory when it is missing. Inputs come from [`Matched::new`], which
//! associates and aligns an estimate with its ground truth exactly as `milliego eval` (and evo) do.
//!
//! Text is drawn with DejaVu Sans compiled into the crate (`assets/`, Bitstream Vera licence), via
//! plotters' `ab_glyph` backend: no system font, fontconfig or network is needed at run time.
//! Errors name the output file and what is wrong; no input makes these functions panic.

#![forbid(unsafe_code)]
#![warn(missing_docs)]

use milliego_eval::{align, ape, associate, Align, EvalError, Trajectory};
use plotters::coord::ranged1d::{AsRangedCoord, ValueFormatter};
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use std::error::Error;
use std::fmt;
use std::io;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

mod colour;
pub use colour::{doppler_colour, error_colour, GROUND_TRUTH, SERIES};
pub use plotters::style::RGBColor;

/// DejaVu Sans, subset (see `assets/LICENSE-DejaVu.txt`).
static FONT: &[u8] = include_bytes!("../assets/DejaVuSans-subset.ttf");

/// Default figure size \[px\]: wide enough for labels at the default text size.
pub const DEFAULT_SIZE: (u32, u32) = (1000, 800);

/// Smallest and largest accepted figure side \[px\].
pub const SIZE_LIMITS: (u32, u32) = (300, 8000);

/// What went wrong, and with which output file.
#[derive(Debug)]
pub struct PlotError {
    /// The figure being written.
    pub path: PathBuf,
    /// What is wrong.
    pub kind: PlotErrorKind,
}

/// The cause of a [`PlotError`].
#[derive(Debug)]
#[non_exhaustive]
pub enum PlotErrorKind {
    /// The extension is neither `.png` nor `.svg`.
    UnsupportedFormat,
    /// A side outside [`SIZE_LIMITS`].
    BadSize {
        /// Requested width \[px\].
        width: u32,
        /// Requested height \[px\].
        height: u32,
    },
    /// An input with nothing to draw.
    Empty {
        /// Which input.
        what: &'static str,
    },
    /// Inputs that must have one entry per pose do not.
    LengthMismatch {
        /// Which input.
        what: &'static str,
        /// Entries expected.
        expected: usize,
        /// Entries given.
        got: usize,
    },
    /// A NaN or infinite value.
    NotFinite {
        /// Which input.
        what: &'static str,
    },
    /// Association or alignment failed.
    Eval(EvalError),
    /// The output directory could not be created.
    CreateDir {
        /// The directory.
        dir: PathBuf,
        /// Why.
        source: io::Error,
    },
    /// The file could not be written.
    Write(io::Error),
    /// Drawing or encoding failed.
    Draw(String),
}

impl fmt::Display for PlotError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}: ", self.path.display())?;
        match &self.kind {
            PlotErrorKind::UnsupportedFormat => {
                write!(
                    f,
                    "unsupported figure format (use a .png or .svg file name)"
                )
            }
            PlotErrorKind::BadSize { width, height } => write!(
                f,
                "figure size {width}x{height} px outside {}..={} px per side",
                SIZE_LIMITS.0, SIZE_LIMITS.1
            ),
            PlotErrorKind::Empty { what } => write!(f, "nothing to plot: {what} is empty"),
            PlotErrorKind::LengthMismatch {
                what,
                expected,
                got,
            } => write!(f, "{what} has {got} entries, expected {expected}"),
            PlotErrorKind::NotFinite { what } => {
                write!(f, "{what} contains a NaN or infinite value")
            }
            PlotErrorKind::Eval(e) => write!(f, "{e}"),
            PlotErrorKind::CreateDir { dir, source } => {
                write!(f, "cannot create directory {}: {source}", dir.display())
            }
            PlotErrorKind::Write(e) => write!(f, "cannot write: {e}"),
            PlotErrorKind::Draw(e) => write!(f, "drawing failed: {e}"),
        }
    }
}

impl Error for PlotError {
    fn source(&self) -> Option<&(dyn Error + 'static)> {
        match &self.kind {
            PlotErrorKind::Eval(e) => Some(e),
            PlotErrorKind::CreateDir { source, .. } => Some(source),
            PlotErrorKind::Write(e) => Some(e),
            _ => None,
        }
    }
}

fn fail(path: &Path, kind: PlotErrorKind) -> PlotError {
    PlotError {
        path: path.to_path_buf(),
        kind,
    }
}

/// An estimate associated with its ground truth and aligned onto it, with the error per pose.
#[derive(Debug, Clone, PartialEq)]
pub struct Matched {
    /// Ground truth at the matched poses.
    pub gt: Trajectory,
    /// Aligned estimate at the matched poses.
    pub est: Trajectory,
    /// ATE of the translation part per matched pose \[m\].
    pub errors: Vec<f64>,
}

impl Matched {
    /// Associates by nearest timestamp within `max_diff` \[s\] and aligns (as `milliego eval`).
    pub fn new(
        gt: &Trajectory,
        est: &Trajectory,
        how: Align,
        max_diff: f64,
    ) -> Result<Matched, EvalError> {
        let (gt, mut est) = associate(gt, est, max_diff, 0.0)?;
        align(&gt, &mut est, how)?;
        let (errors, _) = ape(&gt, &est);
        Ok(Matched { gt, est, errors })
    }
}

/// One radar detection, sensor frame: x right, y boresight.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct RadarPoint {
    /// x \[m\] (right).
    pub x: f64,
    /// y \[m\] (boresight).
    pub y: f64,
    /// Radial (Doppler) velocity \[m/s\]; negative when approaching.
    pub velocity: f64,
}

type DrawResult = Result<(), Box<dyn Error>>;

fn register_font() -> Result<(), String> {
    static DONE: OnceLock<bool> = OnceLock::new();
    let ok = *DONE.get_or_init(|| {
        let normal = register_font_style(FontStyle::Normal);
        let bold = register_font_style(FontStyle::Bold);
        normal && bold
    });
    if ok {
        Ok(())
    } else {
        Err("the built-in font failed to load".into())
    }
}

fn register_font_style(style: FontStyle) -> bool {
    plotters::style::register_font("sans-serif", style, FONT).is_ok()
}

enum Format {
    Png,
    Svg,
}

/// A figure that draws itself on any plotters backend.
trait Figure {
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult
    where
        DB::ErrorType: 'static;
}

/// Renders `fig` into `path` (PNG or SVG by extension), creating the directory if needed.
fn render(path: &Path, size: (u32, u32), fig: &impl Figure) -> Result<(), PlotError> {
    let format = match path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
        .as_deref()
    {
        Some("png") => Format::Png,
        Some("svg") => Format::Svg,
        _ => return Err(fail(path, PlotErrorKind::UnsupportedFormat)),
    };
    let (width, height) = size;
    let side = SIZE_LIMITS.0..=SIZE_LIMITS.1;
    if !side.contains(&width) || !side.contains(&height) {
        return Err(fail(path, PlotErrorKind::BadSize { width, height }));
    }
    register_font().map_err(|e| fail(path, PlotErrorKind::Draw(e)))?;
    let draw_err = |e: Box<dyn Error>| fail(path, PlotErrorKind::Draw(e.to_string()));
    let bytes = match format {
        Format::Png => {
            let mut rgb = vec![255u8; width as usize * height as usize * 3];
            {
                let backend = BitMapBackend::with_buffer(&mut rgb, size);
                let root = backend.into_drawing_area();
                fig.draw(&root).map_err(draw_err)?;
                root.present().map_err(|e| draw_err(e.into()))?;
            }
            encode_png(&rgb, size).map_err(|e| fail(path, PlotErrorKind::Draw(e.to_string())))?
        }
        Format::Svg => {
            let mut svg = String::new();
            {
                let root = SVGBackend::with_string(&mut svg, size).into_drawing_area();
                fig.draw(&root).map_err(draw_err)?;
                root.present().map_err(|e| draw_err(e.into()))?;
            }
            svg.into_bytes()
        }
    };
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(|source| {
            fail(
                path,
                PlotErrorKind::CreateDir {
                    dir: dir.to_path_buf(),
                    source,
                },
            )
        })?;
    }
    std::fs::write(path, bytes).map_err(|e| fail(path, PlotErrorKind::Write(e)))
}

fn encode_png(rgb: &[u8], (w, h): (u32, u32)) -> Result<Vec<u8>, png::EncodingError> {
    let mut out = Vec::new();
    let mut enc = png::Encoder::new(&mut out, w, h);
    enc.set_color(png::ColorType::Rgb);
    enc.set_depth(png::BitDepth::Eight);
    enc.set_compression(png::Compression::Best);
    let mut writer = enc.write_header()?;
    writer.write_image_data(rgb)?;
    writer.finish()?;
    Ok(out)
}

/// Text sizes \[px\] for a figure of height `h` \[px\]: (title, axis description, tick labels).
fn text_sizes(h: u32) -> (f64, f64, f64) {
    let s = (f64::from(h) / 800.0).clamp(0.5, 3.0);
    (26.0 * s, 20.0 * s, 16.0 * s)
}

fn check_finite(
    path: &Path,
    what: &'static str,
    v: impl IntoIterator<Item = f64>,
) -> Result<(), PlotError> {
    if v.into_iter().all(f64::is_finite) {
        Ok(())
    } else {
        Err(fail(path, PlotErrorKind::NotFinite { what }))
    }
}

fn check_len(
    path: &Path,
    what: &'static str,
    expected: usize,
    got: usize,
) -> Result<(), PlotError> {
    if expected == got {
        Ok(())
    } else {
        Err(fail(
            path,
            PlotErrorKind::LengthMismatch {
                what,
                expected,
                got,
            },
        ))
    }
}

fn check_nonempty(path: &Path, what: &'static str, n: usize) -> Result<(), PlotError> {
    if n == 0 {
        Err(fail(path, PlotErrorKind::Empty { what }))
    } else {
        Ok(())
    }
}

/// A tick label: the shortest decimal for `v` rounded to 1e-6, never "-0".
fn num(v: &f64) -> String {
    let r = (v * 1e6).round() / 1e6;
    if r == 0.0 {
        "0".into()
    } else {
        format!("{r}")
    }
}

fn rmse(e: &[f64]) -> f64 {
    if e.is_empty() {
        return 0.0;
    }
    (e.iter().map(|x| x * x).sum::<f64>() / e.len() as f64).sqrt()
}

/// Bounds of `pts` padded by `pad` (fraction of the larger span, itself at least `min_span`).
fn bounds(
    pts: impl IntoIterator<Item = (f64, f64)>,
    pad: f64,
    min_span: f64,
) -> ((f64, f64), (f64, f64)) {
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for (x, y) in pts {
        x0 = x0.min(x);
        x1 = x1.max(x);
        y0 = y0.min(y);
        y1 = y1.max(y);
    }
    if x0 > x1 {
        return ((-1.0, 1.0), (-1.0, 1.0));
    }
    let span = (x1 - x0).max(y1 - y0);
    let p = span.max(min_span) * pad;
    let (cx, cy) = ((x0 + x1) / 2.0, (y0 + y1) / 2.0);
    let half = |a: f64| (a.max(min_span) / 2.0) + p;
    let (hx, hy) = (half(x1 - x0), half(y1 - y0));
    ((cx - hx, cx + hx), (cy - hy, cy + hy))
}

/// Widens one of the ranges so that a metre is as many pixels along x as along y.
/// With `keep_bottom`, y grows upwards only (the radar view has nothing below its sensor).
fn equal_aspect(
    (x, y): ((f64, f64), (f64, f64)),
    (pw, ph): (u32, u32),
    keep_bottom: bool,
) -> ((f64, f64), (f64, f64)) {
    let (pw, ph) = (f64::from(pw.max(1)), f64::from(ph.max(1)));
    let (sx, sy) = ((x.1 - x.0) / pw, (y.1 - y.0) / ph);
    if sx > sy {
        let half = sx * ph / 2.0;
        if keep_bottom {
            return (x, (y.0, y.0 + 2.0 * half));
        }
        let c = (y.0 + y.1) / 2.0;
        (x, (c - half, c + half))
    } else {
        let half = sy * pw / 2.0;
        let c = (x.0 + x.1) / 2.0;
        ((c - half, c + half), y)
    }
}

/// Chart margins and label areas \[px\] for a figure with tick labels of size `tick` \[px\].
fn layout(tick: f64) -> (u32, u32, u32) {
    let margin = (tick * 1.2) as u32;
    let x_label = (tick * 3.4) as u32;
    let y_label = (tick * 5.0) as u32;
    (margin, x_label, y_label)
}

/// A vertical colour bar from `lo` to `hi` in `area`, aligned with a chart drawn with `layout`.
fn colour_bar<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    (lo, hi): (f64, f64),
    cmap: fn(f64) -> RGBColor,
    desc: &str,
    tick: f64,
) -> DrawResult
where
    DB::ErrorType: 'static,
{
    let (margin, x_label, _) = layout(tick);
    let (lo, hi) = if hi > lo {
        (lo, hi)
    } else {
        (lo - 0.5, lo + 0.5)
    };
    let mut chart = ChartBuilder::on(area)
        .margin_top(margin)
        .margin_bottom(margin + x_label)
        .margin_left(8)
        .margin_right((tick * 1.2) as u32)
        .set_label_area_size(LabelAreaPosition::Right, (tick * 5.0) as u32)
        .build_cartesian_2d(0.0..1.0, lo..hi)?;
    chart
        .configure_mesh()
        .disable_mesh()
        .disable_x_axis()
        .set_all_tick_mark_size((tick * 0.4) as u32)
        .y_labels(8)
        .y_desc(desc)
        .y_label_formatter(&num)
        .label_style(("sans-serif", tick))
        .axis_desc_style(("sans-serif", tick * 1.1))
        .draw()?;
    let n = 128;
    let step = (hi - lo) / f64::from(n);
    chart.draw_series((0..n).map(|i| {
        let v0 = lo + step * f64::from(i);
        // Each band takes the colour of its middle, so the exact ends of the map only ever come
        // from data.
        let c = cmap((f64::from(i) + 0.5) / f64::from(n));
        Rectangle::new([(0.0, v0), (1.0, v0 + step)], c.filled())
    }))?;
    chart.draw_series(std::iter::once(Rectangle::new(
        [(0.0, lo), (1.0, hi)],
        BLACK.stroke_width(1),
    )))?;
    Ok(())
}

/// Draws a title line at the top of `root` and returns the area below it.
fn titled<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    title: &str,
    size: f64,
) -> Result<DrawingArea<DB, Shift>, Box<dyn Error>>
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE)?;
    Ok(root.titled(title, ("sans-serif", size).into_font().color(&BLACK))?)
}

/// Draws the axes every figure shares: descriptions, tick labels at their own precision, a light
/// grid without minor lines.
fn draw_mesh<DB, X, Y>(
    chart: &mut ChartContext<'_, DB, Cartesian2d<X, Y>>,
    x_desc: &str,
    y_desc: &str,
    tick: f64,
    desc: f64,
) -> Result<(), Box<dyn Error>>
where
    DB: DrawingBackend,
    DB::ErrorType: 'static,
    X: Ranged<ValueType = f64> + ValueFormatter<f64>,
    Y: Ranged<ValueType = f64> + ValueFormatter<f64>,
{
    chart
        .configure_mesh()
        .x_desc(x_desc)
        .y_desc(y_desc)
        .label_style(("sans-serif", tick))
        .axis_desc_style(("sans-serif", desc))
        .x_label_formatter(&num)
        .y_label_formatter(&num)
        .light_line_style(WHITE.mix(0.0))
        .bold_line_style(BLACK.mix(0.12))
        .draw()?;
    Ok(())
}

/// Builds a chart on `area` with equal metres per pixel along both axes around `b`.
fn equal_chart<'a, DB: DrawingBackend>(
    area: &'a DrawingArea<DB, Shift>,
    b: ((f64, f64), (f64, f64)),
    tick: f64,
    keep_bottom: bool,
) -> Result<
    ChartContext<
        'a,
        DB,
        Cartesian2d<plotters::coord::types::RangedCoordf64, plotters::coord::types::RangedCoordf64>,
    >,
    Box<dyn Error>,
>
where
    DB::ErrorType: 'static,
{
    let (margin, x_label, y_label) = layout(tick);
    let build = |(x, y): ((f64, f64), (f64, f64))| {
        ChartBuilder::on(area)
            .margin(margin)
            .x_label_area_size(x_label)
            .y_label_area_size(y_label)
            .build_cartesian_2d(x.0..x.1, y.0..y.1)
    };
    // Nothing is drawn by building, so the first chart only measures the plotting area.
    let probe = build(b)?;
    let dims = probe.plotting_area().dim_in_pixel();
    Ok(build(equal_aspect(b, dims, keep_bottom))?)
}

fn split_for_bar<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
) -> (DrawingArea<DB, Shift>, DrawingArea<DB, Shift>) {
    let (w, h) = area.dim_in_pixel();
    let bar = (text_sizes(h).2 * 8.0) as u32;
    area.split_horizontally(w.saturating_sub(bar))
}

struct TopView<'a> {
    gt: &'a Trajectory,
    est: &'a Trajectory,
    errors: &'a [f64],
    label: &'a str,
}

impl Figure for TopView<'_> {
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult
    where
        DB::ErrorType: 'static,
    {
        let (title, desc, tick) = text_sizes(root.dim_in_pixel().1);
        let text = format!(
            "{}: top view, ATE RMSE {:.3} m over {} poses",
            self.label,
            rmse(self.errors),
            self.errors.len()
        );
        let area = titled(root, &text, title)?;
        let (left, right) = split_for_bar(&area);
        let pts = self.gt.p.iter().chain(&self.est.p).map(|p| (p.x, p.y));
        let mut chart = equal_chart(&left, bounds(pts, 0.05, 1.0), tick, false)?;
        draw_mesh(&mut chart, "x [m]", "y [m]", tick, desc)?;
        let gt_style = GROUND_TRUTH.stroke_width((tick / 8.0).max(1.0) as u32 + 1);
        chart
            .draw_series(LineSeries::new(
                self.gt.p.iter().map(|p| (p.x, p.y)),
                gt_style,
            ))?
            .label("ground truth")
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 24, y)], gt_style));
        let lo = self.errors.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = self
            .errors
            .iter()
            .copied()
            .fold(f64::NEG_INFINITY, f64::max);
        // A flat error (to rounding) gets a bar of +-10 % around it (not below zero), so it takes
        // the middle of the map rather than both of its ends.
        let flat = hi - lo <= 1e-9 * hi.abs().max(1.0);
        let (lo, hi) = if flat {
            let d = 0.1 * lo.max(0.01);
            let b0 = (lo - d).max(0.0);
            (b0, b0 + 2.0 * d)
        } else {
            (lo, hi)
        };
        let norm = |e: f64| (e - lo) / (hi - lo);
        let width = (tick / 5.0).max(1.0) as u32 + 1;
        let est_legend = error_colour(0.5).stroke_width(width);
        chart
            .draw_series(std::iter::empty::<PathElement<(f64, f64)>>())?
            .label(format!("{} (colour: ATE)", self.label))
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 24, y)], est_legend));
        let p: Vec<(f64, f64)> = self.est.p.iter().map(|p| (p.x, p.y)).collect();
        // Markers go under the estimate, so they never hide the first or last error.
        let r = (tick * 0.45) as i32;
        if let (Some(&s), Some(&e)) = (p.first(), p.last()) {
            chart
                .draw_series(std::iter::once(Circle::new(s, r, BLACK.stroke_width(2))))?
                .label("start")
                .legend(move |(x, y)| Circle::new((x + 12, y), r, BLACK.stroke_width(2)));
            chart
                .draw_series(std::iter::once(TriangleMarker::new(
                    e,
                    r + 2,
                    BLACK.filled(),
                )))?
                .label("end")
                .legend(move |(x, y)| TriangleMarker::new((x + 12, y), r + 2, BLACK.filled()));
        }
        // Each pose owns the path from the midpoint before it to the midpoint after it, in its
        // own colour, so every error is visible and none is averaged away.
        let mid = |a: (f64, f64), b: (f64, f64)| ((a.0 + b.0) / 2.0, (a.1 + b.1) / 2.0);
        chart.draw_series(p.iter().enumerate().map(|(i, &c)| {
            // Wide paths are polygons: repeated points would give them a zero-length edge.
            let mut piece = Vec::with_capacity(3);
            if i > 0 {
                piece.push(mid(p[i - 1], c));
            }
            piece.push(c);
            if let Some(&n) = p.get(i + 1) {
                piece.push(mid(c, n));
            }
            piece.dedup();
            let colour = error_colour(norm(self.errors[i]));
            PathElement::new(piece, colour.stroke_width(width))
        }))?;
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperLeft)
            .label_font(("sans-serif", tick))
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK.mix(0.4))
            .draw()?;
        colour_bar(&right, (lo, hi), error_colour, "ATE [m]", tick)
    }
}

/// Top view (x-y) of the ground truth (grey) and of the aligned estimate coloured by its ATE per
/// pose (viridis from the smallest to the largest error, colour bar in metres), equal axis scaling,
/// start (circle) and end (triangle) of the estimate marked, the ATE RMSE in the title.
///
/// `gt` and `est` are associated and aligned (see [`Matched`]); `errors` has one entry per pose of
/// `est` \[m\]; `label` names the estimator. Writes `path` (`.png` or `.svg`) of `size` \[px\].
pub fn trajectory_top_view(
    gt: &Trajectory,
    est: &Trajectory,
    errors: &[f64],
    label: &str,
    path: &Path,
    size: (u32, u32),
) -> Result<(), PlotError> {
    check_nonempty(path, "the estimate", est.len())?;
    check_nonempty(path, "the ground truth", gt.len())?;
    check_len(path, "the error list", est.len(), errors.len())?;
    check_finite(path, "the estimate", est.p.iter().flat_map(|p| [p.x, p.y]))?;
    check_finite(
        path,
        "the ground truth",
        gt.p.iter().flat_map(|p| [p.x, p.y]),
    )?;
    check_finite(path, "the error list", errors.iter().copied())?;
    render(
        path,
        size,
        &TopView {
            gt,
            est,
            errors,
            label,
        },
    )
}

struct ErrorsOverTime<'a> {
    gt: &'a Trajectory,
    est: &'a Trajectory,
    label: &'a str,
}

impl Figure for ErrorsOverTime<'_> {
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult
    where
        DB::ErrorType: 'static,
    {
        let (title, desc, tick) = text_sizes(root.dim_in_pixel().1);
        let t0 = self.est.t[0];
        let axes: [Vec<(f64, f64)>; 3] = [0, 1, 2].map(|k| {
            self.est
                .t
                .iter()
                .zip(self.est.p.iter().zip(&self.gt.p))
                .map(|(t, (e, g))| (t - t0, e[k] - g[k]))
                .collect()
        });
        let rms = axes
            .each_ref()
            .map(|a| rmse(&a.iter().map(|p| p.1).collect::<Vec<_>>()));
        let text = format!(
            "{}: position error per axis (RMSE x {:.3}, y {:.3}, z {:.3} m)",
            self.label, rms[0], rms[1], rms[2]
        );
        let area = titled(root, &text, title)?;
        let t1 = (self.est.t[self.est.len() - 1] - t0).max(1e-3);
        let emax = axes
            .iter()
            .flatten()
            .map(|p| p.1.abs())
            .fold(0.0, f64::max)
            .max(1e-3)
            * 1.1;
        let (margin, x_label, y_label) = layout(tick);
        let mut chart = ChartBuilder::on(&area)
            .margin(margin)
            .x_label_area_size(x_label)
            .y_label_area_size(y_label)
            .build_cartesian_2d(0.0..t1, -emax..emax)?;
        draw_mesh(
            &mut chart,
            "time [s]",
            "error, estimate − ground truth [m]",
            tick,
            desc,
        )?;
        chart.draw_series(LineSeries::new([(0.0, 0.0), (t1, 0.0)], BLACK.mix(0.5)))?;
        for (k, (name, pts)) in ["x", "y", "z"].iter().zip(axes).enumerate() {
            let style = SERIES[k].stroke_width(2);
            chart
                .draw_series(LineSeries::new(pts, style))?
                .label(*name)
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 24, y)], style));
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperLeft)
            .label_font(("sans-serif", tick))
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK.mix(0.4))
            .draw()?;
        Ok(())
    }
}

/// x, y and z error (estimate minus ground truth) of the aligned estimate against time since its
/// first pose \[s\], three lines with a legend, in metres; the per-axis RMSE in the title.
///
/// `gt` and `est` are associated and aligned (see [`Matched`]). Writes `path` (`.png` or `.svg`) of
/// `size` \[px\].
pub fn error_over_time(
    gt: &Trajectory,
    est: &Trajectory,
    label: &str,
    path: &Path,
    size: (u32, u32),
) -> Result<(), PlotError> {
    check_nonempty(path, "the estimate", est.len())?;
    check_len(path, "the ground truth", est.len(), gt.len())?;
    check_finite(
        path,
        "the estimate",
        est.p.iter().flat_map(|p| p.iter().copied()),
    )?;
    check_finite(
        path,
        "the ground truth",
        gt.p.iter().flat_map(|p| p.iter().copied()),
    )?;
    check_finite(path, "the estimate's times", est.t.iter().copied())?;
    render(path, size, &ErrorsOverTime { gt, est, label })
}

struct Cdf<'a> {
    sets: &'a [(&'a str, &'a [f64])],
}

impl Figure for Cdf<'_> {
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult
    where
        DB::ErrorType: 'static,
    {
        let (title, _, _) = text_sizes(root.dim_in_pixel().1);
        let all = || self.sets.iter().flat_map(|s| s.1.iter().copied());
        let emax = all().fold(0.0, f64::max).max(1e-3) * 1.05;
        // Estimators a hundredfold apart would leave the better one a vertical line at zero:
        // then the error axis is logarithmic, from the decade of the smallest typical error.
        let typical: Vec<f64> = self.sets.iter().map(|s| percentile(s.1, 0.9)).collect();
        let (tmin, tmax) = typical
            .iter()
            .fold((f64::MAX, 0.0f64), |(a, b), &t| (a.min(t), b.max(t)));
        if tmin > 0.0 && tmax / tmin > 30.0 {
            let floor = all().filter(|&e| e > 0.0).fold(tmin, f64::min);
            let lo = 10f64.powf(floor.log10().floor()).max(emax * 1e-6);
            let area = titled(
                root,
                "Cumulative distribution of ATE (log error axis)",
                title,
            )?;
            cdf_chart(&area, (lo..emax).log_scale(), lo, emax, self.sets)
        } else {
            let area = titled(root, "Cumulative distribution of ATE", title)?;
            cdf_chart(&area, 0.0..emax, 0.0, emax, self.sets)
        }
    }
}

/// The `q` quantile of `e` (nearest rank), 0 when empty.
fn percentile(e: &[f64], q: f64) -> f64 {
    let mut v = e.to_vec();
    v.sort_by(f64::total_cmp);
    let i = ((v.len() as f64 * q).ceil() as usize).clamp(1, v.len().max(1)) - 1;
    v.get(i).copied().unwrap_or(0.0)
}

/// The CDF lines on an error axis `x` from `lo` to `hi` \[m\] (linear or logarithmic).
fn cdf_chart<DB: DrawingBackend, X>(
    area: &DrawingArea<DB, Shift>,
    x: X,
    lo: f64,
    hi: f64,
    sets: &[(&str, &[f64])],
) -> DrawResult
where
    DB::ErrorType: 'static,
    X: AsRangedCoord<Value = f64>,
    X::CoordDescType: ValueFormatter<f64>,
{
    let (_, desc, tick) = text_sizes(area.dim_in_pixel().1);
    let (margin, x_label, y_label) = layout(tick);
    let mut chart = ChartBuilder::on(area)
        .margin(margin)
        .x_label_area_size(x_label)
        .y_label_area_size(y_label)
        .build_cartesian_2d(x, 0.0..1.0)?;
    draw_mesh(&mut chart, "ATE [m]", "fraction of poses", tick, desc)?;
    for (k, (name, errors)) in sets.iter().enumerate() {
        let mut e: Vec<f64> = errors.iter().map(|&x| x.max(lo)).collect();
        e.sort_by(f64::total_cmp);
        let n = e.len() as f64;
        // Step function: the fraction jumps to (i + 1) / n at the i-th smallest error.
        let mut pts = vec![(lo, 0.0)];
        for (i, &x) in e.iter().enumerate() {
            pts.push((x, i as f64 / n));
            pts.push((x, (i + 1) as f64 / n));
        }
        pts.push((hi, 1.0));
        let style = SERIES[k % SERIES.len()].stroke_width(2);
        chart
            .draw_series(LineSeries::new(pts, style))?
            .label(format!("{name} (RMSE {} m)", sig3(rmse(errors))))
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 24, y)], style));
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::LowerRight)
        .label_font(("sans-serif", tick))
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK.mix(0.4))
        .draw()?;
    Ok(())
}

/// Three significant digits, at most three decimals: 0.104, 1.23, 151.
fn sig3(v: f64) -> String {
    let digits = if v.abs() >= 100.0 {
        0
    } else if v.abs() >= 10.0 {
        1
    } else if v.abs() >= 1.0 {
        2
    } else {
        3
    };
    format!("{v:.digits$}")
}

/// Cumulative distribution of ATE for one or more estimators on the same axes (the paper's figure:
/// x = error \[m\], y = fraction of poses with at most that error), one line per `(label, errors)`
/// with its RMSE in the legend. Writes `path` (`.png` or `.svg`) of `size` \[px\].
pub fn ate_cdf(sets: &[(&str, &[f64])], path: &Path, size: (u32, u32)) -> Result<(), PlotError> {
    check_nonempty(path, "the list of error sets", sets.len())?;
    for (_, e) in sets {
        check_nonempty(path, "an error set", e.len())?;
        check_finite(path, "an error set", e.iter().copied())?;
    }
    render(path, size, &Cdf { sets })
}

struct Radar<'a> {
    points: &'a [RadarPoint],
    title: &'a str,
}

/// A ring spacing \[m\] giving three to six rings up to `r`.
fn ring_step(r: f64) -> f64 {
    let raw = r / 4.0;
    let p = 10f64.powf(raw.log10().floor());
    [1.0, 2.0, 5.0, 10.0]
        .iter()
        .map(|m| m * p)
        .find(|s| r / s <= 6.0)
        .unwrap_or(10.0 * p)
}

impl Figure for Radar<'_> {
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult
    where
        DB::ErrorType: 'static,
    {
        let (title, desc, tick) = text_sizes(root.dim_in_pixel().1);
        let area = titled(root, self.title, title)?;
        let (left, right) = split_for_bar(&area);
        let reach = self
            .points
            .iter()
            .map(|p| p.x.hypot(p.y))
            .fold(1.0, f64::max);
        let step = ring_step(reach);
        let r = (reach / step).ceil() * step;
        let y0 = self.points.iter().map(|p| p.y).fold(0.0, f64::min);
        let b = ((-r * 1.03, r * 1.03), (y0 - r * 0.08, r * 1.03));
        let mut chart = equal_chart(&left, b, tick, true)?;
        chart
            .configure_mesh()
            .x_desc("x, right [m]")
            .y_desc("y, boresight [m]")
            .label_style(("sans-serif", tick))
            .axis_desc_style(("sans-serif", desc))
            .x_label_formatter(&num)
            .y_label_formatter(&num)
            .light_line_style(WHITE.mix(0.0))
            .bold_line_style(BLACK.mix(0.08))
            .draw()?;
        // Opaque: the arc's segments overlap at their ends, translucent ones would look dotted.
        let ring = RGBColor(170, 170, 170).stroke_width(1);
        let ring_text = ("sans-serif", tick * 0.9)
            .into_font()
            .color(&RGBColor(100, 100, 100))
            .pos(Pos::new(HPos::Center, VPos::Top));
        let mut k = 1.0;
        while k * step <= r + 1e-9 {
            let rr = k * step;
            // One segment per degree on the outer ring, fewer inside: sub-pixel segments look dotted.
            let n = ((180.0 * rr / r).round() as u32).max(24);
            let arc = (0..=n).map(|d| {
                let a = std::f64::consts::PI * f64::from(d) / f64::from(n);
                (rr * a.cos(), rr * a.sin())
            });
            chart.draw_series(LineSeries::new(arc, ring))?;
            // Labels sit under the baseline, right of the sensor, where points rarely are.
            chart.draw_series(std::iter::once(Text::new(
                format!("{} m", num(&rr)),
                (rr, -0.01 * r),
                ring_text.clone(),
            )))?;
            k += 1.0;
        }
        let vmax = self
            .points
            .iter()
            .map(|p| p.velocity.abs())
            .fold(0.0, f64::max)
            .max(0.1);
        let radius = (tick * 0.35).max(2.0) as i32;
        // Points are drawn with a dark outline: still points are near white in the diverging map.
        chart.draw_series(self.points.iter().map(|p| {
            let c = doppler_colour(0.5 + p.velocity / (2.0 * vmax));
            Circle::new((p.x, p.y), radius, c.filled())
        }))?;
        chart.draw_series(
            self.points
                .iter()
                .map(|p| Circle::new((p.x, p.y), radius, BLACK.mix(0.7).stroke_width(1))),
        )?;
        chart.draw_series(std::iter::once(TriangleMarker::new(
            (0.0, 0.0),
            radius + 4,
            BLACK.filled(),
        )))?;
        colour_bar(
            &right,
            (-vmax, vmax),
            doppler_colour,
            "Doppler velocity [m/s]",
            tick,
        )
    }
}

/// Top view of one radar frame (x right, y boresight, sensor at the origin): points coloured by
/// Doppler velocity with a diverging map (blue approaching, white still, red receding; symmetric
/// about zero, colour bar in metres per second), range rings, `title` on top. An empty frame draws
/// the empty field of view. Writes `path` (`.png` or `.svg`) of `size` \[px\].
pub fn radar_frame(
    points: &[RadarPoint],
    title: &str,
    path: &Path,
    size: (u32, u32),
) -> Result<(), PlotError> {
    check_finite(
        path,
        "the radar points",
        points.iter().flat_map(|p| [p.x, p.y, p.velocity]),
    )?;
    render(path, size, &Radar { points, title })
}
