//! Plain SVG line charts for the offline tools: no plotting crate, just
//! polylines, axes with round-number ticks, and a legend.

use std::fmt::Write;

/// One line on a chart.
pub struct Series {
    pub name: String,
    pub points: Vec<(f64, f64)>,
}

impl Series {
    /// A named series of (x, y) points.
    pub fn new(name: &str, points: Vec<(f64, f64)>) -> Series {
        Series {
            name: name.to_string(),
            points,
        }
    }
}

/// A chart: title, axis labels and series.
pub struct Chart {
    pub title: String,
    pub x_label: String,
    pub y_label: String,
    /// Same scale on both axes (for paths and workspaces).
    pub equal_aspect: bool,
    pub series: Vec<Series>,
}

impl Chart {
    /// The XY view of a tool path: the programmed move end points against
    /// the path `name` took (`points`).
    pub fn xy_path(
        title: &str,
        programmed: &[[f64; 3]],
        name: &str,
        points: Vec<(f64, f64)>,
    ) -> Chart {
        Chart {
            title: title.into(),
            x_label: "X, mm".into(),
            y_label: "Y, mm".into(),
            equal_aspect: true,
            series: vec![
                Series::new(
                    "programmed",
                    programmed.iter().map(|p| (p[0], p[1])).collect(),
                ),
                Series::new(name, points),
            ],
        }
    }
}

const COLOURS: [&str; 6] = [
    "#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b",
];
const WIDTH: f64 = 800.0;
const HEIGHT: f64 = 420.0;
const MARGIN: f64 = 60.0;

/// Round tick spacing giving about `n` ticks over `span`.
fn tick_step(span: f64, n: f64) -> f64 {
    let raw = (span / n).max(1e-12);
    let mag = 10f64.powf(raw.log10().floor());
    [1.0, 2.0, 5.0, 10.0]
        .iter()
        .map(|m| m * mag)
        .find(|s| *s >= raw)
        .unwrap_or(10.0 * mag)
}

fn escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

impl Chart {
    fn render(&self, out: &mut String, top: f64) {
        let all = self
            .series
            .iter()
            .flat_map(|s| s.points.iter())
            .filter(|p| p.0.is_finite() && p.1.is_finite());
        let (mut x0, mut x1, mut y0, mut y1) = (
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
        );
        for &(x, y) in all {
            x0 = x0.min(x);
            x1 = x1.max(x);
            y0 = y0.min(y);
            y1 = y1.max(y);
        }
        if !x0.is_finite() {
            (x0, x1, y0, y1) = (0.0, 1.0, 0.0, 1.0);
        }
        if x1 - x0 < 1e-9 {
            x0 -= 0.5;
            x1 += 0.5;
        }
        if y1 - y0 < 1e-9 {
            y0 -= 0.5;
            y1 += 0.5;
        }
        let (pw, ph) = (WIDTH - 2.0 * MARGIN, HEIGHT - 2.0 * MARGIN);
        let (mut sx, mut sy) = (pw / (x1 - x0), ph / (y1 - y0));
        if self.equal_aspect {
            let s = sx.min(sy);
            sx = s;
            sy = s;
        }
        let px = |x: f64| MARGIN + (x - x0) * sx;
        let py = |y: f64| top + MARGIN + ph - (y - y0) * sy;
        let _ = writeln!(
            out,
            r#"<text x="{}" y="{}" font-size="16" text-anchor="middle">{}</text>"#,
            WIDTH / 2.0,
            top + 30.0,
            escape(&self.title)
        );
        let _ = writeln!(
            out,
            r##"<rect x="{MARGIN}" y="{}" width="{pw}" height="{ph}" fill="none" stroke="#888"/>"##,
            top + MARGIN
        );
        let step = tick_step(x1 - x0, 8.0);
        let mut t = (x0 / step).ceil() * step;
        while t <= x1 + 1e-9 && px(t) <= MARGIN + pw + 1e-6 {
            let _ = writeln!(
                out,
                r#"<text x="{:.1}" y="{:.1}" font-size="11" text-anchor="middle">{}</text>"#,
                px(t),
                top + MARGIN + ph + 16.0,
                fmt_tick(t, step)
            );
            t += step;
        }
        let step = tick_step(y1 - y0, 6.0);
        let mut t = (y0 / step).ceil() * step;
        while t <= y1 + 1e-9 {
            if py(t) >= top + MARGIN - 1e-6 {
                let _ = writeln!(
                    out,
                    r#"<text x="{:.1}" y="{:.1}" font-size="11" text-anchor="end">{}</text>"#,
                    MARGIN - 6.0,
                    py(t) + 4.0,
                    fmt_tick(t, step)
                );
            }
            t += step;
        }
        let _ = writeln!(
            out,
            r#"<text x="{}" y="{}" font-size="12" text-anchor="middle">{}</text>"#,
            WIDTH / 2.0,
            top + HEIGHT - 12.0,
            escape(&self.x_label)
        );
        let _ = writeln!(
            out,
            r#"<text x="16" y="{}" font-size="12" text-anchor="middle" transform="rotate(-90 16 {})">{}</text>"#,
            top + HEIGHT / 2.0,
            top + HEIGHT / 2.0,
            escape(&self.y_label)
        );
        for (k, s) in self.series.iter().enumerate() {
            let colour = COLOURS[k % COLOURS.len()];
            let mut d = String::new();
            for &(x, y) in s
                .points
                .iter()
                .filter(|p| p.0.is_finite() && p.1.is_finite())
            {
                let _ = write!(d, "{:.2},{:.2} ", px(x), py(y));
            }
            let _ = writeln!(
                out,
                r#"<polyline fill="none" stroke="{colour}" stroke-width="1.2" points="{d}"/>"#
            );
            let _ = writeln!(
                out,
                r#"<text x="{}" y="{}" font-size="12" fill="{colour}">{}</text>"#,
                MARGIN + pw - 120.0,
                top + MARGIN + 16.0 + 16.0 * k as f64,
                escape(&s.name)
            );
        }
    }
}

fn fmt_tick(v: f64, step: f64) -> String {
    let decimals = (-step.log10().floor()).max(0.0) as usize;
    // Ticks accumulate rounding; print a tick at zero as 0, not -0.
    let v = if v.abs() < step * 1e-6 { 0.0 } else { v };
    format!("{v:.decimals$}")
}

/// An SVG document with the charts stacked vertically.
pub fn page(charts: &[Chart]) -> String {
    let mut out = String::new();
    let height = HEIGHT * charts.len() as f64;
    let _ = writeln!(
        out,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{WIDTH}" height="{height}" viewBox="0 0 {WIDTH} {height}" font-family="sans-serif">"#
    );
    let _ = writeln!(out, r#"<rect width="100%" height="100%" fill="white"/>"#);
    for (i, c) in charts.iter().enumerate() {
        c.render(&mut out, HEIGHT * i as f64);
    }
    out.push_str("</svg>\n");
    out
}
