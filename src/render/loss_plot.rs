//! The training loss plot, `level_K_loss.png`: the loss of every step of the
//! level's two phases (upsampler, then diffusion model) against that phase's
//! own step index, on a log scale, each step faint and a moving average bold;
//! below it, only when a schedule makes it vary, the learning rate.
//!
//! Text is drawn with a TrueType font embedded at build time (build.rs names
//! it: DejaVu Sans from Debian's fonts-dejavu-core), so the program needs no
//! font and no fontconfig where it runs.

use std::error::Error as StdError;
use std::path::Path;
use std::sync::Once;

use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use crate::error::{Error, Result};

/// Size of the PNG, pixels.
pub const WIDTH: u32 = 900;
pub const HEIGHT: u32 = 500;
/// The bold curves' colours (the faint ones are these mixed with white).
pub const UPSAMPLER_COLOUR: RGBColor = RGBColor(31, 119, 180);
pub const DIFFUSION_COLOUR: RGBColor = RGBColor(230, 110, 0);
/// Share of a phase's steps that the moving average spans.
const WINDOW_SHARE: f64 = 0.02;
/// How much of the colour the faint per-step curves keep.
const FAINT: f64 = 0.3;

const FONT: &str = "sans-serif";
const TEXT: RGBColor = RGBColor(40, 40, 40);

static FONT_BYTES: &[u8] = include_bytes!(env!("SHAPESHIFTER_PLOT_FONT"));

/// One phase's history: the loss of each step, and the learning rate of each
/// step where a schedule makes it vary (`None`: constant, not drawn).
#[derive(Clone, Copy, Debug, Default)]
pub struct PhaseCurve<'a> {
    pub loss: &'a [f32],
    pub lr: Option<&'a [f64]>,
}

/// Writes the loss plot of level `level` to `path` (PNG, [`WIDTH`] x [`HEIGHT`],
/// atomically). Either phase may be empty (level 0 has no upsampler).
pub fn write_loss_plot(path: &Path, level: usize, upsampler: PhaseCurve, diffusion: PhaseCurve) -> Result<()> {
    let mut buf = vec![255u8; (WIDTH * HEIGHT * 3) as usize];
    draw(&mut buf, level, &upsampler, &diffusion).map_err(|e| Error::file(path, format!("cannot draw the loss plot: {e}")))?;
    let img = image::RgbImage::from_raw(WIDTH, HEIGHT, buf).expect("buffer of WIDTH x HEIGHT RGB pixels");
    let mut png = std::io::Cursor::new(Vec::new());
    img.write_to(&mut png, image::ImageFormat::Png).map_err(|e| Error::file(path, e.to_string()))?;
    crate::util::fs::write_file(path, png.into_inner())
}

type DrawResult<T> = std::result::Result<T, Box<dyn StdError>>;

fn register_font() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        if plotters::style::register_font(FONT, FontStyle::Normal, FONT_BYTES).is_err() {
            panic!("the font embedded from {} is not a TrueType font", env!("SHAPESHIFTER_PLOT_FONT"));
        }
    });
}

/// A phase ready to draw.
struct Curve {
    name: &'static str,
    colour: RGBColor,
    /// (step, loss) of the steps with a positive finite loss.
    raw: Vec<(f64, f64)>,
    smooth: Vec<(f64, f64)>,
    lr: Option<Vec<(f64, f64)>>,
}

impl Curve {
    fn new(name: &'static str, colour: RGBColor, phase: &PhaseCurve) -> Option<Curve> {
        if phase.loss.is_empty() {
            return None;
        }
        let loss: Vec<f64> = phase.loss.iter().map(|&v| v as f64).collect();
        let window = ((loss.len() as f64 * WINDOW_SHARE).round() as usize).max(1);
        let shown = |(i, v): (usize, f64)| (v > 0.0 && v.is_finite()).then_some((i as f64, v));
        let raw = loss.iter().copied().enumerate().filter_map(shown).collect();
        let smooth = moving_average(&loss, window).into_iter().enumerate().filter_map(shown).collect();
        let lr = phase
            .lr
            .filter(|lr| varies(lr))
            .map(|lr| lr.iter().take(loss.len()).enumerate().map(|(i, &v)| (i as f64, v)).collect());
        Some(Curve { name, colour, raw, smooth, lr })
    }
}

/// Centred moving average over `window` steps (fewer at the ends), of the
/// finite values only (NaN where a window has none).
fn moving_average(v: &[f64], window: usize) -> Vec<f64> {
    let mut sum = vec![0.0; v.len() + 1];
    let mut count = vec![0usize; v.len() + 1];
    for (i, &x) in v.iter().enumerate() {
        let ok = x.is_finite();
        sum[i + 1] = sum[i] + if ok { x } else { 0.0 };
        count[i + 1] = count[i] + ok as usize;
    }
    let half = window / 2;
    (0..v.len())
        .map(|i| {
            let (a, b) = (i.saturating_sub(half), (i + window - half).min(v.len()));
            let n = count[b] - count[a];
            if n == 0 { f64::NAN } else { (sum[b] - sum[a]) / n as f64 }
        })
        .collect()
}

fn varies(v: &[f64]) -> bool {
    v.first().is_some_and(|&a| v.iter().any(|&x| (x - a).abs() > 1e-9 * a.abs()))
}

fn faint(c: RGBColor) -> RGBColor {
    let f = |x: u8| (255.0 - FAINT * (255.0 - x as f64)).round() as u8;
    RGBColor(f(c.0), f(c.1), f(c.2))
}

fn draw(buf: &mut [u8], level: usize, upsampler: &PhaseCurve, diffusion: &PhaseCurve) -> DrawResult<()> {
    register_font();
    let curves: Vec<Curve> = [("upsampler", UPSAMPLER_COLOUR, upsampler), ("diffusion", DIFFUSION_COLOUR, diffusion)]
        .into_iter()
        .filter_map(|(name, colour, phase)| Curve::new(name, colour, phase))
        .collect();
    let root = BitMapBackend::with_buffer(buf, (WIDTH, HEIGHT)).into_drawing_area();
    root.fill(&WHITE)?;

    // Title and the key to the line weights (left), legend (right): above the
    // axes, where they hide no data.
    let (head, body) = root.split_vertically(HEADER);
    let left = (MARGIN_LEFT + Y_LABEL_AREA) as i32;
    head.draw(&Text::new(
        format!("level {level}: training loss"),
        (left, 8),
        (FONT, 24).into_font().color(&TEXT).pos(Pos::new(HPos::Left, VPos::Top)),
    ))?;
    head.draw(&Text::new(
        format!("faint: each step    bold: moving average over {}% of the steps", WINDOW_SHARE * 100.0),
        (left, 40),
        (FONT, 14).into_font().color(&RGBColor(105, 105, 105)).pos(Pos::new(HPos::Left, VPos::Top)),
    ))?;
    let legend_x = WIDTH as i32 - MARGIN_RIGHT as i32 - 190;
    for (i, c) in curves.iter().enumerate() {
        let y = 18 + 24 * i as i32;
        head.draw(&PathElement::new(vec![(legend_x, y), (legend_x + 30, y)], c.colour.stroke_width(3)))?;
        head.draw(&Text::new(
            format!("{} (MSE)", c.name),
            (legend_x + 40, y),
            (FONT, 16).into_font().color(&TEXT).pos(Pos::new(HPos::Left, VPos::Center)),
        ))?;
    }

    let with_lr = curves.iter().any(|c| c.lr.is_some());
    let steps = [upsampler.loss.len(), diffusion.loss.len()].into_iter().max().unwrap_or(0);
    let x_max = if steps == 0 { 10.0 } else { steps as f64 };
    if with_lr {
        let (top, bottom) = body.split_vertically(LOSS_PANEL);
        draw_loss(&top, &curves, x_max, false)?;
        draw_lr(&bottom, &curves, x_max)?;
    } else {
        draw_loss(&body, &curves, x_max, true)?;
    }
    root.present()?;
    Ok(())
}

/// Heights of the title and legend row, and of the loss panel above the lr one.
const HEADER: u32 = 62;
const LOSS_PANEL: u32 = (HEIGHT - HEADER) * 68 / 100;
const Y_LABEL_AREA: u32 = 78;
const X_LABEL_AREA: u32 = 48;
const MARGIN_LEFT: u32 = 8;
const MARGIN_RIGHT: u32 = 24;

/// The x axis's labels: whole steps, in thousands ("20k") when they reach 10000.
fn x_labels(x_max: f64) -> (usize, impl Fn(&f64) -> String) {
    let count = (x_max as usize).clamp(2, 10);
    let thousands = x_max >= 10_000.0;
    (count, move |v: &f64| match (*v == 0.0, thousands) {
        (true, _) => "0".to_string(),
        (false, true) => format!("{}k", fmt_num(*v / 1000.0)),
        (false, false) => format!("{}", v.round()),
    })
}

fn draw_loss(area: &DrawingArea<BitMapBackend, Shift>, curves: &[Curve], x_max: f64, x_axis: bool) -> DrawResult<()> {
    let values = curves.iter().flat_map(|c| c.raw.iter().map(|p| p.1));
    let (lo, hi) = values.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| (lo.min(v), hi.max(v)));
    let (lo, hi) = if lo <= hi { (lo / 1.15, hi * 1.15) } else { (0.1, 1.0) };
    let (bold, light) = log_ticks(lo, hi);
    let mut chart = ChartBuilder::on(area)
        .margin_left(MARGIN_LEFT)
        .margin_right(MARGIN_RIGHT)
        .margin_top(4)
        .margin_bottom(if x_axis { 6 } else { 4 })
        .x_label_area_size(if x_axis { X_LABEL_AREA } else { 0 })
        .y_label_area_size(Y_LABEL_AREA)
        .build_cartesian_2d(0.0..x_max, (lo..hi).log_scale().with_key_points(bold).with_light_points(light))?;
    let (x_count, x_fmt) = x_labels(x_max);
    let mut mesh = chart.configure_mesh();
    mesh.y_desc("loss (MSE, log scale)")
        .y_label_formatter(&|v| fmt_num(*v))
        .x_label_formatter(&x_fmt)
        .x_labels(x_count)
        .x_max_light_lines(1)
        .label_style((FONT, 15).into_font().color(&TEXT))
        .axis_desc_style((FONT, 17).into_font().color(&TEXT))
        .bold_line_style(RGBColor(215, 215, 215))
        .light_line_style(RGBColor(238, 238, 238))
        .axis_style(RGBColor(120, 120, 120));
    if x_axis {
        mesh.x_desc("training step");
    }
    mesh.draw()?;

    if curves.is_empty() {
        let (w, h) = area.dim_in_pixel();
        area.draw(&Text::new(
            "no training steps recorded",
            ((w / 2) as i32, (h / 2) as i32),
            (FONT, 20).into_font().color(&TEXT).pos(Pos::new(HPos::Center, VPos::Center)),
        ))?;
        return Ok(());
    }
    for c in curves {
        chart.draw_series(LineSeries::new(c.raw.iter().copied(), faint(c.colour).stroke_width(1)))?;
    }
    for c in curves {
        chart.draw_series(LineSeries::new(c.smooth.iter().copied(), c.colour.stroke_width(3)))?;
    }
    Ok(())
}

fn draw_lr(area: &DrawingArea<BitMapBackend, Shift>, curves: &[Curve], x_max: f64) -> DrawResult<()> {
    let hi = curves.iter().filter_map(|c| c.lr.as_ref()).flatten().map(|p| p.1).fold(0.0, f64::max);
    let hi = if hi > 0.0 && hi.is_finite() { hi * 1.1 } else { 1.0 };
    let mut chart = ChartBuilder::on(area)
        .margin_left(MARGIN_LEFT)
        .margin_right(MARGIN_RIGHT)
        .margin_top(6)
        .margin_bottom(6)
        .x_label_area_size(X_LABEL_AREA)
        .y_label_area_size(Y_LABEL_AREA)
        .build_cartesian_2d(0.0..x_max, 0.0..hi)?;
    let (x_count, x_fmt) = x_labels(x_max);
    chart
        .configure_mesh()
        .y_desc("learning rate")
        .x_desc("training step")
        .y_labels(4)
        .x_labels(x_count)
        .x_max_light_lines(1)
        .y_max_light_lines(1)
        .y_label_formatter(&|v| fmt_num(*v))
        .x_label_formatter(&x_fmt)
        .label_style((FONT, 15).into_font().color(&TEXT))
        .axis_desc_style((FONT, 17).into_font().color(&TEXT))
        .bold_line_style(RGBColor(215, 215, 215))
        .light_line_style(RGBColor(238, 238, 238))
        .axis_style(RGBColor(120, 120, 120))
        .draw()?;
    for c in curves {
        if let Some(lr) = &c.lr {
            chart.draw_series(LineSeries::new(lr.iter().copied(), c.colour.stroke_width(2)))?;
        }
    }
    Ok(())
}

/// Labelled (bold) and unlabelled (light) grid values of a log axis over
/// [lo, hi]: the sparsest of 1, 1-2-5 and 1..9 per decade that labels at
/// least three values (at most eight decades), the other multiples of each
/// decade light.
fn log_ticks(lo: f64, hi: f64) -> (Vec<f64>, Vec<f64>) {
    let (d0, d1) = (lo.log10().floor() as i32, hi.log10().ceil() as i32);
    let within = |mults: &[f64]| -> Vec<f64> {
        (d0..=d1)
            .flat_map(|d| mults.iter().map(move |m| if d < 0 { m / 10f64.powi(-d) } else { m * 10f64.powi(d) }))
            .filter(|v| *v >= lo && *v <= hi)
            .collect()
    };
    let all = within(&[1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0]);
    for mults in [&[1.0][..], &[1.0, 2.0, 5.0][..]] {
        let mut bold = within(mults);
        if bold.len() > 8 {
            // Many decades: every second (third, ...) one.
            let every = bold.len().div_ceil(8);
            bold = bold.into_iter().step_by(every).collect();
        }
        if bold.len() >= 3 {
            let light = all.iter().copied().filter(|v| !bold.contains(v)).collect();
            return (bold, light);
        }
    }
    if all.len() >= 2 {
        return (all, Vec::new());
    }
    // Less than a factor two: three values rounded to two digits.
    let mid = (lo * hi).sqrt();
    let round = |v: f64| {
        let p = 10f64.powi(v.log10().floor() as i32 - 1);
        (v / p).round() * p
    };
    let bold = [lo * 1.02, mid, hi / 1.02].iter().map(|&v| round(v).clamp(lo, hi)).collect();
    (bold, Vec::new())
}

/// A tick value in few characters: 0.02, 0.5, 3, 1e-4, 2.5e-3.
fn fmt_num(v: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        return format!("{v}");
    }
    let mag = v.abs().log10().floor() as i32;
    if (-3..4).contains(&mag) {
        let s = format!("{:.*}", (2 - mag).max(0) as usize, v);
        let s = if s.contains('.') { s.trim_end_matches('0').trim_end_matches('.').to_string() } else { s };
        return s;
    }
    let s = format!("{v:.2e}");
    let (m, e) = s.split_once('e').unwrap_or((&s, "0"));
    let m = m.trim_end_matches('0').trim_end_matches('.');
    format!("{m}e{e}")
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A decaying, noisy loss (deterministic).
    fn noisy(n: usize, from: f64, to: f64, seed: u64) -> Vec<f32> {
        let mut r = crate::util::rng::Rng::new(seed);
        (0..n)
            .map(|i| {
                let f = i as f64 / (n.max(2) - 1) as f64;
                let trend = from * (to / from).powf(f);
                (trend * (0.6 + 0.8 * r.uniform())) as f32
            })
            .collect()
    }

    fn render(level: usize, up: PhaseCurve, diff: PhaseCurve) -> image::RgbImage {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("loss.png");
        write_loss_plot(&p, level, up, diff).unwrap();
        let img = image::open(&p).unwrap();
        assert_eq!(img.color(), image::ColorType::Rgb8, "an RGB PNG");
        img.to_rgb8()
    }

    fn count(img: &image::RgbImage, c: RGBColor) -> usize {
        img.pixels().filter(|p| p.0 == [c.0, c.1, c.2]).count()
    }

    /// Pixels that are neither white nor grey (text, axes and grid are grey).
    fn coloured(img: &image::RgbImage) -> usize {
        img.pixels().filter(|p| p.0.iter().max().unwrap() - p.0.iter().min().unwrap() > 40).count()
    }

    #[test]
    fn loss_plot_draws_both_curves() {
        let up = noisy(400, 0.5, 0.02, 1);
        let diff = noisy(1000, 1.0, 0.1, 2);
        let img = render(1, PhaseCurve { loss: &up, lr: None }, PhaseCurve { loss: &diff, lr: None });
        assert_eq!(img.dimensions(), (WIDTH, HEIGHT));
        let white = img.pixels().filter(|p| p.0 == [255, 255, 255]).count();
        assert!(white < (WIDTH * HEIGHT) as usize * 95 / 100, "not blank");
        // Text: the title and legend above the axes, the tick labels and axis title left of them.
        let dark = |x0: u32, x1: u32, y0: u32, y1: u32| {
            img.enumerate_pixels().filter(|(x, y, p)| (x0..x1).contains(x) && (y0..y1).contains(y) && p.0.iter().all(|&v| v < 100)).count()
        };
        assert!(dark(0, WIDTH, 0, HEADER) > 400, "title and legend: {}", dark(0, WIDTH, 0, HEADER));
        assert!(dark(0, Y_LABEL_AREA, HEADER, HEIGHT) > 300, "y labels: {}", dark(0, Y_LABEL_AREA, HEADER, HEIGHT));
        assert!(dark(0, WIDTH, HEIGHT - X_LABEL_AREA, HEIGHT) > 300, "x labels: {}", dark(0, WIDTH, HEIGHT - X_LABEL_AREA, HEIGHT));
        // The bold averages, far more than their legend swatches (~90 pixels each).
        assert!(count(&img, UPSAMPLER_COLOUR) > 1500, "upsampler curve: {}", count(&img, UPSAMPLER_COLOUR));
        assert!(count(&img, DIFFUSION_COLOUR) > 1500, "diffusion curve: {}", count(&img, DIFFUSION_COLOUR));
        // The faint per-step values.
        assert!(count(&img, faint(UPSAMPLER_COLOUR)) > 1000, "upsampler steps");
        assert!(count(&img, faint(DIFFUSION_COLOUR)) > 1000, "diffusion steps");
    }

    #[test]
    fn loss_plot_of_level_0_has_no_upsampler() {
        let diff = noisy(3000, 0.5, 0.01, 3);
        let img = render(0, PhaseCurve::default(), PhaseCurve { loss: &diff, lr: None });
        assert_eq!(img.dimensions(), (WIDTH, HEIGHT));
        assert_eq!(count(&img, UPSAMPLER_COLOUR), 0, "no upsampler curve nor legend entry");
        assert!(count(&img, DIFFUSION_COLOUR) > 1500);
        // Nothing at all, and values a log axis cannot show, still give a plot.
        let img = render(2, PhaseCurve::default(), PhaseCurve::default());
        assert_eq!(img.dimensions(), (WIDTH, HEIGHT));
        assert_eq!(coloured(&img), 0);
        let odd = [0.0f32, f32::NAN, -1.0, 0.3, f32::INFINITY, 0.31];
        let img = render(2, PhaseCurve::default(), PhaseCurve { loss: &odd, lr: None });
        assert!(count(&img, DIFFUSION_COLOUR) > 0);
    }

    #[test]
    fn loss_plot_shows_lr_only_when_it_varies() {
        use crate::learn::train::optim::lr_at;
        let up = noisy(400, 0.5, 0.02, 1);
        let diff = noisy(1000, 1.0, 0.1, 2);
        let none = render(1, PhaseCurve { loss: &up, lr: None }, PhaseCurve { loss: &diff, lr: None });
        let flat_u: Vec<f64> = (0..400).map(|s| lr_at(s, 400, 2e-3, 0, 1.0)).collect();
        let flat_d: Vec<f64> = (0..1000).map(|s| lr_at(s, 1000, 1e-3, 0, 1.0)).collect();
        let flat = render(1, PhaseCurve { loss: &up, lr: Some(&flat_u) }, PhaseCurve { loss: &diff, lr: Some(&flat_d) });
        assert!(none == flat, "a constant rate draws nothing");
        let sched_u: Vec<f64> = (0..400).map(|s| lr_at(s, 400, 2e-3, 40, 0.1)).collect();
        let sched_d: Vec<f64> = (0..1000).map(|s| lr_at(s, 1000, 1e-3, 100, 0.1)).collect();
        let sched = render(1, PhaseCurve { loss: &up, lr: Some(&sched_u) }, PhaseCurve { loss: &diff, lr: Some(&sched_d) });
        assert_eq!(sched.dimensions(), (WIDTH, HEIGHT));
        let differ = none.pixels().zip(sched.pixels()).filter(|(a, b)| a != b).count();
        assert!(differ > 10_000, "the lr panel changes the picture: {differ} pixels");
        // The lr curves, in the phases' colours, inside the lr panel's axes.
        let (y0, y1) = (HEADER + LOSS_PANEL + 12, HEIGHT - X_LABEL_AREA - 8);
        let in_panel = |c: RGBColor| {
            sched.enumerate_pixels().filter(|(_, y, p)| (y0..y1).contains(y) && p.0 == [c.0, c.1, c.2]).count()
        };
        assert!(in_panel(UPSAMPLER_COLOUR) > 500, "upsampler lr: {}", in_panel(UPSAMPLER_COLOUR));
        assert!(in_panel(DIFFUSION_COLOUR) > 1000, "diffusion lr: {}", in_panel(DIFFUSION_COLOUR));
    }

    #[test]
    fn moving_average_and_ticks() {
        let v = [1.0, 2.0, 3.0, f64::NAN, 5.0];
        let m = moving_average(&v, 3);
        assert_eq!(m[0], 1.5);
        assert_eq!(m[1], 2.0);
        assert_eq!(m[2], 2.5);
        assert_eq!(m[4], 5.0);
        assert_eq!(moving_average(&v, 1)[1], 2.0);
        let (bold, _) = log_ticks(0.015, 1.2);
        assert_eq!(bold, vec![0.02, 0.05, 0.1, 0.2, 0.5, 1.0]);
        let (bold, light) = log_ticks(1e-4, 2.0);
        assert_eq!(bold, vec![1e-4, 1e-3, 1e-2, 1e-1, 1.0]);
        assert!(light.contains(&0.5));
        assert!(log_ticks(0.3, 0.35).0.len() >= 2);
        assert!(log_ticks(1e-9, 1e3).0.len() <= 8);
        assert_eq!(fmt_num(0.02), "0.02");
        assert_eq!(fmt_num(0.5), "0.5");
        assert_eq!(fmt_num(1.0), "1");
        assert_eq!(fmt_num(1e-4), "1e-4");
        assert_eq!(fmt_num(0.0015000000000000002), "0.0015");
        assert_eq!(x_labels(20000.0).1(&12000.0), "12k");
        assert_eq!(x_labels(20000.0).1(&2500.0), "2.5k");
        assert_eq!(x_labels(1000.0).1(&500.0), "500");
    }
}
