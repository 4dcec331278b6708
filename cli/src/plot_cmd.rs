//! `lhm plot RUN_DIR`: a run's training curves (RUN_DIR/metrics.csv) drawn into one PNG, one small
//! panel per known metric, the raw values as a thin light line under a moving average.

use anyhow::{anyhow, bail, Context, Result};
use clap::Args;
use plotters::prelude::*;
use plotters::style::{register_font, FontStyle};
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

#[derive(Args)]
pub struct PlotArgs {
    /// Run directory holding metrics.csv (e.g. runs/teacher1).
    run_dir: PathBuf,
    /// The PNG to write (default: RUN_DIR/curves.png).
    #[arg(short, long, value_name = "PNG")]
    output: Option<PathBuf>,
    /// Image width in pixels.
    #[arg(long, default_value_t = 1200)]
    width: u32,
    /// Image height in pixels.
    #[arg(long, default_value_t = 1400)]
    height: u32,
}

/// The metrics drawn, in panel order: (column in metrics.csv, panel title). Other columns are
/// ignored; one of these that the file lacks, or holds no value in (a student's discriminator, a
/// teacher's regression loss), gets no panel.
const PANELS: &[(&str, &str)] = &[
    ("mean_return", "return"),
    ("mean_episode_length", "episode length (steps)"),
    ("fall_fraction", "fall fraction"),
    ("reach_rate", "reach rate (task starts)"),
    // Every episode's reach, demo and gait starts too (a run with [env.gait] has no task starts).
    ("reach_rate_all", "reach rate (all starts)"),
    ("disc_accuracy", "discriminator accuracy"),
    // Each side apart (runs from the forty-third session on): which one moves the mean.
    (
        "disc_demo_accuracy",
        "discriminator accuracy on demo windows",
    ),
    (
        "disc_agent_accuracy",
        "discriminator accuracy on agent windows",
    ),
    ("disc_lr", "discriminator learning rate"),
    ("style_reward", "style reward"),
    ("task_reward", "task reward"),
    ("samples_per_s", "samples/s"),
    ("success_rate", "success rate"),
    ("student_loss", "student regression loss (MSE)"),
    ("teacher_mix", "DAgger teacher mix (beta)"),
];

/// The x axis column; without it the row index is used.
const X_COLUMN: &str = "iteration";

/// One line colour per panel (the raw values use it faded).
const COLOURS: &[RGBColor] = &[
    RGBColor(31, 119, 180),
    RGBColor(44, 160, 44),
    RGBColor(255, 127, 14),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(23, 190, 207),
    RGBColor(127, 127, 127),
    RGBColor(188, 189, 34),
    RGBColor(0, 0, 128),
];

pub fn run(args: PlotArgs) -> Result<()> {
    let csv = args.run_dir.join("metrics.csv");
    let output = args
        .output
        .clone()
        .unwrap_or_else(|| args.run_dir.join("curves.png"));
    let metrics = Metrics::read(&csv)?;
    let panels = plot(
        &metrics,
        &csv.display().to_string(),
        &output,
        (args.width, args.height),
    )?;
    println!(
        "wrote {} ({panels} panels, {} rows of {})",
        output.display(),
        metrics.rows,
        csv.display()
    );
    Ok(())
}

/// `lhm plot RUN_DIR` with its defaults: RUN_DIR/curves.png from RUN_DIR/metrics.csv.
pub(crate) fn plot_run(run_dir: &std::path::Path) -> Result<()> {
    run(PlotArgs {
        run_dir: run_dir.to_path_buf(),
        output: None,
        width: 1200,
        height: 1400,
    })
}

/// metrics.csv parsed: every column by name, one value per row, NaN where a field was empty or
/// `nan`.
#[derive(Debug)]
struct Metrics {
    columns: Vec<(String, Vec<f64>)>,
    rows: usize,
}

impl Metrics {
    fn read(path: &Path) -> Result<Self> {
        let text =
            std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
        Self::parse(&text, &path.display().to_string())
    }

    /// `file` names the source in errors. Blank lines are skipped. A last line without its
    /// newline that does not parse is dropped with a warning rather than failing: the trainer may
    /// be writing it right now.
    fn parse(text: &str, file: &str) -> Result<Self> {
        let text = text.strip_prefix('\u{feff}').unwrap_or(text);
        let mut lines = text
            .lines()
            .enumerate()
            .map(|(i, l)| (i + 1, l))
            .filter(|(_, l)| !l.trim().is_empty())
            .peekable();
        let Some((header_line, header)) = lines.next() else {
            bail!("{file}: no header (the file is empty)");
        };
        let names: Vec<String> = header.split(',').map(|s| s.trim().to_string()).collect();
        if names
            .iter()
            .all(|n| parse_field(n).is_some_and(|v| !v.is_nan()))
        {
            bail!("{file}: line {header_line}: no header (the first line is numbers, not column names)");
        }
        for (c, name) in names.iter().enumerate() {
            if name.is_empty() {
                bail!("{file}: line {header_line}: column {} has no name", c + 1);
            }
            if names[..c].contains(name) {
                bail!("{file}: line {header_line}: column {name:?} appears twice");
            }
        }
        let mut columns: Vec<(String, Vec<f64>)> =
            names.into_iter().map(|n| (n, Vec::new())).collect();
        let unterminated_end = !text.ends_with('\n');
        let mut row = Vec::with_capacity(columns.len());
        while let Some((line, fields)) = lines.next() {
            match parse_row(fields, &columns, &mut row) {
                Ok(()) => {
                    for ((_, col), v) in columns.iter_mut().zip(&row) {
                        col.push(*v);
                    }
                }
                Err(e) if unterminated_end && lines.peek().is_none() => {
                    tracing::warn!("{file}: line {line}: ignoring the unfinished last line: {e}");
                }
                Err(e) => bail!("{file}: line {line}: {e}"),
            }
        }
        let rows = columns[0].1.len();
        if rows == 0 {
            bail!("{file}: no rows (only a header)");
        }
        Ok(Self { columns, rows })
    }

    fn column(&self, name: &str) -> Option<&[f64]> {
        self.columns
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, v)| v.as_slice())
    }

    /// The x value of every row: the iteration column when it is present and complete, else the
    /// row index.
    fn x(&self) -> (Vec<f64>, &'static str) {
        match self.column(X_COLUMN) {
            Some(it) if it.iter().all(|v| v.is_finite()) => (it.to_vec(), X_COLUMN),
            _ => ((0..self.rows).map(|i| i as f64).collect(), "row"),
        }
    }
}

/// One data line's fields into `out` (cleared first), checked against the header.
fn parse_row(fields: &str, columns: &[(String, Vec<f64>)], out: &mut Vec<f64>) -> Result<()> {
    out.clear();
    for (c, field) in fields.split(',').enumerate() {
        let Some((name, _)) = columns.get(c) else {
            bail!(
                "{} fields, the header has {}",
                fields.split(',').count(),
                columns.len()
            );
        };
        let v = parse_field(field).ok_or_else(|| {
            anyhow!(
                "column {} ({name}): {:?} is not a number",
                c + 1,
                field.trim()
            )
        })?;
        out.push(v);
    }
    if out.len() != columns.len() {
        bail!("{} fields, the header has {}", out.len(), columns.len());
    }
    Ok(())
}

/// A number, or NaN for a missing value (empty or `nan`); None if it is neither.
fn parse_field(field: &str) -> Option<f64> {
    let f = field.trim();
    if f.is_empty() || f.eq_ignore_ascii_case("nan") {
        return Some(f64::NAN);
    }
    f.parse().ok()
}

/// Trailing moving average over `window` rows, counting only the finite values in each window;
/// NaN where a window has none.
fn moving_average(values: &[f64], window: usize) -> Vec<f64> {
    let window = window.max(1);
    let (mut sum, mut count) = (0.0, 0usize);
    let mut out = Vec::with_capacity(values.len());
    for (i, &v) in values.iter().enumerate() {
        if v.is_finite() {
            sum += v;
            count += 1;
        }
        if i >= window {
            let old = values[i - window];
            if old.is_finite() {
                sum -= old;
                count -= 1;
            }
        }
        out.push(if count > 0 {
            sum / count as f64
        } else {
            f64::NAN
        });
    }
    out
}

/// Runs of consecutive finite points: a missing value breaks the line.
fn segments(x: &[f64], y: &[f64]) -> Vec<Vec<(f64, f64)>> {
    let mut out = Vec::new();
    let mut current = Vec::new();
    for (&x, &y) in x.iter().zip(y) {
        if y.is_finite() {
            current.push((x, y));
        } else if !current.is_empty() {
            out.push(std::mem::take(&mut current));
        }
    }
    if !current.is_empty() {
        out.push(current);
    }
    out
}

/// An axis range around `values`' finite entries with a little margin; [0, 1] for fractions.
fn y_range(values: &[f64]) -> (f64, f64) {
    let (lo, hi) = values
        .iter()
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &v| {
            (lo.min(v), hi.max(v))
        });
    if lo > hi {
        return (0.0, 1.0);
    }
    // Fractions on the whole unit range, unless all are small (a regression loss of 1e-4 would
    // draw as a flat line at 0).
    if lo >= 0.0 && (0.2..=1.0).contains(&hi) {
        return (-0.02, 1.02);
    }
    let pad = if hi > lo {
        0.05 * (hi - lo)
    } else if lo == 0.0 {
        0.1
    } else {
        0.1 * lo.abs()
    };
    (lo - pad, hi + pad)
}

fn x_range(x: &[f64]) -> (f64, f64) {
    let lo = x.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = x.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    if lo < hi {
        (lo, hi)
    } else {
        (lo - 1.0, lo + 1.0)
    }
}

/// plotters' `ab_glyph` text backend loads no system fonts: Noto Sans Regular, embedded by the
/// `ttf-noto-sans` crate, is registered as `sans-serif` once.
fn register_fonts() -> Result<()> {
    static REGISTERED: OnceLock<bool> = OnceLock::new();
    let ok = *REGISTERED.get_or_init(|| {
        register_font("sans-serif", FontStyle::Normal, ttf_noto_sans::REGULAR).is_ok()
    });
    if !ok {
        bail!("the embedded Noto Sans font did not load");
    }
    Ok(())
}

/// Draws every known column present in `metrics` into a PNG of `size` pixels at `output`;
/// returns the number of panels. `source` names the CSV in errors and the image's title.
fn plot(metrics: &Metrics, source: &str, output: &Path, size: (u32, u32)) -> Result<usize> {
    if output.extension().and_then(|e| e.to_str()) != Some("png") {
        bail!("{}: the output must end in .png", output.display());
    }
    if let Some(dir) = output.parent().filter(|d| !d.as_os_str().is_empty()) {
        if !dir.is_dir() {
            bail!(
                "{}: the output's directory {} does not exist",
                output.display(),
                dir.display()
            );
        }
    }
    if size.0 < 200 || size.1 < 200 {
        bail!("the image must be at least 200x200 pixels");
    }
    let panels: Vec<(&str, &[f64])> = PANELS
        .iter()
        .filter_map(|&(name, title)| metrics.column(name).map(|v| (title, v)))
        .filter(|(_, v)| v.iter().any(|x| x.is_finite()))
        .collect();
    if panels.is_empty() {
        let known: Vec<&str> = PANELS.iter().map(|(n, _)| *n).collect();
        bail!(
            "{source}: none of the plotted columns is present (known: {})",
            known.join(", ")
        );
    }
    register_fonts()?;
    let (x, x_label) = metrics.x();
    let (x_lo, x_hi) = x_range(&x);
    let window = (metrics.rows / 50).max(1);

    let draw = || -> Result<()> {
        let root = BitMapBackend::new(output, size).into_drawing_area();
        root.fill(&WHITE)?;
        let title = format!(
            "{source}: {} rows, moving average over {window}",
            metrics.rows
        );
        let body = root.titled(&title, ("sans-serif", 24))?;
        let grid_rows = panels.len().div_ceil(2);
        let areas = body.split_evenly((grid_rows, 2));
        for (i, ((title, y), area)) in panels.iter().zip(&areas).enumerate() {
            let colour = COLOURS[i % COLOURS.len()];
            let (y_lo, y_hi) = y_range(y);
            let mut chart = ChartBuilder::on(area)
                .caption(*title, ("sans-serif", 21))
                .margin(8)
                .x_label_area_size(46)
                .y_label_area_size(70)
                .build_cartesian_2d(x_lo..x_hi, y_lo..y_hi)?;
            chart
                .configure_mesh()
                .x_labels(6)
                .y_labels(5)
                .x_desc(x_label)
                .label_style(("sans-serif", 15))
                .axis_desc_style(("sans-serif", 15))
                .light_line_style(WHITE.mix(0.0))
                .bold_line_style(BLACK.mix(0.08))
                .x_label_formatter(&|v| tick(*v, x_hi - x_lo))
                .y_label_formatter(&|v| tick(*v, y_hi - y_lo))
                .draw()?;
            let raw = segments(&x, y);
            if raw.is_empty() {
                let centre = ((x_lo + x_hi) / 2.0, (y_lo + y_hi) / 2.0);
                chart.draw_series(std::iter::once(Text::new(
                    "no values",
                    centre,
                    ("sans-serif", 14).into_font().color(&BLACK.mix(0.5)),
                )))?;
                continue;
            }
            let faded = colour.mix(0.3).stroke_width(1);
            for seg in &raw {
                if seg.len() == 1 {
                    chart.draw_series(std::iter::once(Circle::new(seg[0], 2, faded.filled())))?;
                } else {
                    chart.draw_series(LineSeries::new(seg.iter().copied(), faded))?;
                }
            }
            let smooth = moving_average(y, window);
            for seg in segments(&x, &smooth) {
                chart.draw_series(LineSeries::new(seg, colour.stroke_width(2)))?;
            }
        }
        root.present()?;
        Ok(())
    };
    draw().with_context(|| format!("writing {}", output.display()))?;
    Ok(panels.len())
}

/// Tick labels: short, without float noise or trailing zeros (0.5, 2.5, 1200, 1.5e6), with enough
/// decimals to tell apart the ~5 ticks of an axis `span` wide (a style reward between 1.25 and
/// 1.42 reads 1.3, 1.35, 1.4, not 1.3, 1.3, 1.4, 1.4). `span` 0: no such floor.
fn tick(v: f64, span: f64) -> String {
    let a = v.abs();
    if a < 1e-9 {
        return "0".into();
    }
    if !(1e-3..1e6).contains(&a) {
        return format!("{v:.1e}");
    }
    let short = if a >= 100.0 {
        0
    } else if a >= 1.0 {
        1
    } else {
        3
    };
    let resolving = if span > 0.0 {
        (-(span / 5.0).log10()).ceil().clamp(0.0, 4.0) as usize
    } else {
        0
    };
    let decimals = short.max(resolving);
    let s = format!("{v:.decimals$}");
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plot_parse_reads_columns_and_missing_values() {
        let csv = "iteration,mean_return,success_rate,extra\n\
                   1,0.5,,7\n\
                   2, 1.5 ,nan,8\r\n\
                   \n\
                   3,-2e1,0.25,NaN\n";
        let m = Metrics::parse(csv, "m.csv").unwrap();
        assert_eq!(m.rows, 3);
        assert_eq!(m.column("iteration").unwrap(), &[1.0, 2.0, 3.0]);
        assert_eq!(m.column("mean_return").unwrap(), &[0.5, 1.5, -20.0]);
        let sr = m.column("success_rate").unwrap();
        assert!(sr[0].is_nan() && sr[1].is_nan());
        assert_eq!(sr[2], 0.25);
        assert!(m.column("extra").unwrap()[2].is_nan());
        assert!(m.column("fall_fraction").is_none());
        assert_eq!(m.x(), (vec![1.0, 2.0, 3.0], "iteration"));
    }

    #[test]
    fn plot_parse_errors_name_file_and_line() {
        let err = |csv: &str| format!("{:#}", Metrics::parse(csv, "run/metrics.csv").unwrap_err());
        let e = err("iteration,mean_return\n1,2\n2,3,4\n3,4\n");
        assert!(
            e.contains("run/metrics.csv: line 3") && e.contains("3 fields"),
            "{e}"
        );
        let e = err("iteration,mean_return\n1,2\n2\n3,4\n");
        assert!(e.contains("line 3") && e.contains("1 fields"), "{e}");
        let e = err("iteration,mean_return\n1,2\n2,abc\n");
        assert!(
            e.contains("line 3") && e.contains("column 2 (mean_return)") && e.contains("\"abc\""),
            "{e}"
        );
        assert!(err("").contains("no header"));
        assert!(err("1,2\n3,4\n").contains("no header"));
        assert!(err("iteration,mean_return\n").contains("no rows"));
        assert!(err("a,,b\n1,2,3\n").contains("column 2 has no name"));
        assert!(err("a,a\n1,2\n").contains("appears twice"));
        // An unfinished last line (no newline: still being written) that does not parse is
        // dropped, not an error; one that parses is kept.
        let m = Metrics::parse("iteration,mean_return\n1,2\n2,3\n3", "m").unwrap();
        assert_eq!(m.rows, 2);
        let m = Metrics::parse("iteration,mean_return\n1,2\n2,3\n3,4", "m").unwrap();
        assert_eq!(m.rows, 3);
        assert!(err("iteration,mean_return\n1,2\n2\n3,4").contains("line 3"));
    }

    #[test]
    fn plot_missing_file_is_named() {
        let e = format!(
            "{:#}",
            Metrics::read(Path::new("/nonexistent/run/metrics.csv")).unwrap_err()
        );
        assert!(e.contains("/nonexistent/run/metrics.csv"), "{e}");
    }

    #[test]
    fn plot_moving_average_skips_missing() {
        let nan = f64::NAN;
        let m = moving_average(&[1.0, 3.0, nan, 5.0, nan, nan], 2);
        assert_eq!(&m[..4], &[1.0, 2.0, 3.0, 5.0]);
        assert_eq!(m[4], 5.0);
        assert!(m[5].is_nan());
        assert_eq!(moving_average(&[1.0, 2.0], 0), vec![1.0, 2.0]);
    }

    #[test]
    fn plot_tick_labels_are_short() {
        let ticks: Vec<String> = [0.0, 0.5, 0.25, 2.0, 2.5, 150.0, 24000.0, 2e6, 1e-4, -0.1]
            .iter()
            .map(|&v| tick(v, 0.0))
            .collect();
        let want = [
            "0", "0.5", "0.25", "2", "2.5", "150", "24000", "2.0e6", "1.0e-4", "-0.1",
        ];
        assert_eq!(ticks, want);
        // A narrow axis gets the decimals that tell its ticks apart; a wide one stays short.
        let narrow: Vec<String> = [1.3, 1.35, 1.4].iter().map(|&v| tick(v, 0.17)).collect();
        assert_eq!(narrow, ["1.3", "1.35", "1.4"]);
        assert_eq!(tick(150.0, 250.0), "150");
        assert_eq!(tick(0.25, 1.0), "0.25");
    }

    #[test]
    fn plot_writes_png_of_requested_size() {
        let dir = std::env::temp_dir().join(format!("lhm-plot-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let mut csv = String::from("iteration,mean_return,fall_fraction,samples_per_s,junk\n");
        for i in 0..120 {
            let r = if i % 17 == 5 {
                String::new()
            } else {
                format!("{}", (i as f64).sqrt() + (i % 3) as f64)
            };
            csv += &format!("{i},{r},{},{},1\n", 1.0 / (1.0 + i as f64), 3000 + i);
        }
        let m = Metrics::parse(&csv, "synthetic").unwrap();
        let out = dir.join("curves.png");
        let panels = plot(&m, "synthetic", &out, (640, 480)).unwrap();
        assert_eq!(panels, 3);
        let bytes = std::fs::read(&out).unwrap();
        assert!(bytes.len() > 1000, "{} bytes", bytes.len());
        assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n");
        let be = |at: usize| {
            u32::from_be_bytes([bytes[at], bytes[at + 1], bytes[at + 2], bytes[at + 3]])
        };
        assert_eq!((be(16), be(20)), (640, 480));
        // No known column: a clear error, no image.
        let m = Metrics::parse("iteration,foo\n1,2\n", "only-foo.csv").unwrap();
        let e = format!(
            "{:#}",
            plot(&m, "only-foo.csv", &dir.join("x.png"), (640, 480)).unwrap_err()
        );
        assert!(
            e.contains("only-foo.csv") && e.contains("none of the plotted columns"),
            "{e}"
        );
        std::fs::remove_dir_all(&dir).ok();
    }
}
