//! `kerf workspace`: what a machine can reach, as numbers and as an SVG.
//!
//! Machines with A and B axes get the tool tip's reachable Z range against
//! tilt; the others an XZ section through their home pose with the largest
//! inscribed axis-aligned rectangle. Both come from
//! [`kerf_machines::workspace`], through the kinematics trait alone.

use std::fmt::Write as _;
use std::path::Path;

use kerf_interp::Axis;
use kerf_machines::workspace::{
    largest_rectangle, xz_section, z_against_tilt, Interval, Rectangle, Section, TiltRow,
};
use kerf_machines::Machine;
use kerf_motion::kinematics::{AxisSpec, Limits};

use super::Failure;

/// Grid of the coarse search for the section's extent, mm.
const COARSE_STEP: f64 = 4.0;
/// Row spacing of the XZ section, mm: the rectangle's z edges fall on rows.
const ROW_STEP: f64 = 0.5;
/// Largest tilt analysed, degrees, and the step between tilts.
const MAX_TILT: f64 = 60.0;
const TILT_STEP: f64 = 1.0;
/// Azimuth sampling for "any direction", degrees.
const AZIMUTH_STEP: f64 = 30.0;
/// Z sampling before bisection in the tilt analysis, mm.
const Z_STEP: f64 = 5.0;

/// Analyse the workspace of `machine_spec`, print it, and draw it into
/// `plot` if given.
pub fn workspace(machine_spec: &str, plot: Option<&Path>) -> Result<(), Failure> {
    let machine = kerf_machines::load(machine_spec).map_err(|e| Failure::new(e.to_string()))?;
    let axes = machine.kinematics.axes();
    let has = |axis: Axis| axes.iter().any(|a| a.axis == axis);
    let svg = if has(Axis::A) && has(Axis::B) && has(Axis::Z) {
        tilt_report(&machine)
    } else if has(Axis::X) && has(Axis::Z) {
        section_report(&machine)
    } else {
        return Err(Failure::new(format!(
            "{}: workspace analysis needs axes X and Z (and A, B for tilt)",
            machine.description.name
        )));
    };
    if let Some(path) = plot {
        std::fs::write(path, svg)
            .map_err(|e| Failure::new(format!("cannot write {}: {e}", path.display())))?;
        println!("plot written to {}", path.display());
    }
    Ok(())
}

fn travel(axes: &[AxisSpec], axis: Axis) -> Option<Limits> {
    axes.iter().find(|a| a.axis == axis).map(|a| a.limits)
}

fn section_report(machine: &Machine) -> String {
    let kins = &*machine.kinematics;
    let home = machine.home();
    let section = xz_section(kins, &home, COARSE_STEP, ROW_STEP);
    let name = &machine.description.name;
    println!(
        "{name}: XZ section of the reachable workspace at y = {:.3} mm ({} kinematics)",
        home.y,
        kins.name()
    );
    let rect = largest_rectangle(&section);
    match (section.rows.first(), section.rows.last()) {
        (Some(first), Some(last)) => {
            let (lo, hi) = section
                .rows
                .iter()
                .flat_map(|r| &r.x)
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), i| {
                    (lo.min(i.lo), hi.max(i.hi))
                });
            println!(
                "reachable      z {:9.3} .. {:9.3} mm, x {:9.3} .. {:9.3} mm",
                first.z, last.z, lo, hi
            );
        }
        _ => println!("nothing is reachable in this section"),
    }
    if let Some(r) = rect {
        println!(
            "largest inscribed rectangle: {:.3} x {:.3} mm (area {:.0} mm²) at x {:.3} .. {:.3}, z {:.3} .. {:.3}",
            r.x.len(),
            r.z.len(),
            r.area(),
            r.x.lo,
            r.x.hi,
            r.z.lo,
            r.z.hi
        );
    }
    let axes = kins.axes();
    if let (Some(tx), Some(tz)) = (travel(axes, Axis::X), travel(axes, Axis::Z)) {
        let inside = rect.is_some_and(|r| {
            r.x.lo <= tx.min && tx.max <= r.x.hi && r.z.lo <= tz.min && tz.max <= r.z.hi
        });
        println!(
            "axis travel    x {:9.3} .. {:9.3} mm, z {:9.3} .. {:9.3} mm ({} the rectangle)",
            tx.min,
            tx.max,
            tz.min,
            tz.max,
            if inside { "inside" } else { "NOT inside" }
        );
    }
    section_svg(machine, &section, rect)
}

fn show(i: Option<Interval>) -> String {
    match i {
        Some(i) => format!("{:8.2} .. {:8.2}", i.lo, i.hi),
        None => format!("{:>20}", "unreachable"),
    }
}

fn tilt_report(machine: &Machine) -> String {
    let kins = &*machine.kinematics;
    let home = machine.home();
    let rows = z_against_tilt(kins, &home, MAX_TILT, TILT_STEP, AZIMUTH_STEP, Z_STEP);
    println!(
        "{}: reachable tool-tip Z (mm) against tilt, at X {:.3} Y {:.3} ({} kinematics)",
        machine.description.name,
        home.x,
        home.y,
        kins.name()
    );
    println!(
        "{:>6}  {:>20}  {:>20}  {:>20}",
        "tilt°", "about X (A)", "about Y (B)", "any direction"
    );
    for row in rows.iter().filter(|r| r.tilt % 5.0 == 0.0) {
        println!(
            "{:>6.1}  {}  {}  {}",
            row.tilt,
            show(row.about_x),
            show(row.about_y),
            show(row.any)
        );
    }
    if let Some(tz) = travel(kins.axes(), Axis::Z) {
        let covered = rows
            .iter()
            .take_while(|r| r.any.is_some_and(|i| i.lo <= tz.min && tz.max <= i.hi))
            .last();
        match covered {
            Some(r) => println!(
                "the whole Z travel {:.3} .. {:.3} is reachable in every direction up to {:.0}° of tilt",
                tz.min, tz.max, r.tilt
            ),
            None => println!(
                "the Z travel {:.3} .. {:.3} is not wholly reachable even untilted",
                tz.min, tz.max
            ),
        }
    }
    tilt_svg(machine, &rows)
}

/// A hand-written SVG chart: data coordinates mapped onto a fixed canvas.
struct Chart {
    x: (f64, f64),
    y: (f64, f64),
    body: String,
    legend: String,
    legend_rows: usize,
}

const WIDTH: f64 = 900.0;
const HEIGHT: f64 = 640.0;
const LEFT: f64 = 80.0;
const RIGHT: f64 = 30.0;
const TOP: f64 = 50.0;
const BOTTOM: f64 = 60.0;

/// A tick label: as many decimals as the spacing needs, and no "-0".
fn tick_label(t: f64, step: f64) -> String {
    let decimals = (-step.log10().floor()).max(0.0) as usize;
    let text = format!("{t:.decimals$}");
    if text
        .trim_start_matches('-')
        .chars()
        .all(|c| c == '0' || c == '.')
    {
        text.trim_start_matches('-').to_string()
    } else {
        text
    }
}

/// A tick spacing of 1, 2 or 5 times a power of ten giving about 8 ticks.
fn tick_step(span: f64) -> f64 {
    let raw = span / 8.0;
    let power = 10f64.powf(raw.log10().floor());
    [1.0, 2.0, 5.0, 10.0]
        .into_iter()
        .map(|m| m * power)
        .find(|s| *s >= raw)
        .unwrap_or(10.0 * power)
}

fn escape(text: &str) -> String {
    text.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

impl Chart {
    /// A chart of data range `x` × `y`; with `equal`, one mm is as long on
    /// both axes (the ranges grow to fit the canvas).
    fn new(mut x: (f64, f64), mut y: (f64, f64), equal: bool) -> Chart {
        if equal {
            let (w, h) = (WIDTH - LEFT - RIGHT, HEIGHT - TOP - BOTTOM);
            let scale = ((x.1 - x.0) / w).max((y.1 - y.0) / h);
            let (cx, cy) = ((x.0 + x.1) / 2.0, (y.0 + y.1) / 2.0);
            x = (cx - scale * w / 2.0, cx + scale * w / 2.0);
            y = (cy - scale * h / 2.0, cy + scale * h / 2.0);
        }
        Chart {
            x,
            y,
            body: String::new(),
            legend: String::new(),
            legend_rows: 0,
        }
    }

    fn px(&self, x: f64) -> f64 {
        LEFT + (x - self.x.0) / (self.x.1 - self.x.0) * (WIDTH - LEFT - RIGHT)
    }

    fn py(&self, y: f64) -> f64 {
        HEIGHT - BOTTOM - (y - self.y.0) / (self.y.1 - self.y.0) * (HEIGHT - TOP - BOTTOM)
    }

    fn rect(&mut self, x: Interval, y: Interval, style: &str) {
        let _ = writeln!(
            self.body,
            r#"<rect x="{:.2}" y="{:.2}" width="{:.2}" height="{:.2}" {style}/>"#,
            self.px(x.lo),
            self.py(y.hi),
            self.px(x.hi) - self.px(x.lo),
            self.py(y.lo) - self.py(y.hi)
        );
    }

    fn polyline(&mut self, points: &[(f64, f64)], style: &str) {
        if points.is_empty() {
            return;
        }
        let path: Vec<String> = points
            .iter()
            .map(|(x, y)| format!("{:.2},{:.2}", self.px(*x), self.py(*y)))
            .collect();
        let fill = if style.contains("fill=") {
            ""
        } else {
            r#"fill="none" "#
        };
        let _ = writeln!(
            self.body,
            r#"<polyline points="{}" {fill}{style}/>"#,
            path.join(" ")
        );
    }

    fn polygon(&mut self, points: &[(f64, f64)], style: &str) {
        let path: Vec<String> = points
            .iter()
            .map(|(x, y)| format!("{:.2},{:.2}", self.px(*x), self.py(*y)))
            .collect();
        let _ = writeln!(
            self.body,
            r#"<polygon points="{}" {style}/>"#,
            path.join(" ")
        );
    }

    fn text(&mut self, x: f64, y: f64, text: &str, style: &str) {
        let _ = writeln!(
            self.body,
            r#"<text x="{x:.1}" y="{y:.1}" {style}>{}</text>"#,
            escape(text)
        );
    }

    /// A legend entry `index` (0 = top) with a swatch drawn in `style`.
    fn legend(&mut self, index: usize, label: &str, style: &str) {
        let y = TOP + 18.0 + 20.0 * index as f64;
        let x = WIDTH - RIGHT - 280.0;
        let _ = writeln!(
            self.legend,
            r#"<rect x="{x:.1}" y="{:.1}" width="22" height="12" {style}/>"#,
            y - 10.0
        );
        let _ = writeln!(
            self.legend,
            r#"<text x="{:.1}" y="{y:.1}" font-size="13">{}</text>"#,
            x + 30.0,
            escape(label)
        );
        self.legend_rows = self.legend_rows.max(index + 1);
    }

    /// Frame, grid, ticks, labels and title around the plotted data.
    fn finish(mut self, title: &str, x_label: &str, y_label: &str) -> String {
        let mut frame = String::new();
        let (x0, x1, y0, y1) = (
            self.px(self.x.0),
            self.px(self.x.1),
            self.py(self.y.0),
            self.py(self.y.1),
        );
        let xs = tick_step(self.x.1 - self.x.0);
        let mut t = (self.x.0 / xs).ceil() * xs;
        while t <= self.x.1 {
            let p = self.px(t);
            let _ = writeln!(
                frame,
                r##"<line x1="{p:.2}" y1="{y1:.2}" x2="{p:.2}" y2="{y0:.2}" stroke="#ddd"/>"##
            );
            let _ = writeln!(
                frame,
                r#"<text x="{p:.2}" y="{:.2}" font-size="12" text-anchor="middle">{}</text>"#,
                y0 + 18.0,
                tick_label(t, xs)
            );
            t += xs;
        }
        let ys = tick_step(self.y.1 - self.y.0);
        let mut t = (self.y.0 / ys).ceil() * ys;
        while t <= self.y.1 {
            let p = self.py(t);
            let _ = writeln!(
                frame,
                r##"<line x1="{x0:.2}" y1="{p:.2}" x2="{x1:.2}" y2="{p:.2}" stroke="#ddd"/>"##
            );
            let _ = writeln!(
                frame,
                r#"<text x="{:.2}" y="{:.2}" font-size="12" text-anchor="end">{}</text>"#,
                x0 - 6.0,
                p + 4.0,
                tick_label(t, ys)
            );
            t += ys;
        }
        let _ = writeln!(
            frame,
            r#"<rect x="{x0:.2}" y="{y1:.2}" width="{:.2}" height="{:.2}" fill="none" stroke="black"/>"#,
            x1 - x0,
            y0 - y1
        );
        // Grid under the data, legend on a white box over it.
        frame.push_str(&self.body);
        self.body = frame;
        if self.legend_rows > 0 {
            let _ = writeln!(
                self.body,
                r##"<rect x="{:.1}" y="{:.1}" width="270" height="{:.1}" fill="white" fill-opacity="0.85" stroke="#999"/>"##,
                WIDTH - RIGHT - 288.0,
                TOP + 2.0,
                20.0 * self.legend_rows as f64 + 8.0
            );
            self.body.push_str(&self.legend);
        }
        self.text(
            WIDTH / 2.0,
            28.0,
            title,
            r#"font-size="16" text-anchor="middle" font-weight="bold""#,
        );
        self.text(
            (x0 + x1) / 2.0,
            HEIGHT - 15.0,
            x_label,
            r#"font-size="14" text-anchor="middle""#,
        );
        let label_y = (y0 + y1) / 2.0;
        let _ = writeln!(
            self.body,
            r#"<text x="20" y="{label_y:.1}" font-size="14" text-anchor="middle" transform="rotate(-90 20 {label_y:.1})">{}</text>"#,
            escape(y_label)
        );
        format!(
            "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{WIDTH}\" height=\"{HEIGHT}\" viewBox=\"0 0 {WIDTH} {HEIGHT}\" font-family=\"sans-serif\">\n<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n{}</svg>\n",
            self.body
        )
    }
}

const WORKSPACE_STYLE: &str = r##"fill="#9ecae1" stroke="none""##;
const RECTANGLE_STYLE: &str =
    r##"fill="#e6550d" fill-opacity="0.25" stroke="#e6550d" stroke-width="2""##;
const TRAVEL_STYLE: &str =
    r##"fill="none" stroke="#006d2c" stroke-width="2" stroke-dasharray="6 4""##;

fn section_svg(machine: &Machine, section: &Section, rect: Option<Rectangle>) -> String {
    let kins = &*machine.kinematics;
    let home = machine.home();
    let mut xr = (home.x, home.x);
    let mut zr = (home.z, home.z);
    for row in &section.rows {
        zr = (zr.0.min(row.z), zr.1.max(row.z));
        for i in &row.x {
            xr = (xr.0.min(i.lo), xr.1.max(i.hi));
        }
    }
    let pad = 0.05 * (xr.1 - xr.0).max(zr.1 - zr.0).max(1.0);
    let mut chart = Chart::new((xr.0 - pad, xr.1 + pad), (zr.0 - pad, zr.1 + pad), true);
    // Each row is drawn as a band a little taller than the row spacing, so
    // that neighbouring bands overlap instead of leaving hairline seams.
    for row in &section.rows {
        let z = Interval {
            lo: row.z - 0.75 * section.z_step,
            hi: row.z + 0.75 * section.z_step,
        };
        for x in &row.x {
            chart.rect(*x, z, WORKSPACE_STYLE);
        }
    }
    chart.legend(0, "reachable (strokes, rod reach)", WORKSPACE_STYLE);
    if let Some(r) = rect {
        chart.rect(r.x, r.z, RECTANGLE_STYLE);
        chart.legend(
            1,
            &format!("largest rectangle {:.1} x {:.1} mm", r.x.len(), r.z.len()),
            RECTANGLE_STYLE,
        );
    }
    if let (Some(tx), Some(tz)) = (travel(kins.axes(), Axis::X), travel(kins.axes(), Axis::Z)) {
        chart.rect(
            Interval {
                lo: tx.min,
                hi: tx.max,
            },
            Interval {
                lo: tz.min,
                hi: tz.max,
            },
            TRAVEL_STYLE,
        );
        chart.legend(2, "axis travel", TRAVEL_STYLE);
    }
    let (hx, hz) = (chart.px(home.x), chart.py(home.z));
    let _ = writeln!(
        chart.body,
        r#"<circle cx="{hx:.2}" cy="{hz:.2}" r="4" fill="black"/>"#
    );
    chart.text(
        hx + 7.0,
        hz - 7.0,
        &format!("home ({}, {})", home.x, home.z),
        r#"font-size="12""#,
    );
    chart.finish(
        &format!(
            "{}: XZ workspace section at y = {}",
            machine.description.name, home.y
        ),
        "x, mm",
        "z, mm",
    )
}

/// Which range of a [`TiltRow`] a curve follows.
type PickRange = fn(&TiltRow) -> Option<Interval>;

fn tilt_svg(machine: &Machine, rows: &[TiltRow]) -> String {
    let kins = &*machine.kinematics;
    let reached: Vec<&TiltRow> = rows
        .iter()
        .filter(|r| r.about_x.is_some() || r.about_y.is_some() || r.any.is_some())
        .collect();
    let mut zr = (f64::INFINITY, f64::NEG_INFINITY);
    for r in &reached {
        for i in [r.about_x, r.about_y, r.any].into_iter().flatten() {
            zr = (zr.0.min(i.lo), zr.1.max(i.hi));
        }
    }
    let tz = travel(kins.axes(), Axis::Z);
    if let Some(t) = tz {
        zr = (zr.0.min(t.min), zr.1.max(t.max));
    }
    if !zr.0.is_finite() {
        zr = (0.0, 1.0);
    }
    let pad = 0.05 * (zr.1 - zr.0);
    let max_tilt = rows.last().map_or(1.0, |r| r.tilt);
    let mut chart = Chart::new((0.0, max_tilt), (zr.0 - pad, zr.1 + pad), false);
    // The band every direction shares, filled.
    let any: Vec<(f64, Interval)> = rows
        .iter()
        .filter_map(|r| r.any.map(|i| (r.tilt, i)))
        .collect();
    if !any.is_empty() {
        let mut outline: Vec<(f64, f64)> = any.iter().map(|(t, i)| (*t, i.hi)).collect();
        outline.extend(any.iter().rev().map(|(t, i)| (*t, i.lo)));
        chart.polygon(&outline, WORKSPACE_STYLE);
    }
    chart.legend(0, "any tilt direction", WORKSPACE_STYLE);
    let series: [(&str, &str, PickRange); 2] = [
        (
            "tilt about X (A)",
            r##"stroke="#e6550d" stroke-width="2""##,
            |r| r.about_x,
        ),
        (
            "tilt about Y (B)",
            r##"stroke="#756bb1" stroke-width="2""##,
            |r| r.about_y,
        ),
    ];
    for (k, (label, style, pick)) in series.iter().enumerate() {
        let lo: Vec<(f64, f64)> = rows
            .iter()
            .filter_map(|r| pick(r).map(|i| (r.tilt, i.lo)))
            .collect();
        let hi: Vec<(f64, f64)> = rows
            .iter()
            .filter_map(|r| pick(r).map(|i| (r.tilt, i.hi)))
            .collect();
        chart.polyline(&lo, style);
        chart.polyline(&hi, style);
        chart.legend(k + 1, label, &format!(r#"fill="none" {style}"#));
    }
    if let Some(t) = tz {
        for z in [t.min, t.max] {
            chart.polyline(&[(0.0, z), (max_tilt, z)], TRAVEL_STYLE);
        }
        chart.legend(3, "Z travel", TRAVEL_STYLE);
    }
    chart.finish(
        &format!(
            "{}: reachable tool-tip Z against tilt",
            machine.description.name
        ),
        "tilt of the tool from vertical, degrees",
        "Z, mm",
    )
}
