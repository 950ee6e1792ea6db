//! Pictures of the global map: plan (top-down) and section (a vertical cut), with the trajectory,
//! the numbered nodes and the loop closures.

use super::draw::{
    color_bar, legend, quantile, scale_bar, subtitle, title, viridis, Anchor, Axes, Canvas, Swatch,
    INK, LABEL_SCALE, LOOP, TRAJECTORY, WHITE,
};
use image::{Rgb, RgbImage};
use sdem::geometry::{Pose, Vec3};

/// What the map pictures and the viewer page draw: plain values, borrowed.
#[derive(Debug, Clone, Copy)]
pub struct MapView<'a> {
    /// The fused map's points, world frame, metres.
    pub points_in_world: &'a [Vec3],
    /// Each node's sensor pose (`world_from_sensor`), in trajectory order.
    pub world_from_node: &'a [Pose],
    /// Accepted loop closures as `(earlier node, later node)` indices into `world_from_node`.
    pub loop_closures: &'a [(usize, usize)],
}

impl MapView<'_> {
    /// The node positions (sensor origins), world frame.
    pub fn node_positions(&self) -> Vec<Vec3> {
        self.world_from_node
            .iter()
            .map(|p| p.translation.vector)
            .collect()
    }

    /// The height above which points are left out of the plan so a ceiling does not hide the
    /// floor: 1.2 m above the highest sensor origin (`None` without nodes).
    pub fn plan_ceiling_cut(&self) -> Option<f64> {
        self.node_positions()
            .iter()
            .map(|p| p.z)
            .max_by(f64::total_cmp)
            .map(|z| z + 1.2)
    }
}

/// A vertical cut through the map: the points within `half_thickness_m` of the vertical plane
/// through `origin` along the horizontal direction `direction_rad`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Section {
    /// A point of the plane, world x and y, metres.
    pub origin: [f64; 2],
    /// The plane's horizontal direction, radians counter-clockwise from +x.
    pub direction_rad: f64,
    /// Points this far or nearer to the plane are drawn, metres.
    pub half_thickness_m: f64,
}

impl Section {
    /// The x–z plane through the first node (the plane y = y₀).
    pub fn xz_through_start(view: &MapView, half_thickness_m: f64) -> Section {
        let start = view
            .node_positions()
            .first()
            .copied()
            .unwrap_or_else(Vec3::zeros);
        Section {
            origin: [start.x, start.y],
            direction_rad: 0.0,
            half_thickness_m,
        }
    }

    /// The plane along the trajectory's main horizontal direction (the principal axis of the
    /// node positions), through their centroid; the x–z plane through the first node when the
    /// robot barely moved.
    pub fn through_trajectory(view: &MapView, half_thickness_m: f64) -> Section {
        let positions = view.node_positions();
        if positions.len() < 2 {
            return Section::xz_through_start(view, half_thickness_m);
        }
        let n = positions.len() as f64;
        let (mx, my) = (
            positions.iter().map(|p| p.x).sum::<f64>() / n,
            positions.iter().map(|p| p.y).sum::<f64>() / n,
        );
        let (mut sxx, mut syy, mut sxy) = (0.0, 0.0, 0.0);
        for p in &positions {
            sxx += (p.x - mx).powi(2);
            syy += (p.y - my).powi(2);
            sxy += (p.x - mx) * (p.y - my);
        }
        if sxx + syy < 0.01 * n {
            return Section::xz_through_start(view, half_thickness_m);
        }
        let direction_rad = 0.5 * (2.0 * sxy).atan2(sxx - syy);
        Section {
            origin: [mx, my],
            direction_rad,
            half_thickness_m,
        }
    }

    /// `(distance along the plane, signed distance off it)` of a world point.
    fn project(&self, p: &Vec3) -> (f64, f64) {
        let (s, c) = self.direction_rad.sin_cos();
        let (dx, dy) = (p.x - self.origin[0], p.y - self.origin[1]);
        (dx * c + dy * s, -dx * s + dy * c)
    }
}

/// Bounds `[lo, hi]` of the 0.5…99.5 % of `values` and of `always`, widened by 4 %.
fn robust_bounds(values: &[f64], always: &[f64]) -> (f64, f64) {
    let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    let (mut lo, mut hi) = if v.is_empty() {
        (f64::INFINITY, f64::NEG_INFINITY)
    } else {
        let lo = quantile(&mut v, 0.005).unwrap_or(0.0);
        let hi = quantile(&mut v, 0.995).unwrap_or(0.0);
        (lo, hi)
    };
    for &a in always.iter().filter(|a| a.is_finite()) {
        lo = lo.min(a);
        hi = hi.max(a);
    }
    if !(lo.is_finite() && hi.is_finite()) {
        return (-1.0, 1.0);
    }
    if hi - lo < 1.0 {
        let mid = 0.5 * (lo + hi);
        lo = mid - 0.5;
        hi = mid + 0.5;
    }
    let pad = 0.04 * (hi - lo);
    (lo - pad, hi + pad)
}

/// Draws the trajectory, loop closures and numbered nodes at the given pixel positions.
fn draw_graph(canvas: &mut Canvas, nodes_px: &[(f64, f64)], loops: &[(usize, usize)]) {
    for w in nodes_px.windows(2) {
        canvas.line(w[0], w[1], 3.0, TRAJECTORY, None);
    }
    for &(a, b) in loops {
        if let (Some(&pa), Some(&pb)) = (nodes_px.get(a), nodes_px.get(b)) {
            canvas.line(pa, pb, 2.5, LOOP, Some((8.0, 5.0)));
        }
    }
    // Label at most ~40 nodes so numbers stay legible.
    let label_every = nodes_px.len().div_ceil(40).max(1);
    for (i, &(x, y)) in nodes_px.iter().enumerate() {
        canvas.disc(x, y, 6.5, INK);
        canvas.disc(x, y, 4.5, if i == 0 { Rgb([40, 180, 40]) } else { WHITE });
        if i % label_every == 0 || i + 1 == nodes_px.len() {
            canvas.text_boxed(
                (x + 11.0).round() as i64,
                (y - 13.0).round() as i64,
                &i.to_string(),
                LABEL_SCALE,
                Anchor::Left,
                INK,
            );
        }
    }
}

/// The legend of the graph overlay.
fn graph_legend<'a>(with_loops: bool) -> Vec<(Swatch, &'a str)> {
    let mut entries = vec![
        (Swatch::Line(TRAJECTORY, false), "trajectory"),
        (Swatch::Dot(WHITE), "node (number)"),
        (Swatch::Dot(Rgb([40, 180, 40])), "start (node 0)"),
    ];
    if with_loops {
        entries.push((Swatch::Line(LOOP, true), "loop closure"));
    }
    entries
}

/// The map from above: each pixel shows the highest point in it below the ceiling cut
/// ([`MapView::plan_ceiling_cut`]), coloured by height (viridis, a colour bar in metres); then the
/// trajectory (red), the nodes (numbered, node 0 green), the loop closures (dashed magenta), axes
/// in metres with equal scale and a scale bar.
///
/// # Arguments
/// * `view` — the points, node poses and loop closures.
/// * `title` — a line above the picture.
///
/// # Returns
/// An RGB image at most about 1300 × 1100 pixels.
pub fn map_plan(view: &MapView, title_text: &str) -> RgbImage {
    let cut = view.plan_ceiling_cut().unwrap_or(f64::INFINITY);
    let kept: Vec<&Vec3> = view
        .points_in_world
        .iter()
        .filter(|p| p.z <= cut && p.iter().all(|v| v.is_finite()))
        .collect();
    let nodes = view.node_positions();
    let xs: Vec<f64> = kept.iter().map(|p| p.x).collect();
    let ys: Vec<f64> = kept.iter().map(|p| p.y).collect();
    let node_x: Vec<f64> = nodes.iter().map(|p| p.x).collect();
    let node_y: Vec<f64> = nodes.iter().map(|p| p.y).collect();
    let x_range = robust_bounds(&xs, &node_x);
    let y_range = robust_bounds(&ys, &node_y);
    let (left, top) = (120, 90);
    let axes = Axes::equal(left, top, 950, 900, x_range, y_range);
    let mut canvas = Canvas::new(
        (left + axes.width + 290) as u32,
        (top + axes.height + 90) as u32,
    );
    let mut zs: Vec<f64> = kept.iter().map(|p| p.z).collect();
    let z_lo = quantile(&mut zs, 0.01).unwrap_or(0.0);
    let z_hi = quantile(&mut zs, 0.99).unwrap_or(1.0).max(z_lo + 0.1);
    axes.draw_grid(&mut canvas, None, None);
    // Highest point per pixel; each point covers 2 × 2 pixels so sparse floors read as surfaces.
    let (w, h) = (axes.width as usize, axes.height as usize);
    let mut top_z = vec![f64::NEG_INFINITY; w * h];
    for p in &kept {
        let (x, y) = (axes.px(p.x) - 0.5, axes.py(p.y) - 0.5);
        for (dx, dy) in [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0)] {
            if axes.contains(x + dx, y + dy) {
                let i = ((y + dy) as i64 - top) as usize * w + ((x + dx) as i64 - left) as usize;
                top_z[i] = top_z[i].max(p.z);
            }
        }
    }
    for (i, z) in top_z.iter().enumerate() {
        if z.is_finite() {
            let color = viridis((z - z_lo) / (z_hi - z_lo));
            canvas.put(left + (i % w) as i64, top + (i / w) as i64, color);
        }
    }
    let nodes_px: Vec<(f64, f64)> = nodes.iter().map(|p| (axes.px(p.x), axes.py(p.y))).collect();
    draw_graph(&mut canvas, &nodes_px, view.loop_closures);
    axes.draw_frame(&mut canvas, "x (m)", "y (m)", None, None);
    scale_bar(
        &mut canvas,
        left + 10,
        top + axes.height - 10,
        axes.x_scale(),
        120.0,
    );
    title(&mut canvas, &format!("Map, plan view: {title_text}"));
    subtitle(
        &mut canvas,
        &format!(
            "{} points, {} nodes, {} loop closures; points above z = {:.1} m left out",
            view.points_in_world.len(),
            nodes.len(),
            view.loop_closures.len(),
            cut
        ),
    );
    let bar_left = left + axes.width + 40;
    let bottom = legend(
        &mut canvas,
        bar_left - 10,
        top,
        &graph_legend(!view.loop_closures.is_empty()),
    );
    let bar_top = bottom + 50;
    let bar_h = (top + axes.height - bar_top - 10).max(80);
    color_bar(
        &mut canvas,
        bar_left,
        bar_top,
        26,
        bar_h,
        (z_lo, z_hi),
        viridis,
        "height z (m)",
    );
    canvas.image
}

/// A vertical cut through the map: the points within the slab of `section`, drawn by distance
/// along it (across) and height (up) at equal scale, darker where more points fall; the nodes
/// and trajectory projected onto the plane (numbered; loop closures dashed), axes in metres and
/// a scale bar.
///
/// # Arguments
/// * `view` — the points, node poses and loop closures.
/// * `section` — the plane and the slab's half thickness; see [`Section::through_trajectory`].
/// * `title` — a line above the picture.
///
/// # Returns
/// An RGB image at most about 1400 × 900 pixels.
pub fn map_section(view: &MapView, section: &Section, title_text: &str) -> RgbImage {
    let half = section.half_thickness_m.abs().max(1e-3);
    let in_slab: Vec<(f64, f64)> = view
        .points_in_world
        .iter()
        .filter(|p| p.iter().all(|v| v.is_finite()))
        .filter_map(|p| {
            let (along, off) = section.project(p);
            (off.abs() <= half).then_some((along, p.z))
        })
        .collect();
    let nodes = view.node_positions();
    let nodes_2d: Vec<(f64, f64)> = nodes.iter().map(|p| (section.project(p).0, p.z)).collect();
    let s_values: Vec<f64> = in_slab.iter().map(|p| p.0).collect();
    let z_values: Vec<f64> = in_slab.iter().map(|p| p.1).collect();
    let node_s: Vec<f64> = nodes_2d.iter().map(|p| p.0).collect();
    let node_z: Vec<f64> = nodes_2d.iter().map(|p| p.1).collect();
    let x_range = robust_bounds(&s_values, &node_s);
    let y_range = robust_bounds(&z_values, &node_z);
    let (left, top) = (120, 90);
    let axes = Axes::equal(left, top, 1150, 650, x_range, y_range);
    let mut canvas = Canvas::new(
        (left + axes.width.max(700) + 290) as u32,
        (top + axes.height + 100) as u32,
    );
    axes.draw_grid(&mut canvas, None, None);
    let (w, h) = (axes.width as usize, axes.height as usize);
    let mut counts = vec![0u32; w * h];
    // Each point covers 2 × 2 pixels so thin walls stay visible.
    for &(s, z) in &in_slab {
        let (x, y) = (axes.px(s) - 0.5, axes.py(z) - 0.5);
        for (dx, dy) in [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0)] {
            if axes.contains(x + dx, y + dy) {
                counts[((y + dy) as i64 - top) as usize * w + ((x + dx) as i64 - left) as usize] +=
                    1;
            }
        }
    }
    let mut nonzero: Vec<f64> = counts
        .iter()
        .filter(|&&c| c > 0)
        .map(|&c| c as f64)
        .collect();
    let dense = quantile(&mut nonzero, 0.9).unwrap_or(1.0).max(1.0);
    for (i, &c) in counts.iter().enumerate() {
        if c > 0 {
            // Few points: slate blue; many: near black.
            let t = ((c as f64).ln() / dense.ln().max(1e-9)).clamp(0.0, 1.0);
            let v = |a: f64, b: f64| (a * (1.0 - t) + b * t).round() as u8;
            let color = Rgb([v(60.0, 10.0), v(85.0, 20.0), v(150.0, 60.0)]);
            canvas.put(left + (i % w) as i64, top + (i / w) as i64, color);
        }
    }
    let nodes_px: Vec<(f64, f64)> = nodes_2d
        .iter()
        .map(|&(s, z)| (axes.px(s), axes.py(z)))
        .collect();
    draw_graph(&mut canvas, &nodes_px, view.loop_closures);
    let (sin, cos) = section.direction_rad.sin_cos();
    axes.draw_frame(
        &mut canvas,
        &format!("distance along the cut (m), direction ({cos:.2}, {sin:.2})"),
        "height z (m)",
        None,
        None,
    );
    scale_bar(
        &mut canvas,
        left + 10,
        top + axes.height - 10,
        axes.x_scale(),
        120.0,
    );
    title(&mut canvas, &format!("Map, vertical section: {title_text}"));
    subtitle(
        &mut canvas,
        &format!(
            "{} points within ±{:.2} m of the plane through ({:.2}, {:.2}) m; nodes projected onto it",
            in_slab.len(),
            half,
            section.origin[0],
            section.origin[1]
        ),
    );
    let mut entries = graph_legend(!view.loop_closures.is_empty());
    entries.insert(0, (Swatch::Fill(Rgb([40, 55, 100])), "map points"));
    legend(&mut canvas, left + axes.width + 30, top, &entries);
    canvas.image
}
