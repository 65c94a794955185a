//! Perception simulation: the detections a robot's camera delivers, like HL-SIM's simulated
//! vision. Objects are reported only inside the horizontal field of view, within range and the
//! vertical coverage the head pitch gives, when no robot stands in the line of sight; range and
//! bearing carry noise that grows with distance; detection probability falls with distance and
//! with head speed (motion blur); an image may contain a false positive.
//!
//! Detections are relative to the camera: `range` is the ground distance from the robot,
//! `bearing` the angle from the optical axis (the head yaw), left positive.

use strata_robot::platform::{Detection, HeadAngles, ObjectClass};
use strata_robot::{Global as FieldFrame, Point, Pose};
use strata_spl::field::{Colour, Landmark, Side};
use strata_spl::{Field, ObjectKind};

use crate::config::CameraConfig;
use crate::noise::CameraNoise;
use crate::random::Stream;
use crate::util::{bearing, length, sin_cos, wrap_half_turn};

/// What the camera reports about a fixed point feature.
#[derive(Clone, Copy, Debug)]
struct PointFeature {
    class: ObjectClass,
    variant: Option<u16>,
    /// Orientation in the field frame (line crossings).
    orientation: Option<f64>,
    /// Sticks up from the ground: seen above the lower edge of the image.
    tall: bool,
}

/// The static part of what cameras can see: the field's landmarks and lines, and which of them
/// a camera could see from each part of the carpet looking into each range of directions.
#[derive(Clone, Debug)]
pub(crate) struct Scene {
    /// Point features' positions, then the lines' start points, then their end points.
    xs: Vec<f64>,
    ys: Vec<f64>,
    points: Vec<PointFeature>,
    lines: Vec<LineFeature>,
    grid: Grid,
    /// tan(fov / 2) of the camera the grid was built for.
    tan_half: f64,
}

/// What the camera needs of a field line besides its ends.
#[derive(Clone, Copy, Debug)]
struct LineFeature {
    /// Direction in the field frame.
    direction: f64,
    /// Squared length and its inverse.
    len2: f64,
    inv_len2: f64,
}

fn class(kind: ObjectKind) -> ObjectClass {
    ObjectClass(kind.code())
}

impl Scene {
    /// The scene of `field` for cameras of `camera`'s field of view and range, on a carpet of
    /// half extents `carpet` (robots beyond it are served too, only more slowly).
    pub fn new(field: &Field, camera: &CameraConfig, carpet: [f64; 2]) -> Scene {
        let colours = field.dimensions().goal_colours;
        let mut xs = Vec::new();
        let mut ys = Vec::new();
        let mut points = Vec::new();
        for landmark in field.landmarks() {
            let p = landmark.position();
            xs.push(p.x);
            ys.push(p.y);
            let mut feature = PointFeature {
                class: class(landmark.object_kind()),
                variant: None,
                orientation: None,
                tall: false,
            };
            match landmark {
                Landmark::GoalPost { goal, .. } => {
                    let colour = match goal {
                        Side::Own => colours.own,
                        Side::Opponent => colours.opponent,
                    };
                    // White posts look alike; coloured ones tell their goal apart.
                    feature.variant = (colour != Colour::White).then(|| colour.code());
                    feature.tall = true;
                }
                Landmark::Crossing { orientation, .. } => {
                    feature.orientation = Some(*orientation);
                }
                Landmark::Beacon { index, .. } => {
                    feature.variant = Some(u16::try_from(*index).unwrap_or(u16::MAX));
                    feature.tall = true;
                }
                Landmark::CenterCircle { .. } | Landmark::PenaltyMark { .. } => {}
            }
            points.push(feature);
        }
        let lines: Vec<_> = field.lines().to_vec();
        xs.extend(lines.iter().map(|l| l.start.x));
        ys.extend(lines.iter().map(|l| l.start.y));
        xs.extend(lines.iter().map(|l| l.end.x));
        ys.extend(lines.iter().map(|l| l.end.y));
        let lines = lines
            .iter()
            .map(|l| {
                let (dx, dy) = (l.end.x - l.start.x, l.end.y - l.start.y);
                let len2 = dx * dx + dy * dy;
                let inv_len2 = if len2 > 0.0 { 1.0 / len2 } else { 0.0 };
                LineFeature { direction: dy.atan2(dx), len2, inv_len2 }
            })
            .collect();
        let grid = Grid::new(&xs, &ys, points.len(), camera, carpet);
        Scene { xs, ys, points, lines, grid, tan_half: (camera.fov / 2.0).tan() }
    }
}

/// Which features (point masks: bit `i` for point `i`; line masks: bit `j` for line `j`) a
/// camera could see from each square cell of the carpet with its axis in each of [`SECTORS`]
/// sectors of directions — a superset of what it sees from anywhere in the cell looking
/// anywhere in the sector, so an image tests only these exactly (about a quarter of the
/// field's features).
#[derive(Clone, Debug)]
struct Grid {
    /// The field of view and range it was built for; other cameras test every feature.
    fov: f64,
    range: f64,
    /// Lower corner, inverse cell size, cells along x and y.
    x0: f64,
    y0: f64,
    inv_cell: f64,
    nx: usize,
    ny: usize,
    /// Words of the point mask and of the line mask of a cell and sector.
    point_words: usize,
    line_words: usize,
    /// The point mask then the line mask of each cell and sector, indexed by
    /// ((cell y * nx + cell x) * SECTORS + sector) * (point_words + line_words).
    masks: Vec<u64>,
    /// Every point and every line.
    all: Vec<u64>,
}

/// Sectors of camera directions per turn.
const SECTORS: usize = 32;
/// Side of a grid cell, m.
const CELL: f64 = 0.5;
/// Extra angle (rad) the sectors are widened by: covers the difference between the camera
/// axis as an angle (which picks the sector) and as the sine and cosine the image uses.
const SECTOR_MARGIN: f64 = 0.01;

/// Which sectors' wedges can hold something seen from a cell's centre in an arc of
/// directions: a wedge of half-angle `half` from the apex `k` behind the centre (`k` sin `half`
/// = `r`) holds a point at distance `d` > `k` from the centre only if the point's direction
/// is within `half` + asin(`r` / `d`) of the sector's (law of sines in the triangle of apex,
/// centre and point: the angle at the point is below the one at the apex, at most `half`,
/// and its sine is at most `r` / `d`).
struct SectorSpan {
    half: f64,
    r: f64,
    k: f64,
    width: f64,
}

impl SectorSpan {
    /// The sectors (the first, unwrapped, and how many) whose wedges can hold a point of the
    /// arc from direction `start` over `arc` (rad, less than a half turn) no nearer than
    /// `distance` to the centre: with a margin of 0.02 rad far beyond rounding, all of them
    /// within `k` (and a percent).
    fn sectors(&self, start: f64, arc: f64, distance: f64) -> (i64, i64) {
        let all = (0, SECTORS as i64);
        if !(distance > 1.01 * self.k && arc.is_finite() && start.is_finite()) {
            return all;
        }
        let bound = self.half + (self.r / distance).asin() + 0.02;
        let first = ((start - bound) / self.width - 0.5).floor() as i64;
        let last = ((start + arc + bound) / self.width - 0.5).ceil() as i64;
        if last - first + 1 >= SECTORS as i64 { all } else { (first, last - first + 1) }
    }
}

impl Grid {
    fn new(xs: &[f64], ys: &[f64], points: usize, camera: &CameraConfig, carpet: [f64; 2]) -> Grid {
        use std::f64::consts::{FRAC_PI_2, TAU};
        let n = xs.len();
        let lines = (n - points) / 2;
        let (point_words, line_words) = (points.div_ceil(64).max(1), lines.div_ceil(64).max(1));
        let words = point_words + line_words;
        let mut all = vec![0u64; words];
        for i in 0..points {
            all[i / 64] |= 1 << (i % 64);
        }
        for j in 0..lines {
            all[point_words + j / 64] |= 1 << (j % 64);
        }
        // The carpet and half a metre around it (robots pushed against its edge).
        let margin = 0.5;
        let (x0, y0) = (-carpet[0] - margin, -carpet[1] - margin);
        let cells =
            |extent: f64| (((2.0 * (extent + margin)) / CELL).ceil() as usize).clamp(1, 400);
        let (nx, ny) = (cells(carpet[0]), cells(carpet[1]));
        let width = TAU / SECTORS as f64;
        let half = camera.fov / 2.0 + width / 2.0 + SECTOR_MARGIN;
        let usable = camera.fov.is_finite()
            && camera.range.is_finite()
            && half < FRAC_PI_2 - 0.05
            && carpet.iter().all(|e| e.is_finite() && *e >= 0.0);
        if !usable {
            return Grid {
                fov: f64::NAN,
                range: f64::NAN,
                x0,
                y0,
                inv_cell: 1.0 / CELL,
                nx: 0,
                ny: 0,
                point_words,
                line_words,
                masks: Vec::new(),
                all,
            };
        }
        // A viewer anywhere in a cell is within `r` of its centre; one looking anywhere in a
        // sector sees inside the wedge of half-angle `half` around the sector's middle from
        // the apex `k` behind the centre, whose wedge holds that whole disc, and no farther
        // than `reach` from the centre.
        let r = CELL * std::f64::consts::FRAC_1_SQRT_2 + 1e-6;
        let k = r / half.sin();
        let reach = camera.range + r + 1e-6;
        let tan = half.tan();
        let mut masks = vec![0u64; nx * ny * SECTORS * words];
        // Per cell, the points within reach of its centre and the lines that come within
        // reach (plus a margin over rounding: the piece a sector keeps of a line is no nearer
        // than the whole line), each tested exactly only in the sectors whose wedge can hold
        // it ([`SectorSpan`]).
        let axes: Vec<(f64, f64)> =
            (0..SECTORS).map(|sector| ((sector as f64 + 0.5) * width).sin_cos()).collect();
        let span = SectorSpan { half, r, k, width };
        let mut apexes = vec![(0.0, 0.0); SECTORS];
        for cy in 0..ny {
            for cx in 0..nx {
                let (ccx, ccy) = (x0 + (cx as f64 + 0.5) * CELL, y0 + (cy as f64 + 0.5) * CELL);
                for (apex, &(sin, cos)) in apexes.iter_mut().zip(&axes) {
                    *apex = (ccx - k * cos, ccy - k * sin);
                }
                let cell = &mut masks[(cy * nx + cx) * SECTORS * words..][..SECTORS * words];
                // The exact test of the wedge of `sector` (the apex's frame, as in an image).
                let local = |sector: usize, i: usize| {
                    let ((sin, cos), (ax, ay)) = (axes[sector], apexes[sector]);
                    let (dx, dy) = (xs[i] - ax, ys[i] - ay);
                    (cos * dx + sin * dy, -sin * dx + cos * dy)
                };
                for i in 0..points {
                    let (wx, wy) = (xs[i] - ccx, ys[i] - ccy);
                    let distance = length(wx, wy);
                    let near = distance <= reach;
                    if !near {
                        continue;
                    }
                    let (first, count) = span.sectors(wy.atan2(wx), 0.0, distance);
                    for n in first..first + count {
                        let sector = n.rem_euclid(SECTORS as i64) as usize;
                        let (x, y) = local(sector, i);
                        if x * tan >= y.abs() {
                            cell[sector * words + i / 64] |= 1 << (i % 64);
                        }
                    }
                }
                for j in 0..lines {
                    let (a, b) = (points + j, points + lines + j);
                    let (dx, dy) = (xs[b] - xs[a], ys[b] - ys[a]);
                    let len2 = dx * dx + dy * dy;
                    let nearest = |t0: f64, t1: f64| {
                        let t = if len2 > 0.0 {
                            (((ccx - xs[a]) * dx + (ccy - ys[a]) * dy) / len2).clamp(t0, t1)
                        } else {
                            t0
                        };
                        length(xs[a] + dx * t - ccx, ys[a] + dy * t - ccy)
                    };
                    let distance = nearest(0.0, 1.0);
                    let near = distance <= reach + 1e-9;
                    if !near {
                        continue;
                    }
                    // The directions from the centre to the segment: an arc shorter than a half
                    // turn when the segment keeps away from the centre (the only case where
                    // `sectors` narrows).
                    let from = (ys[a] - ccy).atan2(xs[a] - ccx);
                    let to = (ys[b] - ccy).atan2(xs[b] - ccx);
                    let turn = crate::util::wrap_angle(to - from);
                    let (start, arc) = if turn >= 0.0 { (from, turn) } else { (to, -turn) };
                    let (first, count) = span.sectors(start, arc, distance);
                    for n in first..first + count {
                        let sector = n.rem_euclid(SECTORS as i64) as usize;
                        let Some((t0, t1)) = clip_to_wedge(local(sector, a), local(sector, b), tan)
                        else {
                            continue;
                        };
                        // The piece's point nearest to the cell's centre.
                        if nearest(t0, t1) <= reach {
                            cell[sector * words + point_words + j / 64] |= 1 << (j % 64);
                        }
                    }
                }
            }
        }
        Grid {
            fov: camera.fov,
            range: camera.range,
            x0,
            y0,
            inv_cell: 1.0 / CELL,
            nx,
            ny,
            point_words,
            line_words,
            masks,
            all,
        }
    }

    /// Whether the grid was built for cameras of `config`.
    fn fits(&self, config: &CameraConfig) -> bool {
        config.fov == self.fov && config.range == self.range
    }

    /// The points and the lines a camera at (x, y) with its axis at angle `axis` could see (of
    /// a configuration the grid [`fits`](Grid::fits)).
    #[inline]
    fn candidates(&self, x: f64, y: f64, axis: f64) -> (&[u64], &[u64]) {
        let fx = (x - self.x0) * self.inv_cell;
        let fy = (y - self.y0) * self.inv_cell;
        let s = axis * (SECTORS as f64 / std::f64::consts::TAU);
        let words = self.point_words + self.line_words;
        // `!(a < b)` also sends NaN to the fallback.
        let inside = fx >= 0.0 && fy >= 0.0 && fx < self.nx as f64 && fy < self.ny as f64;
        let masks = if inside && s.abs() < 1e9 {
            // In range: the conversions truncate, as a floor of these non-negative values.
            let (cx, cy) = (fx as i64 as usize, fy as i64 as usize);
            // Floor without the library call: truncation, one down for negative fractions.
            let t = s as i64;
            let sector = ((t - i64::from((t as f64) > s)) & (SECTORS as i64 - 1)) as usize;
            let at = ((cy * self.nx + cx) * SECTORS + sector) * words;
            &self.masks[at..at + words]
        } else {
            &self.all[..]
        };
        masks.split_at(self.point_words)
    }
}

/// Another robot as a camera sees it: something to detect and something that hides.
#[derive(Clone, Copy, Debug)]
pub(crate) struct RobotMark {
    pub position: Point<FieldFrame>,
    /// Jersey colour code.
    pub variant: u16,
}

/// The robots on the field as cameras see them, with their slots.
#[derive(Clone, Debug, Default)]
pub(crate) struct RobotMarks {
    /// Rows, not columns: an image reads every field of every robot, and one slice walks
    /// cheaper than four zipped ones.
    marks: Vec<MarkRow>,
}

#[derive(Clone, Copy, Debug)]
struct MarkRow {
    x: f64,
    y: f64,
    slot: usize,
    variant: u16,
}

impl RobotMarks {
    #[inline]
    pub fn clear(&mut self) {
        self.marks.clear();
    }

    /// Adds the robot of slot `slot` (slots in increasing order).
    #[inline]
    pub fn push(&mut self, slot: usize, mark: RobotMark) {
        let (x, y) = (mark.position.x, mark.position.y);
        self.marks.push(MarkRow { x, y, slot, variant: mark.variant });
    }
}

/// The referee showing a gesture, as cameras see it.
#[derive(Clone, Copy, Debug)]
pub(crate) struct GestureSight {
    pub position: Point<FieldFrame>,
    /// The gesture's code (`strata_spl::Gesture`), reported as the detection's variant.
    pub gesture: u16,
    /// How far cameras see it, m.
    pub range: f64,
    /// Probability that an image whose view holds it reports it.
    pub detection: f64,
}

/// The robot taking the image.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Viewer {
    pub pose: Pose,
    /// Sine and cosine of the camera's direction (heading plus head yaw).
    pub axis: (f64, f64),
    pub head: HeadAngles,
    /// Head angular speed, rad/s (motion blur).
    pub head_rate: f64,
    /// Its own slot (it does not see or hide behind itself).
    pub index: Option<usize>,
    /// Lying, falling or getting up: the camera sees the sky or the carpet.
    pub blind: bool,
    /// The ground distances the camera covers at the head's pitch ([`ground_band`]).
    pub band: (f64, f64),
}

/// An object in the camera frame: x along the optical axis, y to the left.
#[derive(Clone, Copy, Debug)]
struct Local {
    x: f64,
    y: f64,
    distance: f64,
}

impl Local {
    fn new(x: f64, y: f64) -> Local {
        Local { x, y, distance: length(x, y) }
    }
}

/// Reusable buffers, so taking an image allocates nothing in the steady state.
#[derive(Clone, Debug, Default)]
pub(crate) struct Scratch {
    occluders: Vec<Local>,
    seen: Vec<(Local, u16)>,
}

pub(crate) struct Camera<'a> {
    pub config: &'a CameraConfig,
    pub noise: &'a CameraNoise,
    pub robot_radius: f64,
    /// tan(fov / 2).
    pub tan_half: f64,
}

impl<'a> Camera<'a> {
    /// A camera of `config` for images of `scene` (which keeps tan(fov / 2) of the camera it
    /// was built for).
    pub fn new(
        config: &'a CameraConfig,
        noise: &'a CameraNoise,
        robot_radius: f64,
        scene: &Scene,
    ) -> Camera<'a> {
        let tan_half =
            if scene.grid.fits(config) { scene.tan_half } else { (config.fov / 2.0).tan() };
        Camera { config, noise, robot_radius, tan_half }
    }
}

impl Camera<'_> {
    /// Appends the detections of one image to `out`.
    #[allow(clippy::too_many_arguments)]
    pub fn capture(
        &self,
        scene: &Scene,
        viewer: &Viewer,
        robots: &RobotMarks,
        ball: Option<Point<FieldFrame>>,
        rng: &mut Stream,
        scratch: &mut Scratch,
        out: &mut Vec<Detection>,
    ) {
        if viewer.blind {
            return;
        }
        let config = self.config;
        let axis = viewer.pose.theta + viewer.head.yaw;
        let (sin, cos) = viewer.axis;
        let (ox, oy) = (viewer.pose.x, viewer.pose.y);
        let to_local = |x: f64, y: f64| {
            let dx = x - ox;
            let dy = y - oy;
            (cos * dx + sin * dy, -sin * dx + cos * dy)
        };
        let tan_half = self.tan_half;
        let range = config.range;
        let range2 = range * range;
        let in_view =
            |x: f64, y: f64| x > 0.0 && y.abs() <= x * tan_half && x * x + y * y <= range2;
        let (near, far) = viewer.band;

        // Robots in or beside the view can hide what is behind them; those in it are seen.
        let radius = self.robot_radius;
        let beside = radius * (1.0 + tan_half * tan_half).sqrt();
        scratch.occluders.clear();
        scratch.seen.clear();
        let own = viewer.index.unwrap_or(usize::MAX);
        for &MarkRow { x: mx, y: my, slot, variant } in &robots.marks {
            let (x, y) = to_local(mx, my);
            if (x > -radius) & (y.abs() <= x * tan_half + beside) & (x * x + y * y < range2)
                && slot != own
            {
                let local = Local::new(x, y);
                scratch.occluders.push(local);
                if in_view(x, y) && local.distance >= near {
                    scratch.seen.push((local, variant));
                }
            }
        }
        let occluders = &scratch.occluders;
        let hidden = |target: &Local| {
            occluders.iter().any(|o| {
                o.distance < target.distance - radius
                    && o.x * target.x + o.y * target.y > 0.0
                    && (o.x * target.y - o.y * target.x).abs() < radius * target.distance
            })
        };

        let (point_mask, line_mask) = if scene.grid.fits(config) {
            scene.grid.candidates(ox, oy, axis)
        } else {
            scene.grid.all[..].split_at(scene.grid.point_words)
        };
        // Room for the detections of nearly every image at once: a fresh buffer (its platform
        // keeps the one it read) is allocated once, where growing by pushes reallocated it
        // two or three times.
        out.reserve(DETECTIONS_RESERVED);

        let reporter = Reporter::new(self.noise, range, viewer.head_rate);
        if let Some(ball) = ball {
            let (x, y) = to_local(ball.x, ball.y);
            if in_view(x, y) {
                let local = Local::new(x, y);
                if local.distance >= near && local.distance <= far {
                    let ball = class(ObjectKind::Ball);
                    reporter.report(rng, out, ball, None, &local, Facing::None, 1.0, &hidden);
                }
            }
        }
        let robot = class(ObjectKind::Robot);
        for (local, variant) in &scratch.seen {
            reporter.report(rng, out, robot, Some(*variant), local, Facing::None, 1.0, &hidden);
        }

        // The fixed points and lines this camera could see from where it stands, looking where
        // it looks (the scene's grid), each tested exactly.
        let landmark = self.noise.landmark_factor;
        let points = scene.points.len();
        let lines = scene.lines.len();
        let (px, py) = (&scene.xs[..points + 2 * lines], &scene.ys[..points + 2 * lines]);
        for (word, &bits) in point_mask.iter().enumerate() {
            let mut bits = bits;
            while bits != 0 {
                let i = word * 64 + bits.trailing_zeros() as usize;
                bits &= bits - 1;
                let Some(feature) = scene.points.get(i) else { continue };
                let (x, y) = to_local(px[i], py[i]);
                let inside = (x * tan_half - y >= 0.0) & (x * tan_half + y >= 0.0);
                if !inside || x * x + y * y > range2 || x <= 0.0 {
                    continue;
                }
                let local = Local::new(x, y);
                if local.distance < near || (!feature.tall && local.distance > far) {
                    continue;
                }
                let facing = feature.orientation.map_or(Facing::None, |o| Facing::Full(o - axis));
                let (class, variant) = (feature.class, feature.variant);
                reporter.report(rng, out, class, variant, &local, facing, landmark, &hidden);
            }
        }
        let line_class = class(ObjectKind::FieldLine);
        let max_distance = range.min(far);
        for (word, &bits) in line_mask.iter().enumerate() {
            let mut bits = bits;
            while bits != 0 {
                let j = word * 64 + bits.trailing_zeros() as usize;
                bits &= bits - 1;
                let Some(line) = scene.lines.get(j) else { continue };
                let (a, b) = (points + j, points + lines + j);
                let start = to_local(px[a], py[a]);
                let end = to_local(px[b], py[b]);
                let Some(closest) =
                    visible_piece(start, end, tan_half, config.min_line_length, line)
                else {
                    continue;
                };
                if closest.distance > max_distance {
                    continue;
                }
                let facing = Facing::Half(line.direction - axis);
                reporter.report(rng, out, line_class, None, &closest, facing, landmark, &hidden);
            }
        }

        self.false_positive(rng, out);
    }

    /// Appends the referee's gesture to an image's detections when the view holds the referee:
    /// a point within the horizontal field of view and the gesture's own range (whatever the
    /// head pitch: a person is tall), not behind another robot, the camera not blind. Range
    /// and bearing carry the camera's noise; the detection probability is the gesture's own,
    /// flat over its range.
    pub fn capture_gesture(
        &self,
        viewer: &Viewer,
        robots: &RobotMarks,
        referee: &GestureSight,
        rng: &mut Stream,
        out: &mut Vec<Detection>,
    ) {
        if viewer.blind {
            return;
        }
        let (sin, cos) = viewer.axis;
        let (ox, oy) = (viewer.pose.x, viewer.pose.y);
        let to_local = |x: f64, y: f64| {
            let dx = x - ox;
            let dy = y - oy;
            (cos * dx + sin * dy, -sin * dx + cos * dy)
        };
        let (x, y) = to_local(referee.position.x, referee.position.y);
        let range = referee.range;
        if !(x > 0.0 && y.abs() <= x * self.tan_half && x * x + y * y <= range * range) {
            return;
        }
        let local = Local::new(x, y);
        let radius = self.robot_radius;
        let own = viewer.index.unwrap_or(usize::MAX);
        // The referee stands farther than the camera's range, so the robots that hide it are
        // not all among an image's occluders: every robot is tested, for a detection made.
        let hidden = |target: &Local| {
            robots.marks.iter().any(|m| {
                let (mx, my) = to_local(m.x, m.y);
                m.slot != own
                    && length(mx, my) < target.distance - radius
                    && mx * target.x + my * target.y > 0.0
                    && (mx * target.y - my * target.x).abs() < radius * target.distance
            })
        };
        let reporter = Reporter::new(self.noise, self.config.range, viewer.head_rate);
        let class = class(ObjectKind::Referee);
        let (variant, detection) = (Some(referee.gesture), referee.detection);
        reporter.report_with(rng, out, class, variant, &local, Facing::None, detection, &hidden);
    }

    /// Now and then an object that is not there.
    fn false_positive(&self, rng: &mut Stream, out: &mut Vec<Detection>) {
        let config = self.config;
        if rng.chance(self.noise.false_positive_rate) {
            const GHOSTS: [ObjectKind; 6] = [
                ObjectKind::Ball,
                ObjectKind::Ball,
                ObjectKind::Robot,
                ObjectKind::GoalPost,
                ObjectKind::LCrossing,
                ObjectKind::TCrossing,
            ];
            let pick = rng.uniform(0.0, GHOSTS.len() as f64) as usize;
            let kind = GHOSTS[pick.min(GHOSTS.len() - 1)];
            let range = rng.uniform(0.3, config.range);
            let bearing = rng.uniform(-config.fov / 2.0, config.fov / 2.0);
            let orientation = matches!(kind, ObjectKind::LCrossing | ObjectKind::TCrossing)
                .then(|| rng.uniform(-std::f64::consts::PI, std::f64::consts::PI));
            out.push(Detection { class: class(kind), variant: None, range, bearing, orientation });
        }
    }
}

/// Detections an image buffer is given room for (about five on average, rarely more than
/// sixteen).
const DETECTIONS_RESERVED: usize = 16;

/// Decides whether a detection is made and adds its noise.
struct Reporter<'a> {
    noise: &'a CameraNoise,
    /// Detection probability at zero distance and its change per unit of `distance / range`,
    /// both with the motion blur.
    near: f64,
    slope: f64,
    inv_range: f64,
}

impl<'a> Reporter<'a> {
    fn new(noise: &'a CameraNoise, range: f64, head_rate: f64) -> Reporter<'a> {
        let blur = (1.0 - noise.motion_blur_per_rad_s * head_rate).max(0.0);
        Reporter {
            noise,
            near: noise.detection_near * blur,
            slope: (noise.detection_far - noise.detection_near) * blur,
            inv_range: 1.0 / range,
        }
    }

    /// Reports `local` with probability falling with distance (times `factor`), with noise,
    /// unless it is `hidden` (tested only for a detection the draw decided to make).
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn report(
        &self,
        rng: &mut Stream,
        out: &mut Vec<Detection>,
        class: ObjectClass,
        variant: Option<u16>,
        local: &Local,
        facing: Facing,
        factor: f64,
        hidden: &impl Fn(&Local) -> bool,
    ) {
        // Distances are not negative.
        let t = local.distance * self.inv_range;
        let t = if t < 1.0 { t } else { 1.0 };
        let probability = (self.near + self.slope * t) * factor;
        self.report_with(rng, out, class, variant, local, facing, probability, hidden);
    }

    /// Reports `local` with `probability`, with noise, unless it is `hidden` (tested only for
    /// a detection the draw decided to make).
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn report_with(
        &self,
        rng: &mut Stream,
        out: &mut Vec<Detection>,
        class: ObjectClass,
        variant: Option<u16>,
        local: &Local,
        facing: Facing,
        probability: f64,
        hidden: &impl Fn(&Local) -> bool,
    ) {
        // Two words: 32 bits decide the detection, three normal samples give the noise (a
        // zero deviation adds exactly zero, so the zero-noise mode stays exact).
        let first = rng.next_u64();
        let detected = Stream::unit_from(first as u32) < probability;
        if !detected || hidden(local) {
            return;
        }
        let second = rng.next_u64();
        let noise = self.noise;
        let range_sigma = noise.range_sigma + noise.range_sigma_per_metre * local.distance;
        let bearing_sigma = noise.bearing_sigma + noise.bearing_sigma_per_metre * local.distance;
        let range = local.distance + rng.normal_from((first >> 32) as u32) * range_sigma;
        let range = if range > 0.0 { range } else { 0.0 };
        let bearing = bearing(local.y, local.x) + rng.normal_from(second as u32) * bearing_sigma;
        let orientation = match facing {
            Facing::None => None,
            Facing::Full(o) => Some(wrap_relative(o)),
            Facing::Half(o) => Some(wrap_half_turn(o)),
        }
        .map(|o| o + rng.normal_from((second >> 32) as u32) * noise.orientation_sigma);
        out.push(Detection { class, variant, range, bearing, orientation });
    }
}

/// A detection's orientation relative to the camera axis, before wrapping.
#[derive(Clone, Copy, Debug)]
enum Facing {
    None,
    /// A crossing's: wrapped to (-pi, pi].
    Full(f64),
    /// An undirected line's: wrapped to (-pi/2, pi/2].
    Half(f64),
}

fn wrap_relative(angle: f64) -> f64 {
    crate::util::wrap_angle(angle)
}

/// The ground distances the camera covers at head pitch `pitch`: [near, far].
pub(crate) fn ground_band(config: &CameraConfig, pitch: f64) -> (f64, f64) {
    let tan = |a: f64| {
        let (s, c) = sin_cos(a);
        s / c
    };
    let lower = pitch + config.min_depression;
    let upper = pitch + config.max_depression;
    let far = if lower > 1e-6 { config.height / tan(lower) } else { f64::INFINITY };
    let near = if upper < std::f64::consts::FRAC_PI_2 - 1e-6 {
        (config.height / tan(upper)).max(0.0)
    } else {
        0.0
    };
    (near, far)
}

/// The parameter interval [t0, t1] of the piece of segment a-b inside the wedge
/// `x * tan >= |y|` (a camera frame), if any.
#[inline]
fn clip_to_wedge(a: (f64, f64), b: (f64, f64), tan: f64) -> Option<(f64, f64)> {
    // Inside the wedge: x * tan - y >= 0 (left edge) and x * tan + y >= 0 (right edge).
    let (la, lb) = (a.0 * tan - a.1, b.0 * tan - b.1);
    let (ra, rb) = (a.0 * tan + a.1, b.0 * tan + b.1);
    if (la < 0.0 && lb < 0.0) || (ra < 0.0 && rb < 0.0) {
        return None;
    }
    // Where each edge crosses the segment (finite: the signs differ), by plain comparisons
    // (cheaper than `f64::max` and `min`, whose NaN rules need not apply).
    let (mut t0, mut t1) = (0.0f64, 1.0f64);
    for (ha, hb) in [(la, lb), (ra, rb)] {
        if ha < 0.0 {
            let t = ha / (ha - hb);
            if t > t0 {
                t0 = t;
            }
        } else if hb < 0.0 {
            let t = ha / (ha - hb);
            if t < t1 {
                t1 = t;
            }
        }
    }
    (t1 > t0).then_some((t0, t1))
}

/// Clips a segment (camera frame) to the horizontal field of view; returns the point of the
/// visible piece nearest to the camera, if the piece is long enough. `line` gives the
/// segment's squared length and its inverse (the same in any frame).
fn visible_piece(
    a: (f64, f64),
    b: (f64, f64),
    tan_half: f64,
    min_length: f64,
    line: &LineFeature,
) -> Option<Local> {
    let (t0, t1) = clip_to_wedge(a, b, tan_half)?;
    if line.len2 * (t1 - t0) * (t1 - t0) < min_length * min_length {
        return None;
    }
    let (dx, dy) = (b.0 - a.0, b.1 - a.1);
    let t = -(a.0 * dx + a.1 * dy) * line.inv_len2;
    let t = if t < t0 {
        t0
    } else if t > t1 {
        t1
    } else {
        t
    };
    let x = a.0 + dx * t;
    let y = a.1 + dy * t;
    // Both wedge edges meet at the camera: a piece through it has no direction to report.
    (x > 1e-6).then(|| Local::new(x, y))
}

/// The line data of the segment a-b, for [`visible_piece`].
#[cfg(test)]
fn line_of(a: (f64, f64), b: (f64, f64)) -> LineFeature {
    let (dx, dy) = (b.0 - a.0, b.1 - a.1);
    let len2 = dx * dx + dy * dy;
    LineFeature {
        direction: dy.atan2(dx),
        len2,
        inv_len2: if len2 > 0.0 { 1.0 / len2 } else { 0.0 },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_line_across_the_view_is_seen_at_its_nearest_point() {
        let tan_half = 0.5f64;
        let piece = visible_piece(
            (2.0, -5.0),
            (2.0, 5.0),
            tan_half,
            0.1,
            &line_of((2.0, -5.0), (2.0, 5.0)),
        )
        .expect("crosses the view");
        assert!((piece.x - 2.0).abs() < 1e-12 && piece.y.abs() < 1e-12);
        // Beside the wedge on both ends.
        let line = line_of((1.0, 2.0), (3.0, 4.0));
        assert!(visible_piece((1.0, 2.0), (3.0, 4.0), tan_half, 0.1, &line).is_none());
        // Behind the camera.
        let line = line_of((-1.0, -1.0), (-1.0, 1.0));
        assert!(visible_piece((-1.0, -1.0), (-1.0, 1.0), tan_half, 0.1, &line).is_none());
    }

    #[test]
    fn the_grid_keeps_every_feature_a_camera_can_see() {
        let config = CameraConfig::default();
        for preset in ["spl", "paper2010"] {
            let field = Field::preset(preset).expect("preset");
            let carpet = [field.half_length() + 0.7, field.half_width() + 0.7];
            let scene = Scene::new(&field, &config, carpet);
            let (points, lines) = (scene.points.len(), scene.lines.len());
            let tan_half = (config.fov / 2.0).tan();
            let mut rng = Stream::new(5, "grid");
            let (mut candidates, mut visible) = (0usize, 0usize);
            for _ in 0..20_000 {
                let x = rng.uniform(-carpet[0] - 0.6, carpet[0] + 0.6);
                let y = rng.uniform(-carpet[1] - 0.6, carpet[1] + 0.6);
                let axis = rng.uniform(-6.0, 6.0);
                let (sin, cos) = sin_cos(axis);
                let local = |i: usize| {
                    let (dx, dy) = (scene.xs[i] - x, scene.ys[i] - y);
                    (cos * dx + sin * dy, -sin * dx + cos * dy)
                };
                assert!(scene.grid.fits(&config));
                let (point_mask, line_mask) = scene.grid.candidates(x, y, axis);
                let has = |mask: &[u64], bit: usize| mask[bit / 64] & (1 << (bit % 64)) != 0;
                candidates += point_mask
                    .iter()
                    .chain(line_mask)
                    .map(|w| w.count_ones() as usize)
                    .sum::<usize>();
                for i in 0..points {
                    let (lx, ly) = local(i);
                    let seen = lx > 0.0
                        && lx * tan_half - ly >= 0.0
                        && lx * tan_half + ly >= 0.0
                        && lx * lx + ly * ly <= config.range * config.range;
                    visible += usize::from(seen);
                    assert!(!seen || has(point_mask, i), "point {i} from ({x}, {y}) at {axis}");
                }
                for j in 0..lines {
                    let (a, b) = (local(points + j), local(points + lines + j));
                    let piece = visible_piece(a, b, tan_half, 0.0, &scene.lines[j]);
                    let seen = piece.is_some_and(|p| p.distance <= config.range);
                    visible += usize::from(seen);
                    assert!(!seen || has(line_mask, j), "line {j} from ({x}, {y}) at {axis}");
                }
            }
            // The grid is worth it: far fewer candidates than features.
            let per_image = candidates as f64 / 20_000.0;
            assert!(per_image < 0.5 * (points + lines) as f64, "{preset}: {per_image} candidates");
            assert!(visible > 0);
        }
    }

    /// The grid's masks as computed before the per-cell pre-selection: every point and line
    /// tested in every sector.
    fn plain_masks(scene: &Scene, camera: &CameraConfig) -> Vec<u64> {
        use std::f64::consts::TAU;
        let (xs, ys, grid) = (&scene.xs, &scene.ys, &scene.grid);
        let (points, lines) = (scene.points.len(), scene.lines.len());
        let words = grid.point_words + grid.line_words;
        let width = TAU / SECTORS as f64;
        let half = camera.fov / 2.0 + width / 2.0 + SECTOR_MARGIN;
        let r = CELL * std::f64::consts::FRAC_1_SQRT_2 + 1e-6;
        let k = r / half.sin();
        let reach = camera.range + r + 1e-6;
        let tan = half.tan();
        let mut masks = vec![0u64; grid.nx * grid.ny * SECTORS * words];
        for cy in 0..grid.ny {
            for cx in 0..grid.nx {
                let ccx = grid.x0 + (cx as f64 + 0.5) * CELL;
                let ccy = grid.y0 + (cy as f64 + 0.5) * CELL;
                for sector in 0..SECTORS {
                    let (sin, cos) = ((sector as f64 + 0.5) * width).sin_cos();
                    let (ax, ay) = (ccx - k * cos, ccy - k * sin);
                    let local = |i: usize| {
                        let (dx, dy) = (xs[i] - ax, ys[i] - ay);
                        (cos * dx + sin * dy, -sin * dx + cos * dy)
                    };
                    let mask =
                        &mut masks[((cy * grid.nx + cx) * SECTORS + sector) * words..][..words];
                    for i in 0..points {
                        let (x, y) = local(i);
                        let near = length(xs[i] - ccx, ys[i] - ccy) <= reach;
                        if near && x * tan >= y.abs() {
                            mask[i / 64] |= 1 << (i % 64);
                        }
                    }
                    for j in 0..lines {
                        let (a, b) = (points + j, points + lines + j);
                        let Some((t0, t1)) = clip_to_wedge(local(a), local(b), tan) else {
                            continue;
                        };
                        let (dx, dy) = (xs[b] - xs[a], ys[b] - ys[a]);
                        let len2 = dx * dx + dy * dy;
                        let t = if len2 > 0.0 {
                            (((ccx - xs[a]) * dx + (ccy - ys[a]) * dy) / len2).clamp(t0, t1)
                        } else {
                            t0
                        };
                        if length(xs[a] + dx * t - ccx, ys[a] + dy * t - ccy) <= reach {
                            mask[grid.point_words + j / 64] |= 1 << (j % 64);
                        }
                    }
                }
            }
        }
        masks
    }

    #[test]
    fn the_grid_preselection_per_cell_changes_no_mask() {
        for preset in ["spl", "paper2010"] {
            let field = Field::preset(preset).expect("preset");
            for (fov, range) in [(1.0, 6.0), (0.6, 3.0), (1.4, 9.0), (0.2, 1.0), (1.2, 0.5)] {
                let config = CameraConfig { fov, range, ..CameraConfig::default() };
                let carpet = [field.half_length() + 0.7, field.half_width() + 0.7];
                let scene = Scene::new(&field, &config, carpet);
                assert!(scene.grid.fits(&config) && !scene.grid.masks.is_empty());
                assert_eq!(
                    scene.grid.masks,
                    plain_masks(&scene, &config),
                    "{preset} {fov} {range}"
                );
            }
        }
    }

    #[test]
    fn head_pitch_moves_the_visible_band() {
        let config = CameraConfig::default();
        let (near, far) = ground_band(&config, 0.0);
        assert!(far.is_infinite() && near > 0.1 && near < 0.5, "{near}");
        let (near, far) = ground_band(&config, 0.5);
        assert_eq!(near, 0.0);
        assert!(far > 2.0 && far < 10.0, "{far}");
    }
}
