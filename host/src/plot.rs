//! The charts' shared plotting: one place for what morphctl's run plots, `morph-model charts`
//! and `cargo xtask strategies` have in common.
//!
//! - [`write()`] draws a [`Figure`] into `.svg` or `.png` chosen by the file's extension (both
//!   with text: the PNG's is drawn with [`FONT_TTF`], DejaVu Sans embedded in the tools);
//!   [`write_svg`] takes a closure for SVG-only charts. Both fill the page white, draw, and
//!   present. [`Format::of`] checks a path before anything runs.
//! - [`Frame`] is a panel's caption, margin and label areas; [`mesh`] its axis descriptions;
//!   [`sci`] and [`whole`] label log axes.
//! - [`line()`] draws a line series with its legend entry, [`marks`] thin vertical marks (phase
//!   changes), [`labelled_point`] a dot with a text beside it, [`legend`] the series box.
//! - [`PALETTE`] and the `TAB_*` colours, [`FONT`]; [`PlotError`] converts from every backend's
//!   error and into `String`, so `?` works across the charts and their callers.
//!
//! [`prelude`] re-exports plotters' prelude with this module, so a chart needs no direct
//! dependency on plotters.

use plotters::chart::MeshStyle;
use plotters::coord::ranged1d::ValueFormatter;
use plotters::coord::{CoordTranslate, Shift};
use plotters::prelude::*;
use std::path::Path;

/// Everything a chart needs: plotters' prelude and this module's items.
pub mod prelude {
    pub use super::{
        labelled_point, legend, line, line_key, marks, mesh, palette, sci, whole, write, write_svg,
        Figure, Format, Frame, PlotError, PlotResult, FONT, PALETTE, TAB_BLUE, TAB_GREEN,
        TAB_ORANGE, TAB_PURPLE, TAB_RED,
    };
    pub use plotters::coord::Shift;
    pub use plotters::prelude::*;
}

/// Why a chart could not be drawn or written: the backend's message.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct PlotError(pub String);

impl std::fmt::Display for PlotError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for PlotError {}

impl<E: std::error::Error + Send + Sync> From<DrawingAreaErrorKind<E>> for PlotError {
    fn from(e: DrawingAreaErrorKind<E>) -> PlotError {
        PlotError(e.to_string())
    }
}

impl From<PlotError> for String {
    fn from(e: PlotError) -> String {
        e.0
    }
}

/// The result of drawing.
pub type PlotResult = Result<(), PlotError>;

/// A chart file's format, from its extension.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    /// SVG: text is written as SVG text.
    Svg,
    /// PNG through the bitmap backend: text drawn with the embedded [`FONT_TTF`].
    Png,
}

impl Format {
    /// The format `path` names (`.svg` or `.png`, any case).
    pub fn of(path: &Path) -> Result<Format, PlotError> {
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase);
        match ext.as_deref() {
            Some("svg") => Ok(Format::Svg),
            Some("png") => Ok(Format::Png),
            _ => Err(PlotError(format!(
                "{}: the plot must end in .svg or .png (other formats are not written)",
                path.display()
            ))),
        }
    }

    /// Whether text (captions, labels, legends) can be drawn in this format: in both, since
    /// the PNG's font is embedded.
    pub fn has_text(self) -> bool {
        true
    }
}

/// A chart that can be drawn on any backend (so one chart serves SVG and PNG).
pub trait Figure {
    /// Draws onto `root`, already filled white; `format` says whether text can be drawn.
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>, format: Format)
        -> PlotResult;
}

/// Writes `figure` into `path` (`.svg` or `.png`, by extension) at `size` pixels.
pub fn write(path: &Path, size: (u32, u32), figure: &impl Figure) -> PlotResult {
    let format = Format::of(path)?;
    can_write(path)?;
    let done = match format {
        Format::Svg => page(SVGBackend::new(path, size).into_drawing_area(), |root| {
            figure.draw(root, Format::Svg)
        }),
        Format::Png => page(BitMapBackend::new(path, size).into_drawing_area(), |root| {
            figure.draw(root, Format::Png)
        }),
    };
    naming(path, done)
}

/// Whether a file can be made at `path`, in plain words ([`crate::out_path::check_new_file`]):
/// checked first, because the PNG backend reports such a failure in Rust's debug notation.
fn can_write(path: &Path) -> PlotResult {
    crate::out_path::check_new_file(path)
        .map_err(|why| PlotError(format!("cannot write {}: {why}", path.display())))
}

/// `done`, its error naming the file and saying what went wrong without plotters' layers of
/// "backend error" (`cannot write d/x.svg: No such file or directory (os error 2)`).
fn naming(path: &Path, done: PlotResult) -> PlotResult {
    done.map_err(|e| {
        let mut why = e.0.as_str();
        for layer in ["backend error: ", "Drawing backend error: "] {
            why = why.strip_prefix(layer).unwrap_or(why);
        }
        PlotError(format!("cannot write {}: {why}", path.display()))
    })
}

/// Writes an SVG chart into `path` at `size` pixels, drawn by `draw` (whatever `path` ends in).
pub fn write_svg(
    path: &Path,
    size: (u32, u32),
    draw: impl FnOnce(&DrawingArea<SVGBackend<'_>, Shift>) -> PlotResult,
) -> PlotResult {
    can_write(path)?;
    naming(
        path,
        page(SVGBackend::new(path, size).into_drawing_area(), draw),
    )
}

/// White page, the drawing, then the file.
fn page<DB: DrawingBackend>(
    root: DrawingArea<DB, Shift>,
    draw: impl FnOnce(&DrawingArea<DB, Shift>) -> PlotResult,
) -> PlotResult {
    register_font()?;
    root.fill(&WHITE)?;
    draw(&root)?;
    root.present()?;
    Ok(())
}

/// The font family of every caption, label and legend.
pub const FONT: &str = "sans-serif";

/// The font every chart's text is drawn and measured with: DejaVu Sans 2.37 (Bitstream Vera
/// licence, `host/fonts/LICENSE-DejaVu.txt`), embedded so a chart looks the same on every
/// machine and needs no system font.
pub const FONT_TTF: &[u8] = include_bytes!("../fonts/DejaVuSans.ttf");

/// Registers [`FONT_TTF`] as [`FONT`] with plotters, once per process.
fn register_font() -> PlotResult {
    static REGISTERED: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    let ok = *REGISTERED.get_or_init(|| {
        [FontStyle::Normal, FontStyle::Bold]
            .into_iter()
            .all(|style| plotters::style::register_font(FONT, style, FONT_TTF).is_ok())
    });
    if ok {
        Ok(())
    } else {
        Err(PlotError(
            "the embedded chart font could not be read".into(),
        ))
    }
}

/// Matplotlib's "tab10" blue.
pub const TAB_BLUE: RGBColor = RGBColor(31, 119, 180);
/// "tab10" orange.
pub const TAB_ORANGE: RGBColor = RGBColor(255, 127, 14);
/// "tab10" green.
pub const TAB_GREEN: RGBColor = RGBColor(44, 160, 44);
/// "tab10" red.
pub const TAB_RED: RGBColor = RGBColor(214, 39, 40);
/// "tab10" purple.
pub const TAB_PURPLE: RGBColor = RGBColor(148, 103, 189);

/// Series colours in order (the first eight of "tab10").
pub const PALETTE: [RGBColor; 8] = [
    TAB_BLUE,
    TAB_ORANGE,
    TAB_GREEN,
    TAB_RED,
    TAB_PURPLE,
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(23, 190, 207),
];

/// The `i`-th series colour, cycling through [`PALETTE`].
pub fn palette(i: usize) -> RGBColor {
    PALETTE[i % PALETTE.len()]
}

/// A chart panel's frame: caption size, margin and the label areas, all in pixels.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Frame {
    /// Caption font size.
    pub caption_px: u32,
    /// Margin around the panel.
    pub margin_px: u32,
    /// Height of the x label area (below).
    pub x_label_px: u32,
    /// Width of the y label area (left).
    pub y_label_px: u32,
    /// Width of a right-hand y label area (a secondary axis), 0 for none.
    pub right_y_label_px: u32,
    /// Whether text is drawn: without it, no caption and no label areas (PNG).
    pub text: bool,
}

impl Frame {
    /// A frame with text and no right-hand axis.
    pub const fn new(caption_px: u32, margin_px: u32, x_label_px: u32, y_label_px: u32) -> Frame {
        Frame {
            caption_px,
            margin_px,
            x_label_px,
            y_label_px,
            right_y_label_px: 0,
            text: true,
        }
    }

    /// The same frame with a right-hand label area of `px` (for a secondary y axis).
    pub const fn right_y(self, px: u32) -> Frame {
        Frame {
            right_y_label_px: px,
            ..self
        }
    }

    /// The same frame with text drawn or not (see [`Format::has_text`]).
    pub const fn text(self, text: bool) -> Frame {
        Frame { text, ..self }
    }

    /// A chart builder on `area` with this frame and, if text is drawn, the caption `title`.
    pub fn builder<'a, 'b, DB: DrawingBackend>(
        &self,
        area: &'a DrawingArea<DB, Shift>,
        title: Option<&str>,
    ) -> ChartBuilder<'a, 'b, DB> {
        let mut b = ChartBuilder::on(area);
        b.margin(self.margin_px);
        if self.text {
            b.x_label_area_size(self.x_label_px)
                .y_label_area_size(self.y_label_px);
            if self.right_y_label_px > 0 {
                b.right_y_label_area_size(self.right_y_label_px);
            }
            if let Some(t) = title {
                b.caption(t, (FONT, self.caption_px));
            }
        }
        b
    }
}

/// The mesh (grid and axes) of `chart` with axis descriptions, or with no labels at all when
/// `text` is false; add formatters if needed, then `.draw()?`.
pub fn mesh<'a, 'b, DB, X, Y, XT, YT>(
    chart: &'b mut ChartContext<'a, DB, Cartesian2d<X, Y>>,
    x_desc: &str,
    y_desc: &str,
    text: bool,
) -> MeshStyle<'a, 'b, X, Y, DB>
where
    DB: DrawingBackend,
    X: Ranged<ValueType = XT> + ValueFormatter<XT>,
    Y: Ranged<ValueType = YT> + ValueFormatter<YT>,
{
    let mut m = chart.configure_mesh();
    if text {
        m.x_desc(x_desc).y_desc(y_desc);
    } else {
        m.x_labels(0).y_labels(0);
    }
    m
}

/// Axis label `1e-3` style (log axes of errors).
pub fn sci(v: &f64) -> String {
    format!("{v:.0e}")
}

/// Axis label as a whole number (log axes of counts).
pub fn whole(v: &f64) -> String {
    format!("{v:.0}")
}

/// The legend key of a line series: a short line in its style.
pub fn line_key(style: ShapeStyle) -> impl Fn((i32, i32)) -> PathElement<(i32, i32)> {
    move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], style)
}

/// Draws a line through `points` in `style`; with a `label`, also its legend entry.
pub fn line<DB, CT>(
    chart: &mut ChartContext<'_, DB, CT>,
    points: impl IntoIterator<Item = CT::From>,
    style: impl Into<ShapeStyle>,
    label: Option<&str>,
) -> PlotResult
where
    DB: DrawingBackend,
    CT: CoordTranslate,
    CT::From: Clone + 'static,
{
    let style = style.into();
    let anno = chart.draw_series(LineSeries::new(points, style))?;
    if let Some(l) = label {
        anno.label(l).legend(line_key(style));
    }
    Ok(())
}

/// Thin grey vertical lines from `lo` to `hi` at each `x` (phase changes).
pub fn marks<DB, CT>(
    chart: &mut ChartContext<'_, DB, CT>,
    xs: impl IntoIterator<Item = f64>,
    lo: f64,
    hi: f64,
) -> PlotResult
where
    DB: DrawingBackend,
    CT: CoordTranslate<From = (f64, f64)>,
{
    for x in xs {
        chart.draw_series(LineSeries::new(
            [(x, lo), (x, hi)],
            BLACK.mix(0.3).stroke_width(1),
        ))?;
    }
    Ok(())
}

/// A filled dot of `radius_px` at `at` with `text` (12 px, black) beside it.
pub fn labelled_point<DB, CT>(
    chart: &mut ChartContext<'_, DB, CT>,
    at: CT::From,
    radius_px: u32,
    colour: RGBColor,
    text: &str,
) -> PlotResult
where
    DB: DrawingBackend,
    CT: CoordTranslate,
    CT::From: Clone + 'static,
{
    chart.draw_series(std::iter::once(Circle::new(
        at.clone(),
        radius_px,
        colour.filled(),
    )))?;
    chart.draw_series(std::iter::once(Text::new(
        text.to_string(),
        at,
        (FONT, 12).into_font().color(&BLACK),
    )))?;
    Ok(())
}

/// The legend box of the labelled series at `position`, on a translucent white background.
pub fn legend<'a, DB, CT>(
    chart: &mut ChartContext<'a, DB, CT>,
    position: SeriesLabelPosition,
) -> PlotResult
where
    DB: DrawingBackend + 'a,
    CT: CoordTranslate,
{
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .position(position)
        .draw()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    struct Two;

    impl Figure for Two {
        fn draw<DB: DrawingBackend>(
            &self,
            root: &DrawingArea<DB, Shift>,
            format: Format,
        ) -> PlotResult {
            let frame = Frame::new(18, 10, 35, 55).text(format.has_text());
            let mut chart = frame
                .builder(root, Some("two lines"))
                .build_cartesian_2d(0f64..10f64, 0f64..10f64)?;
            mesh(&mut chart, "x (s)", "y (W)", format.has_text()).draw()?;
            let label = |s| format.has_text().then_some(s);
            line(
                &mut chart,
                [(0.0, 1.0), (10.0, 9.0)],
                palette(0).stroke_width(2),
                label("rising"),
            )?;
            line(
                &mut chart,
                [(0.0, 9.0), (10.0, 1.0)],
                TAB_RED,
                label("falling"),
            )?;
            marks(&mut chart, [5.0], 0.0, 10.0)?;
            if format.has_text() {
                labelled_point(&mut chart, (5.0, 5.0), 4, TAB_GREEN, "cross")?;
                legend(&mut chart, SeriesLabelPosition::UpperRight)?;
            }
            Ok(())
        }
    }

    #[test]
    fn figures_are_written_by_extension_and_others_refused() {
        let dir = std::env::temp_dir().join(format!("morphlink-plot-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        write(&dir.join("a.svg"), (400, 300), &Two).unwrap();
        write(&dir.join("a.PNG"), (400, 300), &Two).unwrap();
        let svg = std::fs::read_to_string(dir.join("a.svg")).unwrap();
        for s in [
            "<svg",
            "two lines",
            "rising",
            "falling",
            "cross",
            "x (s)",
            "y (W)",
        ] {
            assert!(svg.contains(s), "{s} missing from the SVG");
        }
        assert!(std::fs::read(dir.join("a.PNG"))
            .unwrap()
            .starts_with(b"\x89PNG"));
        let e = write(&dir.join("a.txt"), (400, 300), &Two).unwrap_err();
        assert!(e.0.contains("must end in .svg or .png"), "{e}");
        assert!(!dir.join("a.txt").exists());
        write_svg(&dir.join("b.svg"), (300, 200), |root| {
            let mut c = Frame::new(20, 15, 45, 70)
                .builder(root, Some("log axes"))
                .build_cartesian_2d((1.0..100.0).log_scale(), (1e-4..1.0).log_scale())?;
            mesh(&mut c, "entries", "error", true)
                .x_label_formatter(&whole)
                .y_label_formatter(&sci)
                .draw()?;
            Ok(())
        })
        .unwrap();
        assert!(std::fs::read_to_string(dir.join("b.svg"))
            .unwrap()
            .contains("log axes"));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn png_text_is_drawn_with_the_embedded_font() {
        let (w, h) = (200u32, 40u32);
        let ink = |text: &str| -> usize {
            let mut buf = vec![255u8; (w * h * 3) as usize];
            {
                let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
                register_font().unwrap();
                root.draw(&Text::new(
                    text.to_string(),
                    (5, 5),
                    (FONT, 20).into_font().color(&BLACK),
                ))
                .unwrap();
                root.present().unwrap();
            }
            buf.iter().filter(|&&b| b < 128).count()
        };
        assert_eq!(ink(""), 0);
        let one = ink("l");
        let word = ink("MORPH 38 closed");
        assert!(one > 0, "no pixel drawn for a glyph");
        assert!(
            word > 10 * one,
            "{word} dark bytes for a word, {one} for one glyph"
        );
    }

    #[test]
    fn palette_cycles_and_errors_become_strings() {
        assert_eq!(palette(0), TAB_BLUE);
        assert_eq!(palette(3), TAB_RED);
        assert_eq!(palette(8), palette(0));
        let s: String = PlotError("boom".into()).into();
        assert_eq!(s, "boom");
    }
}
