//! Line charts written both as PNG and SVG, drawn with `plotters`.
//!
//! Text is rendered with DejaVu Sans (from the `dejavu` crate, embedded in the
//! binary and registered with `plotters`' `ab_glyph` font table), so drawing
//! needs no system font library.

use std::ffi::OsString;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use plotters::coord::Shift;
use plotters::coord::ranged1d::{AsRangedCoord, ValueFormatter};
use plotters::prelude::*;

/// Width and height of the PNG (and of the SVG canvas), in pixels.
const SIZE: (u32, u32) = (1024, 640);

/// Font family the embedded font is registered under; `plotters` uses it for
/// every text it draws by default.
const FONT_FAMILY: &str = "sans-serif";

/// Line colours, taken in turn by the series (Tableau 10, less its pale ones).
const COLOURS: [RGBColor; 8] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(23, 190, 207),
];

/// One named line.
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    /// Name shown in the legend.
    pub name: String,
    /// The `(x, y)` points, joined in this order.
    pub points: Vec<(f64, f64)>,
}

/// A line chart.
#[derive(Debug, Clone, PartialEq)]
pub struct Chart {
    /// Caption above the plot.
    pub title: String,
    /// Description of the x axis.
    pub x_label: String,
    /// Description of the y axis.
    pub y_label: String,
    /// Shown x interval `(min, max)`.
    pub x_range: (f64, f64),
    /// Shown y interval `(min, max)`; both must be positive when `log_y` is set.
    pub y_range: (f64, f64),
    /// The lines, drawn in order, each in its own colour.
    pub series: Vec<Series>,
    /// Logarithmic y axis; points with `y <= 0` are then left out.
    pub log_y: bool,
    /// Corner of the legend (pick the one the lines leave free).
    pub legend: Corner,
}

/// A corner of the plotting area.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Corner {
    /// Top left.
    UpperLeft,
    /// Top right.
    UpperRight,
    /// Bottom left.
    LowerLeft,
    /// Bottom right.
    LowerRight,
}

/// Why a chart could not be drawn.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    /// Drawing the chart or writing its file failed.
    #[error("cannot draw {path}: {message}")]
    Draw {
        /// The file being drawn.
        path: PathBuf,
        /// What `plotters` (or the check of the chart) reported.
        message: String,
    },
}

/// Draws `chart` to `<stem>.png` (1024x640) and `<stem>.svg`; returns the two paths.
///
/// The extensions are appended to `stem` (`runs/loss.v2` gives
/// `runs/loss.v2.png`); its folder must exist. Non-finite points are left out.
pub fn draw(chart: &Chart, stem: &Path) -> Result<[PathBuf; 2], PlotError> {
    let png = with_suffix(stem, ".png");
    let svg = with_suffix(stem, ".svg");
    let fail = |path: &Path, message: String| PlotError::Draw {
        path: path.to_path_buf(),
        message,
    };

    check(chart).map_err(|m| fail(&png, m))?;
    register_embedded_font().map_err(|m| fail(&png, m))?;

    let root = BitMapBackend::new(&png, SIZE).into_drawing_area();
    render(&root, chart).map_err(|m| fail(&png, m))?;
    drop(root);

    let root = SVGBackend::new(&svg, SIZE).into_drawing_area();
    render(&root, chart).map_err(|m| fail(&svg, m))?;
    drop(root);

    Ok([png, svg])
}

/// `stem` with `suffix` appended to its last component.
fn with_suffix(stem: &Path, suffix: &str) -> PathBuf {
    let mut name = OsString::from(stem.as_os_str());
    name.push(suffix);
    PathBuf::from(name)
}

/// Rejects ranges `plotters` cannot map.
fn check(chart: &Chart) -> Result<(), String> {
    let ok = |(lo, hi): (f64, f64)| lo.is_finite() && hi.is_finite() && lo < hi;
    if !ok(chart.x_range) {
        return Err(format!("bad x range {:?}", chart.x_range));
    }
    if !ok(chart.y_range) {
        return Err(format!("bad y range {:?}", chart.y_range));
    }
    if chart.log_y && chart.y_range.0 <= 0.0 {
        return Err(format!("log y range {:?} is not positive", chart.y_range));
    }
    Ok(())
}

/// Registers the embedded DejaVu Sans as [`FONT_FAMILY`], once per process.
fn register_embedded_font() -> Result<(), String> {
    static REGISTERED: OnceLock<bool> = OnceLock::new();
    let ok = *REGISTERED.get_or_init(|| {
        plotters::style::register_font(FONT_FAMILY, FontStyle::Normal, dejavu::sans::regular())
            .is_ok()
    });
    if ok {
        Ok(())
    } else {
        Err("the embedded font cannot be parsed".to_owned())
    }
}

/// Draws `chart` on `root` and writes the backend's file.
fn render<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, chart: &Chart) -> Result<(), String> {
    let err = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    root.fill(&WHITE).map_err(err)?;
    let mut builder = ChartBuilder::on(root);
    builder
        .caption(&chart.title, (FONT_FAMILY, 28))
        .margin(16)
        .x_label_area_size(56)
        .y_label_area_size(80);
    let x = chart.x_range.0..chart.x_range.1;
    let y = chart.y_range.0..chart.y_range.1;
    if chart.log_y {
        plot_series(&mut builder, chart, x, y.log_scale())?;
    } else {
        plot_series(&mut builder, chart, x, y)?;
    }
    root.present().map_err(err)
}

/// Builds the axes from `x` and `y` and draws mesh, lines, markers and legend.
fn plot_series<DB, X, Y>(
    builder: &mut ChartBuilder<'_, '_, DB>,
    chart: &Chart,
    x: X,
    y: Y,
) -> Result<(), String>
where
    DB: DrawingBackend,
    X: AsRangedCoord<Value = f64>,
    Y: AsRangedCoord<Value = f64>,
    X::CoordDescType: ValueFormatter<f64>,
    Y::CoordDescType: ValueFormatter<f64>,
{
    let err = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    let mut ctx = builder.build_cartesian_2d(x, y).map_err(err)?;
    ctx.configure_mesh()
        .x_desc(chart.x_label.as_str())
        .y_desc(chart.y_label.as_str())
        .axis_desc_style((FONT_FAMILY, 20))
        .label_style((FONT_FAMILY, 16))
        .bold_line_style(RGBColor(210, 210, 210))
        .light_line_style(RGBColor(238, 238, 238))
        .draw()
        .map_err(err)?;

    for (i, series) in chart.series.iter().enumerate() {
        let colour = COLOURS[i % COLOURS.len()];
        let points: Vec<(f64, f64)> = series
            .points
            .iter()
            .copied()
            .filter(|&(px, py)| px.is_finite() && py.is_finite() && (!chart.log_y || py > 0.0))
            .collect();
        ctx.draw_series(LineSeries::new(
            points.iter().copied(),
            colour.stroke_width(2),
        ))
        .map_err(err)?
        .label(series.name.as_str())
        .legend(move |(lx, ly)| {
            EmptyElement::at((lx, ly))
                + PathElement::new([(0, 0), (20, 0)], colour.stroke_width(2))
                + Circle::new((10, 0), 3, colour.filled())
        });
        ctx.draw_series(points.iter().map(|&p| Circle::new(p, 3, colour.filled())))
            .map_err(err)?;
    }

    if !chart.series.is_empty() {
        ctx.configure_series_labels()
            .position(match chart.legend {
                Corner::UpperLeft => SeriesLabelPosition::UpperLeft,
                Corner::UpperRight => SeriesLabelPosition::UpperRight,
                Corner::LowerLeft => SeriesLabelPosition::LowerLeft,
                Corner::LowerRight => SeriesLabelPosition::LowerRight,
            })
            .label_font((FONT_FAMILY, 16))
            .background_style(WHITE)
            .border_style(BLACK)
            .draw()
            .map_err(err)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A fresh folder under the system temp dir, unique to this process and test.
    fn temp_folder(test: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("pcrnet-plot-{}-{test}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    fn two_series(log_y: bool) -> Chart {
        let line = |name: &str, f: fn(f64) -> f64| Series {
            name: name.to_owned(),
            points: (1..=20).map(|i| (f64::from(i), f(f64::from(i)))).collect(),
        };
        Chart {
            title: "Training loss".to_owned(),
            x_label: "epoch".to_owned(),
            y_label: "loss".to_owned(),
            x_range: (0.0, 21.0),
            y_range: if log_y { (1e-3, 10.0) } else { (0.0, 10.0) },
            series: vec![
                line("train-loss", |e| 8.0 / e),
                line("val-loss", |e| 9.0 * (-e / 4.0).exp() + 0.01),
            ],
            log_y,
            legend: Corner::LowerLeft,
        }
    }

    fn check_files(chart: &Chart, test: &str) {
        let dir = temp_folder(test);
        let [png, svg] = draw(chart, &dir.join("chart")).unwrap();
        assert_eq!(png, dir.join("chart.png"));
        assert_eq!(svg, dir.join("chart.svg"));

        let png_bytes = std::fs::read(&png).unwrap();
        assert!(png_bytes.starts_with(b"\x89PNG\r\n\x1a\n"));
        assert!(
            png_bytes.len() > 5 * 1024,
            "PNG is {} bytes",
            png_bytes.len()
        );

        let svg_text = std::fs::read_to_string(&svg).unwrap();
        assert!(svg_text.contains("<svg"));
        for needle in ["train-loss", "val-loss", "Training loss"] {
            assert!(svg_text.contains(needle), "SVG lacks {needle}");
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn draws_png_and_svg() {
        check_files(&two_series(false), "linear");
    }

    #[test]
    fn draws_log_y() {
        check_files(&two_series(true), "log");
    }

    #[test]
    fn log_y_needs_positive_range() {
        let mut chart = two_series(true);
        chart.y_range = (0.0, 10.0);
        let dir = temp_folder("bad-log");
        assert!(matches!(
            draw(&chart, &dir.join("chart")),
            Err(PlotError::Draw { .. })
        ));
        assert!(!dir.join("chart.png").exists());
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
