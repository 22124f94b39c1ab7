//! A line as a 3D scene for the live view (a `foxglove.SceneUpdate` each time the line ticks, on
//! the line's `scene`): what the paper's Figure 1 draws: the input hopper
//! with the batch coming in, the belt carrying its batch (material A blue, B orange, as long as
//! the amounts), the sorting machine coloured by its sort mode, and the two containers, each a
//! stack of what it holds rightly (its colour) and wrongly (the other), as tall as its share of
//! everything sorted, labelled with counts and purity. Line k stands 3 m beside line k-1, in the
//! frame `sorting_line` (x along the flow, z up). Geometry only: no I/O.

use foxglove::messages::Timestamp;
use foxglove::messages::{Color, CubePrimitive, Pose, Quaternion, SceneEntity, SceneUpdate, TextPrimitive, Vector3};

use crate::ros::protocol::HostedLine;
use crate::sim::SortMode;

/// The scene's frame (Foxglove's 3D panel shows it when it is the display frame).
pub(super) const FRAME: &str = "sorting_line";

const A: (f64, f64, f64) = (0.20, 0.45, 0.85);
const B: (f64, f64, f64) = (0.95, 0.55, 0.15);
const STEEL: (f64, f64, f64) = (0.55, 0.57, 0.60);
const DARK: (f64, f64, f64) = (0.25, 0.26, 0.28);
const WHITE: (f64, f64, f64) = (1.0, 1.0, 1.0);

/// Metres a full batch (100 units) spans on the belt, and the hopper's and containers' heights.
const BELT_LENGTH: f64 = 5.0;
const FULL_HEIGHT: f64 = 1.5;
const LINE_SPACING: f64 = 3.0;

fn color((r, g, b): (f64, f64, f64), a: f64) -> Option<Color> {
    Some(Color { r, g, b, a })
}

/// An axis-aligned box by its centre and size.
fn cube(center: (f64, f64, f64), size: (f64, f64, f64), rgb: (f64, f64, f64)) -> CubePrimitive {
    CubePrimitive {
        pose: pose(center),
        size: Some(Vector3 { x: size.0, y: size.1, z: size.2 }),
        color: color(rgb, 1.0),
    }
}

fn pose((x, y, z): (f64, f64, f64)) -> Option<Pose> {
    Some(Pose { position: Some(Vector3 { x, y, z }), orientation: Some(Quaternion { x: 0.0, y: 0.0, z: 0.0, w: 1.0 }) })
}

fn text(at: (f64, f64, f64), text: String) -> TextPrimitive {
    TextPrimitive {
        pose: pose(at),
        billboard: true,
        font_size: 14.0,
        scale_invariant: true,
        color: color(WHITE, 1.0),
        text,
    }
}

/// Two stacked boxes at `x, y` from the floor up: `lower` units of one colour, then `upper` of
/// another, `per_unit` metres each (nothing for an empty part).
fn stack(x: f64, y: f64, width: f64, parts: [(f64, (f64, f64, f64)); 2], per_unit: f64) -> Vec<CubePrimitive> {
    let mut z = 0.0;
    let mut out = Vec::new();
    for (units, rgb) in parts {
        let h = units * per_unit;
        if h > 0.0 {
            out.push(cube((x, y, z + h / 2.0), (width, width, h), rgb));
            z += h;
        }
    }
    out
}

/// The entity of line `index` (in `namespace`).
fn line_entity(host: &HostedLine, index: usize, namespace: &str, timestamp: Option<Timestamp>) -> SceneEntity {
    let model = host.line();
    let y = index as f64 * LINE_SPACING;
    let (input, belt, containers) = (model.input(), model.belt(), model.containers());
    let mut cubes = Vec::new();
    let mut texts = Vec::new();
    // The hopper: the batch about to enter, A below B, as tall as its share of a full batch.
    let unit = FULL_HEIGHT / 100.0;
    cubes.push(cube((0.0, y, -0.05), (1.0, 1.0, 0.1), DARK));
    cubes.extend(stack(0.0, y, 0.8, [(f64::from(input.a), A), (f64::from(input.b), B)], unit));
    texts.push(text((0.0, y, FULL_HEIGHT + 0.4), format!("input A {} B {}", input.a, input.b)));
    // The belt, and its batch as two segments, A then B, as long as their amounts.
    let (start, per_unit) = (1.0, BELT_LENGTH / 100.0);
    cubes.push(cube((start + BELT_LENGTH / 2.0, y, 0.05), (BELT_LENGTH, 1.0, 0.1), STEEL));
    let (a_len, b_len) = (f64::from(belt.a) * per_unit, f64::from(belt.b) * per_unit);
    if a_len > 0.0 {
        cubes.push(cube((start + a_len / 2.0, y, 0.2), (a_len, 0.7, 0.2), A));
    }
    if b_len > 0.0 {
        cubes.push(cube((start + a_len + b_len / 2.0, y, 0.2), (b_len, 0.7, 0.2), B));
    }
    texts.push(text(
        (start + BELT_LENGTH / 2.0, y, 0.9),
        format!("speed {:.1}  occupancy {:.2}", model.speed(), belt.occupancy()),
    ));
    // The sorting machine, coloured by its mode.
    let machine_x = start + BELT_LENGTH + 0.75;
    let (machine, label) = match (host.takes_modes(), model.mode()) {
        (false, _) => (STEEL, "sorter".to_string()),
        (true, SortMode::Basic) => (STEEL, format!("mode {}", SortMode::Basic.label())),
        (true, SortMode::Positive) => (A, format!("mode {}", SortMode::Positive.label())),
        (true, SortMode::Negative) => (B, format!("mode {}", SortMode::Negative.label())),
    };
    cubes.push(cube((machine_x, y, 0.6), (1.0, 1.2, 1.2), machine));
    texts.push(text((machine_x, y, 1.6), label));
    // The containers: A (left of the flow) and B, each as tall as its share of all sorted.
    let total = containers.total().max(1) as f64;
    let per_unit = FULL_HEIGHT / total;
    let bin_x = machine_x + 1.75;
    let purity = |right: u64, wrong: u64| if right + wrong == 0 { 0.0 } else { right as f64 / (right + wrong) as f64 };
    for (dy, right, wrong, rgb, other, name) in
        [(-0.7, containers.a, containers.a_false, A, B, "A"), (0.7, containers.b, containers.b_false, B, A, "B")]
    {
        cubes.push(cube((bin_x, y + dy, -0.05), (1.0, 1.0, 0.1), DARK));
        cubes.extend(stack(bin_x, y + dy, 0.8, [(right as f64, rgb), (wrong as f64, other)], per_unit));
        texts.push(text(
            (bin_x, y + dy, FULL_HEIGHT + 0.4),
            format!("{name}: {right} + {wrong} wrong, purity {:.2}", purity(right, wrong)),
        ));
    }
    texts.push(text(
        (0.0, y - 1.2, 0.0),
        format!(
            "{} episode {} step {}  reward {:+.2} (total {:+.2})  purity {:.3}",
            namespace,
            model.episode(),
            model.step_count(),
            model.last_step().map_or(0.0, |s| s.reward),
            model.cumulative_reward(),
            containers.purity()
        ),
    ));
    SceneEntity {
        timestamp,
        frame_id: FRAME.to_string(),
        id: format!("line_{index}"),
        lifetime: None, // until replaced: the next tick's update
        frame_locked: false,
        cubes,
        texts,
        ..SceneEntity::default()
    }
}

/// The scene of line `index` (in `namespace`) at its current tick: one entity, `line_<index>`,
/// which the next tick's replaces.
pub(super) fn scene(host: &HostedLine, index: usize, namespace: &str) -> SceneUpdate {
    let stamp = host.stamp();
    let timestamp = Some(Timestamp::new(stamp.sec.max(0) as u32, stamp.nanosec));
    SceneUpdate { deletions: Vec::new(), entities: vec![line_entity(host, index, namespace, timestamp)] }
}
