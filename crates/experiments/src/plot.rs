//! Figures of the experiment reports, each written as PNG and SVG: stacked time series (the
//! style of the paper's Fig. 5), grouped bars with confidence intervals and the paper's values,
//! paths on the field (Fig. 4), and trade-offs between two measures with a third as point size.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use anyhow::{Result, anyhow};
use plotters::coord::Shift;
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;

use super::stats::Estimate;

/// DejaVu Sans (Bitstream Vera licence, `assets/DejaVuSans-LICENSE.txt`): bitmap text needs a
/// font file and the machines running experiments may have none installed.
const FONT: &[u8] = include_bytes!("../assets/DejaVuSans.ttf");
const FAMILY: &str = "sans-serif";

const COLOURS: [RGBColor; 8] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(127, 127, 127),
];

pub fn colour(i: usize) -> RGBColor {
    COLOURS[i % COLOURS.len()]
}

fn ensure_font() -> Result<()> {
    static REGISTERED: OnceLock<bool> = OnceLock::new();
    let ok = *REGISTERED
        .get_or_init(|| plotters::style::register_font(FAMILY, FontStyle::Normal, FONT).is_ok());
    if ok { Ok(()) } else { Err(anyhow!("the bundled font cannot be loaded")) }
}

/// A figure that can draw itself on any plotters backend.
pub trait Figure {
    fn size(&self) -> (u32, u32);
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), String>;
}

/// Writes `dir/stem.png` and `dir/stem.svg`; returns both paths.
pub fn save(figure: &impl Figure, dir: &Path, stem: &str) -> Result<Vec<PathBuf>> {
    ensure_font()?;
    let png = dir.join(format!("{stem}.png"));
    let svg = dir.join(format!("{stem}.svg"));
    {
        let root = BitMapBackend::new(&png, figure.size()).into_drawing_area();
        figure.draw(&root).map_err(|e| anyhow!("drawing {}: {e}", png.display()))?;
        root.present().map_err(|e| anyhow!("writing {}: {e}", png.display()))?;
    }
    {
        let root = SVGBackend::new(&svg, figure.size()).into_drawing_area();
        figure.draw(&root).map_err(|e| anyhow!("drawing {}: {e}", svg.display()))?;
        root.present().map_err(|e| anyhow!("writing {}: {e}", svg.display()))?;
    }
    Ok(vec![png, svg])
}

fn s<E: std::fmt::Display>(e: E) -> String {
    e.to_string()
}

/// One line of a chart.
#[derive(Clone, Debug)]
pub struct Series {
    pub name: String,
    pub points: Vec<(f64, f64)>,
    pub colour: usize,
}

/// One chart of a stack.
#[derive(Clone, Debug)]
pub struct Panel {
    pub title: String,
    pub y_label: String,
    pub y_range: Option<(f64, f64)>,
    pub series: Vec<Series>,
}

/// Charts stacked vertically over a common x axis.
#[derive(Clone, Debug)]
pub struct Stack {
    pub title: String,
    pub x_label: String,
    pub panels: Vec<Panel>,
}

fn range_of(points: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = points
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| (lo.min(v), hi.max(v)));
    if !lo.is_finite() {
        return (0.0, 1.0);
    }
    if hi - lo < 1e-9 { (lo - 0.5, hi + 0.5) } else { (lo, hi) }
}

/// Axes with their descriptions and the grid's minor lines hidden, as every line plot here has
/// them.
fn draw_axes<DB: DrawingBackend>(
    chart: &mut ChartContext<'_, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>,
    x_label: &str,
    y_label: &str,
) -> Result<(), String> {
    chart
        .configure_mesh()
        .x_desc(x_label)
        .y_desc(y_label)
        .label_style((FAMILY, 12))
        .axis_desc_style((FAMILY, 13))
        .light_line_style(WHITE.mix(0.0))
        .draw()
        .map_err(s)
}

impl Figure for Stack {
    fn size(&self) -> (u32, u32) {
        (1000, 60 + 230 * self.panels.len().max(1) as u32)
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), String> {
        root.fill(&WHITE).map_err(s)?;
        let body = root.titled(&self.title, (FAMILY, 22)).map_err(s)?;
        let areas = body.split_evenly((self.panels.len().max(1), 1));
        let (x0, x1) = range_of(
            self.panels.iter().flat_map(|p| &p.series).flat_map(|s| &s.points).map(|p| p.0),
        );
        for (panel, area) in self.panels.iter().zip(areas.iter()) {
            let (y0, y1) = panel.y_range.unwrap_or_else(|| {
                let (lo, hi) = range_of(panel.series.iter().flat_map(|s| &s.points).map(|p| p.1));
                let pad = 0.05 * (hi - lo);
                (lo - pad, hi + pad)
            });
            let mut chart = ChartBuilder::on(area)
                .caption(&panel.title, (FAMILY, 16))
                .margin(8)
                .x_label_area_size(30)
                .y_label_area_size(55)
                .build_cartesian_2d(x0..x1, y0..y1)
                .map_err(s)?;
            draw_axes(&mut chart, &self.x_label, &panel.y_label)?;
            for series in &panel.series {
                let c = colour(series.colour);
                chart
                    .draw_series(LineSeries::new(series.points.iter().copied(), c.stroke_width(2)))
                    .map_err(s)?
                    .label(series.name.as_str())
                    .legend(move |(x, y)| {
                        PathElement::new(vec![(x, y), (x + 18, y)], c.stroke_width(2))
                    });
            }
            if !panel.series.is_empty() {
                chart
                    .configure_series_labels()
                    .background_style(WHITE.mix(0.85))
                    .border_style(BLACK.mix(0.4))
                    .label_font((FAMILY, 12))
                    .position(SeriesLabelPosition::UpperRight)
                    .draw()
                    .map_err(s)?;
            }
        }
        Ok(())
    }
}

/// Grouped bars: one group per condition, one bar per series, each with its 95% confidence
/// interval; optional reference marks (the paper's values) per group.
#[derive(Clone, Debug)]
pub struct Bars {
    pub title: String,
    pub y_label: String,
    pub groups: Vec<String>,
    pub series: Vec<(String, Vec<Estimate>)>,
    /// The paper's value per group, drawn as a black bar across the group.
    pub reference: Option<(String, Vec<Option<f64>>)>,
    /// A horizontal target line per group (drawn dashed across the group).
    pub targets: Option<(String, Vec<Option<f64>>)>,
}

impl Figure for Bars {
    fn size(&self) -> (u32, u32) {
        (1000, 520)
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), String> {
        root.fill(&WHITE).map_err(s)?;
        let n = self.groups.len().max(1);
        let values = self
            .series
            .iter()
            .flat_map(|(_, v)| v.iter().map(|e| e.high()))
            .chain(self.reference.iter().flat_map(|(_, v)| v.iter().flatten().copied()))
            .chain(self.targets.iter().flat_map(|(_, v)| v.iter().flatten().copied()));
        let (_, hi) = range_of(values);
        // Room above the tallest bar for the legend in the upper right, so it hides no bar.
        let entries = self.series.len()
            + usize::from(self.reference.is_some())
            + usize::from(self.targets.is_some());
        let y1 = (hi * (1.1 + 0.06 * entries as f64)).max(1e-6);
        let mut chart = ChartBuilder::on(root)
            .caption(&self.title, (FAMILY, 20))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(60)
            .build_cartesian_2d(0.0..n as f64, 0.0..y1)
            .map_err(s)?;
        chart
            .configure_mesh()
            .disable_x_mesh()
            .x_labels(0)
            .y_desc(self.y_label.as_str())
            .label_style((FAMILY, 12))
            .axis_desc_style((FAMILY, 13))
            .draw()
            .map_err(s)?;
        let k = self.series.len().max(1) as f64;
        let width = 0.8 / k;
        for (si, (name, estimates)) in self.series.iter().enumerate() {
            let c = colour(si);
            let mut bars = Vec::new();
            let mut whiskers = Vec::new();
            for (g, e) in estimates.iter().enumerate().take(n) {
                if !e.mean.is_finite() {
                    continue;
                }
                let left = g as f64 + 0.1 + si as f64 * width;
                let right = left + width * 0.92;
                bars.push(Rectangle::new([(left, 0.0), (right, e.mean.max(0.0))], c.filled()));
                if e.n >= 2 && e.ci95.is_finite() {
                    let mid = 0.5 * (left + right);
                    let cap = 0.25 * (right - left);
                    whiskers.push(PathElement::new(
                        vec![(mid, e.low().max(0.0)), (mid, e.high())],
                        BLACK.stroke_width(1),
                    ));
                    whiskers.push(PathElement::new(
                        vec![(mid - cap, e.high()), (mid + cap, e.high())],
                        BLACK.stroke_width(1),
                    ));
                    whiskers.push(PathElement::new(
                        vec![(mid - cap, e.low().max(0.0)), (mid + cap, e.low().max(0.0))],
                        BLACK.stroke_width(1),
                    ));
                }
            }
            chart
                .draw_series(bars)
                .map_err(s)?
                .label(name.as_str())
                .legend(move |(x, y)| Rectangle::new([(x, y - 5), (x + 14, y + 5)], c.filled()));
            chart.draw_series(whiskers).map_err(s)?;
        }
        for (marks, style) in [
            (&self.reference, BLACK.stroke_width(3)),
            (&self.targets, RGBColor(200, 0, 0).stroke_width(2)),
        ] {
            if let Some((name, values)) = marks {
                let lines: Vec<_> = values
                    .iter()
                    .enumerate()
                    .filter_map(|(g, v)| {
                        v.map(|v| {
                            PathElement::new(
                                vec![(g as f64 + 0.05, v), (g as f64 + 0.95, v)],
                                style,
                            )
                        })
                    })
                    .collect();
                if !lines.is_empty() {
                    chart
                        .draw_series(lines)
                        .map_err(s)?
                        .label(name.as_str())
                        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], style));
                }
            }
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK.mix(0.4))
            .label_font((FAMILY, 12))
            .position(SeriesLabelPosition::UpperRight)
            .draw()
            .map_err(s)?;
        // Group names under the axis, at the groups' pixel positions.
        for (g, label) in self.groups.iter().enumerate() {
            let (px, py) = chart.backend_coord(&(g as f64 + 0.5, 0.0));
            let style = TextStyle::from((FAMILY, 13).into_font()).pos(
                plotters::style::text_anchor::Pos::new(
                    plotters::style::text_anchor::HPos::Center,
                    plotters::style::text_anchor::VPos::Top,
                ),
            );
            root.draw(&Text::new(label.clone(), (px, py + 8), style)).map_err(s)?;
        }
        Ok(())
    }
}

/// Paths on the field, with the field's outline: the paper's Fig. 4.
#[derive(Clone, Debug)]
pub struct FieldPaths {
    pub title: String,
    /// Field lines and goals, drawn grey.
    pub outline: Vec<Vec<(f64, f64)>>,
    pub paths: Vec<Series>,
    /// Half extents of the view, m.
    pub half_extent: (f64, f64),
}

impl Figure for FieldPaths {
    fn size(&self) -> (u32, u32) {
        let (hx, hy) = self.half_extent;
        let w = 900u32;
        (w, ((f64::from(w) - 80.0) * hy / hx.max(1e-3)) as u32 + 110)
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), String> {
        root.fill(&RGBColor(235, 245, 235)).map_err(s)?;
        let (hx, hy) = self.half_extent;
        let mut chart = ChartBuilder::on(root)
            .caption(&self.title, (FAMILY, 20))
            .margin(12)
            .x_label_area_size(30)
            .y_label_area_size(45)
            .build_cartesian_2d(-hx..hx, -hy..hy)
            .map_err(s)?;
        chart
            .configure_mesh()
            .disable_mesh()
            .x_desc("x (m)")
            .y_desc("y (m)")
            .label_style((FAMILY, 12))
            .draw()
            .map_err(s)?;
        let grey = RGBColor(120, 120, 120);
        for line in &self.outline {
            chart
                .draw_series(LineSeries::new(line.iter().copied(), grey.stroke_width(2)))
                .map_err(s)?;
        }
        for path in &self.paths {
            let c = colour(path.colour);
            chart
                .draw_series(LineSeries::new(path.points.iter().copied(), c.stroke_width(3)))
                .map_err(s)?
                .label(path.name.as_str())
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 18, y)], c.stroke_width(3))
                });
            if let Some(&(x, y)) = path.points.first() {
                chart.draw_series([Circle::new((x, y), 4, c.filled())]).map_err(s)?;
            }
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK.mix(0.4))
            .label_font((FAMILY, 12))
            .position(SeriesLabelPosition::LowerRight)
            .draw()
            .map_err(s)?;
        Ok(())
    }
}

/// One point of a [`Tradeoff`]: a method's two measures with their confidence intervals, and a
/// third measure shown as the point's size.
#[derive(Clone, Debug)]
pub struct TradeoffPoint {
    pub name: String,
    pub x: Estimate,
    pub y: Estimate,
    pub size: f64,
    pub colour: usize,
}

/// Two measures where lower is better on both, one point per method with 95% confidence
/// intervals as whiskers, a third measure as the point's size: the points nearest the origin
/// are the Pareto front.
#[derive(Clone, Debug)]
pub struct Tradeoff {
    pub title: String,
    pub x_label: String,
    pub y_label: String,
    /// What the size shows, for the legend ("goal coverage").
    pub size_label: String,
    /// How a point's size value is written in the legend.
    pub size_unit: (f64, String),
    pub points: Vec<TradeoffPoint>,
}

impl Tradeoff {
    /// The radius of each point, px: the size values' span mapped onto 5..=22 px, so that
    /// differences of a few percent stay visible (the legend gives the values).
    fn radii(&self) -> Vec<i32> {
        let (lo, hi) = range_of(self.points.iter().map(|p| p.size));
        self.points
            .iter()
            .map(|p| {
                let t = if p.size.is_finite() && hi > lo { (p.size - lo) / (hi - lo) } else { 0.5 };
                (5.0 + 17.0 * t.clamp(0.0, 1.0)).round() as i32
            })
            .collect()
    }
}

impl Figure for Tradeoff {
    fn size(&self) -> (u32, u32) {
        (900, 650)
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), String> {
        root.fill(&WHITE).map_err(s)?;
        let pad = |(lo, hi): (f64, f64)| {
            let span = (hi - lo).max(1e-6);
            ((lo - 0.15 * span).min(0.0).max(lo - span), hi + 0.35 * span)
        };
        let finite = |e: &Estimate| e.mean.is_finite();
        let (x0, x1) = pad(range_of(
            self.points
                .iter()
                .filter(|p| finite(&p.x))
                .flat_map(|p| [p.x.low(), p.x.high(), p.x.mean]),
        ));
        let (y0, y1) = pad(range_of(
            self.points
                .iter()
                .filter(|p| finite(&p.y))
                .flat_map(|p| [p.y.low(), p.y.high(), p.y.mean]),
        ));
        let mut chart = ChartBuilder::on(root)
            .caption(&self.title, (FAMILY, 20))
            .margin(14)
            .x_label_area_size(40)
            .y_label_area_size(60)
            .build_cartesian_2d(x0..x1, y0..y1)
            .map_err(s)?;
        draw_axes(&mut chart, &self.x_label, &self.y_label)?;
        for (point, radius) in self.points.iter().zip(self.radii()) {
            if !finite(&point.x) || !finite(&point.y) {
                continue;
            }
            let c = colour(point.colour);
            let (x, y) = (point.x.mean, point.y.mean);
            let mut whiskers = Vec::new();
            if point.x.n >= 2 && point.x.ci95.is_finite() {
                whiskers.push(PathElement::new(vec![(point.x.low(), y), (point.x.high(), y)], c));
            }
            if point.y.n >= 2 && point.y.ci95.is_finite() {
                whiskers.push(PathElement::new(vec![(x, point.y.low()), (x, point.y.high())], c));
            }
            chart.draw_series(whiskers).map_err(s)?;
            let (scale, unit) = &self.size_unit;
            let label =
                format!("{} ({} {:.1}{unit})", point.name, self.size_label, point.size * scale);
            chart
                .draw_series([Circle::new((x, y), radius, c.mix(0.55).filled())])
                .map_err(s)?
                .label(label)
                .legend(move |(x, y)| Circle::new((x + 7, y), 6, c.filled()));
            chart.draw_series([Circle::new((x, y), radius, c.stroke_width(2))]).map_err(s)?;
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK.mix(0.4))
            .label_font((FAMILY, 12))
            .position(SeriesLabelPosition::UpperRight)
            .draw()
            .map_err(s)?;
        Ok(())
    }
}

/// Histogram-like bars of discrete distributions (strikers per team), one group per condition.
pub fn distribution_bars(
    title: &str,
    y_label: &str,
    groups: Vec<String>,
    categories: &[&str],
    values: &[Vec<Estimate>],
) -> Bars {
    Bars {
        title: title.to_owned(),
        y_label: y_label.to_owned(),
        groups,
        series: categories
            .iter()
            .enumerate()
            .map(|(c, name)| {
                (
                    (*name).to_owned(),
                    values.iter().map(|g| g.get(c).copied().unwrap_or_default()).collect(),
                )
            })
            .collect(),
        reference: None,
        targets: None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn figures_are_written_as_png_and_svg_with_text() {
        let dir = std::env::temp_dir().join(format!("strata-plot-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        let stack = Stack {
            title: "scores".into(),
            x_label: "t (s)".into(),
            panels: vec![Panel {
                title: "final score".into(),
                y_label: "score".into(),
                y_range: Some((0.0, 1.0)),
                series: vec![Series {
                    name: "ball".into(),
                    points: (0..50)
                        .map(|i| (f64::from(i) * 0.1, 0.5 + 0.01 * f64::from(i)))
                        .collect(),
                    colour: 0,
                }],
            }],
        };
        let files = save(&stack, &dir, "stack").expect("written");
        let bars = Bars {
            title: "ball unknown".into(),
            y_label: "%".into(),
            groups: vec!["0.5 Hz".into(), "1 Hz".into()],
            series: vec![("a".into(), vec![Estimate::of(&[1.0, 2.0]), Estimate::of(&[3.0])])],
            reference: Some(("paper".into(), vec![Some(2.0), None])),
            targets: None,
        };
        let more = save(&bars, &dir, "bars").expect("written");
        let tradeoff = Tradeoff {
            title: "pareto".into(),
            x_label: "ball unknown (%)".into(),
            y_label: "pose error (cm)".into(),
            size_label: "coverage".into(),
            size_unit: (100.0, " %".into()),
            points: vec![
                TradeoffPoint {
                    name: "value-function".into(),
                    x: Estimate::of(&[1.0, 2.0, 3.0]),
                    y: Estimate::of(&[2.5, 2.9]),
                    size: 0.55,
                    colour: 0,
                },
                TradeoffPoint {
                    name: "entropy".into(),
                    x: Estimate::of(&[0.5]),
                    y: Estimate::of(&[f64::NAN]),
                    size: 0.5,
                    colour: 1,
                },
            ],
        };
        let tradeoffs = save(&tradeoff, &dir, "tradeoff").expect("written");
        let svg = std::fs::read_to_string(dir.join("tradeoff.svg")).expect("svg");
        // A point without a mean is left out rather than drawn at the origin.
        assert!(svg.contains("value-function (coverage 55.0 %)") && !svg.contains("entropy ("));
        for file in files.iter().chain(&more).chain(&tradeoffs) {
            let len = std::fs::metadata(file).expect("exists").len();
            assert!(len > 1000, "{}: {len} bytes", file.display());
        }
        let svg = std::fs::read_to_string(dir.join("bars.svg")).expect("svg");
        assert!(svg.contains("0.5 Hz") && svg.contains("paper"));
        let _ = std::fs::remove_dir_all(&dir);
    }
}
