//! Top-down picture of a task (`lhm scenes render`): room and walls (window in blue), obstacles
//! (support surfaces lighter), objects filled and goals outlined in their step's colour with the
//! step number, the character's start and heading, and the planned routes (walk dashed, carry
//! solid).

use crate::catalogue::Catalogue;
use crate::geometry::Rect;
use crate::model::{Task, Wall};
use crate::raster::{Canvas, Rgb};
use crate::routes::{footprint, obstacle_rect, Leg, LegKind};

const FLOOR: Rgb = [238, 232, 218];
const WALL: Rgb = [60, 60, 60];
const WINDOW: Rgb = [110, 170, 230];
const OBSTACLE: Rgb = [150, 120, 95];
const SURFACE: Rgb = [205, 180, 140];
const OUTLINE: Rgb = [70, 55, 45];
const TEXT: Rgb = [20, 20, 20];
const BACKGROUND: Rgb = [255, 255, 255];
const STEP_COLOURS: [Rgb; 5] = [
    [214, 39, 40],
    [31, 119, 180],
    [44, 160, 44],
    [148, 103, 189],
    [255, 127, 14],
];

fn step_colour(k: usize) -> Rgb {
    STEP_COLOURS[k % STEP_COLOURS.len()]
}

fn lighter(c: Rgb) -> Rgb {
    [c[0] / 2 + 128, c[1] / 2 + 128, c[2] / 2 + 128]
}

/// Word-wraps `s` to lines of at most `width` characters.
fn wrap(s: &str, width: usize) -> Vec<String> {
    let mut lines = vec![String::new()];
    for w in s.split_whitespace() {
        let last = lines.last_mut().expect("non-empty");
        if !last.is_empty() && last.len() + 1 + w.len() > width {
            lines.push(w.to_string());
        } else {
            if !last.is_empty() {
                last.push(' ');
            }
            last.push_str(w);
        }
    }
    lines
}

/// Draws the task; `legs` are the planned routes, drawn when given.
pub fn render_task(task: &Task, cat: &Catalogue, legs: Option<&[Leg]>) -> Canvas {
    let [w, d] = task.room_size;
    let scale = (820.0 / w.max(d)).min(140.0);
    let margin = 30.0;
    let width = (w * scale + 2.0 * margin).ceil();
    let chars_per_line = ((width - 2.0 * margin) / 12.0).floor().max(20.0) as usize;
    let mut legend: Vec<(String, Rgb)> = vec![(
        format!(
            "{}  {}  {:.1} X {:.1} M  ({} OBSTACLES)",
            task.id,
            task.room.as_str().replace('_', " "),
            w,
            d,
            task.obstacles.len()
        ),
        TEXT,
    )];
    for (k, s) in task.sequence.iter().enumerate() {
        for (i, line) in wrap(&format!("{}: {}", k + 1, s.instruction), chars_per_line)
            .into_iter()
            .enumerate()
        {
            legend.push((
                if i == 0 { line } else { format!("   {line}") },
                step_colour(k),
            ));
        }
    }
    let header = 12.0 + legend.len() as f64 * 20.0;
    let height = (d * scale + 2.0 * margin + header).ceil();
    let mut c = Canvas::new(width as u32, height as u32, BACKGROUND);
    let top = header + margin;
    let to_px = |p: [f64; 2]| {
        [
            margin + (p[0] + w / 2.0) * scale,
            top + (d / 2.0 - p[1]) * scale,
        ]
    };
    let rect_px = |r: &Rect| r.corners().map(to_px);

    for (i, (line, colour)) in legend.iter().enumerate() {
        c.text(margin, 10.0 + i as f64 * 20.0, line, 2, *colour);
    }
    // Floor, walls, window.
    let room = [
        to_px([-w / 2.0, -d / 2.0]),
        to_px([w / 2.0, -d / 2.0]),
        to_px([w / 2.0, d / 2.0]),
        to_px([-w / 2.0, d / 2.0]),
    ];
    c.fill_convex(&room, FLOOR);
    c.polygon_outline(&room, 6.0, WALL);
    let (hw, hd) = (w / 2.0, d / 2.0);
    let window = match task.window_wall {
        Wall::North => [[-hw / 3.0, hd], [hw / 3.0, hd]],
        Wall::South => [[-hw / 3.0, -hd], [hw / 3.0, -hd]],
        Wall::East => [[hw, -hd / 3.0], [hw, hd / 3.0]],
        Wall::West => [[-hw, -hd / 3.0], [-hw, hd / 3.0]],
    };
    c.line(to_px(window[0]), to_px(window[1]), 6.0, WINDOW);
    // Object radius around the centroid (1.5 m), faint.
    let centroid = to_px(task.centroid);
    let ring: Vec<[f64; 2]> = (0..=72)
        .map(|i| {
            let a = f64::from(i) / 72.0 * std::f64::consts::TAU;
            to_px([
                task.centroid[0] + 1.5 * a.cos(),
                task.centroid[1] + 1.5 * a.sin(),
            ])
        })
        .collect();
    c.dashed_polyline(&ring, 1.0, 6.0, [190, 190, 190]);
    c.disc(centroid, 3.0, [160, 160, 160]);

    for o in &task.obstacles {
        let t = cat.get(&o.kind);
        let pts = rect_px(&obstacle_rect(o));
        c.fill_convex(
            &pts,
            if t.is_some_and(|t| t.support) {
                SURFACE
            } else {
                OBSTACLE
            },
        );
        c.polygon_outline(&pts, 2.0, OUTLINE);
        let name = t
            .map_or(o.kind.as_str(), |t| t.display.as_str())
            .to_uppercase();
        let centre = to_px(o.pos);
        let fits = Canvas::text_width(&name, 1) < o.size[0].max(o.size[1]) * scale;
        let label = if fits {
            name
        } else {
            name.split_whitespace().map(|s| &s[..1]).collect()
        };
        c.text(
            centre[0] - Canvas::text_width(&label, 1) / 2.0,
            centre[1] - 3.5,
            &label,
            1,
            TEXT,
        );
    }
    if let Some(legs) = legs {
        for leg in legs {
            let pts: Vec<[f64; 2]> = leg.path.iter().map(|p| to_px(*p)).collect();
            let colour = step_colour(leg.step);
            // Connect the carry leg to the object it lifts and the goal it reaches.
            if let (LegKind::Carry, Some(step)) = (leg.kind, task.sequence.get(leg.step)) {
                if let (Some(o), Some(first), Some(last)) =
                    (task.object(&step.object), pts.first(), pts.last())
                {
                    c.line(to_px([o.pos[0], o.pos[1]]), *first, 1.5, colour);
                    c.line(*last, to_px([step.goal[0], step.goal[1]]), 1.5, colour);
                }
            }
            match leg.kind {
                LegKind::Walk => c.dashed_polyline(&pts, 2.0, 8.0, lighter(colour)),
                LegKind::Carry => {
                    for s in pts.windows(2) {
                        c.line(s[0], s[1], 3.0, colour);
                    }
                }
            }
        }
    }
    for (k, s) in task.sequence.iter().enumerate() {
        let Some(o) = task.object(&s.object) else {
            continue;
        };
        let colour = step_colour(k);
        let pts = rect_px(&footprint(o.pos, o.yaw, o.size));
        c.fill_convex(&pts, colour);
        c.polygon_outline(&pts, 1.0, TEXT);
        let goal = rect_px(&footprint(s.goal, s.goal_yaw, o.size));
        c.polygon_outline(&goal, 3.0, colour);
        c.line(goal[0], goal[2], 1.5, colour);
        c.line(goal[1], goal[3], 1.5, colour);
        let label = (k + 1).to_string();
        for (p, fg) in [
            (to_px([o.pos[0], o.pos[1]]), BACKGROUND),
            (to_px([s.goal[0], s.goal[1]]), colour),
        ] {
            c.disc(p, 9.0, if fg == BACKGROUND { colour } else { BACKGROUND });
            c.text(p[0] - 5.0, p[1] - 7.0, &label, 2, fg);
        }
    }
    // The character: a disc at the start with a heading tick.
    let s = to_px(task.start.pos);
    let (sy, cy) = task.start.yaw.sin_cos();
    c.disc(s, 0.22 * scale, [40, 40, 40]);
    c.line(
        s,
        [s[0] + 0.45 * scale * cy, s[1] - 0.45 * scale * sy],
        4.0,
        [40, 40, 40],
    );
    c.text(s[0] - 15.0, s[1] + 0.25 * scale + 4.0, "START", 1, TEXT);
    c
}
