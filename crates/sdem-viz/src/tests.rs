//! Pictures are well formed and not blank; the page is offline and holds the points.

use super::draw::{UNKNOWN, WHITE};
use super::*;
use sdem::cost::CostConfig;
use sdem::geometry::{Attitude, Pose, Vec3};
use sdem::sdem::{Sdem, SdemConfig};
use std::collections::HashSet;

/// The room of [`room_scan`]: the distance from `origin` along the unit vector `d` to its
/// nearest wall, floor or ceiling.
fn room_range(origin: &Vec3, d: &Vec3) -> f64 {
    let (lo, hi) = (Vec3::new(-3.0, -2.0, 0.0), Vec3::new(3.0, 2.0, 2.5));
    let mut t = f64::INFINITY;
    for k in 0..3 {
        if d[k].abs() > 1e-9 {
            let bound = if d[k] > 0.0 { hi[k] } else { lo[k] };
            t = t.min((bound - origin[k]) / d[k]);
        }
    }
    t
}

/// The unit vector at azimuth `az_deg`, elevation `el_deg`.
fn unit_at(az_deg: f64, el_deg: f64) -> Vec3 {
    let (a, e) = (az_deg.to_radians(), el_deg.to_radians());
    Vec3::new(e.cos() * a.cos(), e.cos() * a.sin(), e.sin())
}

/// A 6 × 4 × 2.5 m room (floor at z = 0) seen from `origin`: the nearest wall in every direction
/// on a 1° lattice between −60° and 60° of elevation (at azimuth `az + 0.3°` and elevation
/// `el + 0.4°`, one point per S-DEM cell), and a window (no return) at azimuth 40…60°,
/// elevation above 10°. Points relative to `origin`.
fn room_scan(origin: &Vec3) -> Vec<Vec3> {
    let mut points = Vec::new();
    for el in -60..60 {
        for az in -180..180 {
            if (40..60).contains(&az) && el > 10 {
                continue;
            }
            let d = unit_at(az as f64 + 0.3, el as f64 + 0.4);
            points.push(d * room_range(origin, &d));
        }
    }
    points
}

fn room_sdem(origin: &Vec3) -> Sdem {
    Sdem::from_points(
        &room_scan(origin),
        &Attitude::default(),
        &SdemConfig::default(),
    )
    .unwrap()
}

/// Distinct colours in the image and whether the rectangle `[x0, x1) × [y0, y1)` holds more
/// than one.
fn check_picture(name: &str, image: &RgbImage, min_colors: usize, region: (u32, u32, u32, u32)) {
    assert!(image.width() > 300 && image.height() > 300);
    let colors: HashSet<[u8; 3]> = image.pixels().map(|p| p.0).collect();
    let png = encode_png(image).unwrap();
    if let Some(dir) = std::env::var_os("SDEM_VIZ_OUT") {
        let _ = std::fs::create_dir_all(&dir);
        let name = format!("{name}.png");
        std::fs::write(std::path::Path::new(&dir).join(name), &png).unwrap();
    }
    assert!(colors.len() >= min_colors, "only {} colours", colors.len());
    let (x0, y0, x1, y1) = region;
    let mut region_colors = HashSet::new();
    for y in y0..y1 {
        for x in x0..x1 {
            region_colors.insert(image.get_pixel(x, y).0);
        }
    }
    assert!(region_colors.len() > 5, "the data region is uniform");
    let non_white = image.pixels().filter(|p| **p != WHITE).count();
    assert!(
        non_white * 40 > (image.width() * image.height()) as usize,
        "mostly blank"
    );
    let decoded = image::load_from_memory(&png).unwrap().to_rgb8();
    assert_eq!(&decoded, image);
}

#[test]
fn panorama_shows_ranges_and_unknown() {
    let sdem = room_sdem(&Vec3::new(0.5, 0.3, 1.0));
    let image = sdem_panorama(&sdem, "a test room");
    check_picture("panorama", &image, 50, (110, 80, 1190, 620));
    // The elevation band above 60° holds no return: grey hatch (near the top of the data).
    let p = image.get_pixel(600, 90).0;
    assert!(p == UNKNOWN.0 || p == super::draw::UNKNOWN_HATCH.0, "{p:?}");
}

/// The most common colour within `r0..r1` pixels of `(cx, cy)`.
fn common_colour(image: &RgbImage, (cx, cy): (f64, f64), r0: f64, r1: f64) -> [u8; 3] {
    let mut counts = std::collections::HashMap::new();
    for y in (cy - r1) as u32..=(cy + r1) as u32 {
        for x in (cx - r1) as u32..=(cx + r1) as u32 {
            let r = (x as f64 + 0.5 - cx).hypot(y as f64 + 0.5 - cy);
            if (r0..r1).contains(&r) {
                *counts.entry(image.get_pixel(x, y).0).or_insert(0) += 1;
            }
        }
    }
    counts.into_iter().max_by_key(|&(_, n)| n).unwrap().0
}

/// The polar slice paints free space from the sensor out to each known direction's boundary
/// point, and nothing where the direction is unknown. Along rays at the middle of azimuth
/// cells (away from the spokes every 30° and the ring labels at −75°), the free colour runs
/// from the sensor to a distance that is the room's horizontal distance in that cell times
/// one scale for the picture, within 2 pixels (the boundary dot, 2.2 px, covers its end).
#[test]
fn polar_slice_fills_free_space() {
    let origin = Vec3::new(0.5, 0.3, 1.0);
    let sdem = room_sdem(&origin);
    // The plot is 760 px square at (120, 90): the sensor at its centre.
    let centre = (500.0, 470.0);
    let pixel_at = |image: &RgbImage, az_deg: f64, rho: f64| {
        let a = az_deg.to_radians();
        image
            .get_pixel(
                (centre.0 + rho * a.cos()).floor() as u32,
                (centre.1 - rho * a.sin()).floor() as u32,
            )
            .0
    };
    for elevation in [-30.0, -10.0, 20.0, 85.0] {
        let image = sdem_polar_slice(&sdem, elevation, "a test room");
        check_picture(
            &format!("slice{elevation}"),
            &image,
            20,
            (120, 90, 880, 850),
        );
        assert_eq!(image.get_pixel(500, 470), &WHITE, "the sensor's dot");
        let free = common_colour(&image, centre, 12.0, 40.0);
        let hatch = [UNKNOWN.0, super::draw::UNKNOWN_HATCH.0];
        if elevation == 85.0 {
            // The scan stops at 60° of elevation: nothing known, nothing free.
            assert!(hatch.contains(&free), "{free:?} at 85°");
            continue;
        }
        assert!(free != WHITE.0 && !hatch.contains(&free), "{free:?}");
        let band = elevation.floor();
        let mut runs = Vec::new();
        for cell in [-165, -140, -115, -100, -50, -20, 10, 70, 100, 125, 160] {
            let az = cell as f64;
            // The cell's one point, and its horizontal distance as the slice takes it.
            let d = unit_at(az + 0.3, band + 0.4);
            let h = room_range(&origin, &d) * (band + 0.5).to_radians().cos();
            let samples: Vec<(f64, bool)> = (24..760)
                .map(|k| {
                    let rho = k as f64 * 0.5;
                    (rho, pixel_at(&image, az + 0.5, rho) == free)
                })
                .collect();
            let last = samples.iter().rev().find(|s| s.1).expect("no free pixel").0;
            let inside = samples.iter().filter(|s| s.0 <= last).count();
            let filled = samples.iter().filter(|s| s.0 <= last && s.1).count();
            // Rings and spokes cross the free space: a few pixels.
            assert!(
                filled * 10 >= inside * 9,
                "{elevation}°, azimuth {az}: {filled} of {inside} free"
            );
            runs.push((h, last));
        }
        if elevation == -30.0 {
            // The floor, 1 m below, is nearer than the walls but towards +y (`h` 1.763 m):
            // those rays end together.
            let floor: Vec<f64> = (runs.iter())
                .filter(|r| (r.0 - runs[0].0).abs() < 1e-6)
                .map(|r| r.1)
                .collect();
            let spread = floor
                .iter()
                .fold(0.0f64, |m, l| m.max((l - floor[0]).abs()));
            assert!(floor.len() >= 8 && spread <= 2.0, "{runs:?}");
        } else {
            // The walls set the distances: one scale and offset for all rays (least squares),
            // and every ray on it.
            let n = runs.len() as f64;
            let (mh, ml) = (
                runs.iter().map(|r| r.0).sum::<f64>() / n,
                runs.iter().map(|r| r.1).sum::<f64>() / n,
            );
            let scale = runs.iter().map(|r| (r.0 - mh) * (r.1 - ml)).sum::<f64>()
                / runs.iter().map(|r| (r.0 - mh).powi(2)).sum::<f64>();
            let offset = ml - scale * mh;
            assert!(
                scale > 50.0 && (-6.0..=1.0).contains(&offset),
                "{elevation}°: {scale} px/m, {offset} px: {runs:?}"
            );
            for (h, last) in &runs {
                assert!(
                    (last - (scale * h + offset)).abs() <= 2.0,
                    "{elevation}°: free to {last} px where the wall is {h} m: {runs:?}"
                );
            }
        }
        // The window (azimuth 40–60°, above 10°) is unknown: nothing free there.
        if elevation > 10.0 {
            for az in [43.5, 50.5, 56.5] {
                assert!(
                    (24..760).all(|k| pixel_at(&image, az, k as f64 * 0.5) != free),
                    "free space painted through the window at {az}°"
                );
            }
        }
    }
}

#[test]
fn map_pictures_draw_points_and_graph() {
    let origins = [
        Vec3::new(-1.5, -0.5, 0.4),
        Vec3::new(0.0, 0.0, 0.4),
        Vec3::new(1.5, 0.6, 0.4),
    ];
    let mut points = Vec::new();
    for o in &origins {
        points.extend(room_scan(o).into_iter().map(|p| p + o));
    }
    let poses: Vec<Pose> = origins
        .iter()
        .map(|o| Pose::translation(o.x, o.y, o.z))
        .collect();
    let view = MapView {
        points_in_world: &points,
        world_from_node: &poses,
        loop_closures: &[(0, 2)],
    };
    let plan = map_plan(&view, "test room");
    check_picture("plan", &plan, 30, (130, 100, 600, 500));
    // The graph: the trajectory's and the loop closure's colours in the plot, left of the
    // legend; with no loop closure, none of the latter.
    let in_plot = |image: &RgbImage, colour: image::Rgb<u8>| {
        (0..image.height())
            .flat_map(|y| (0..1080.min(image.width())).map(move |x| (x, y)))
            .filter(|&(x, y)| *image.get_pixel(x, y) == colour)
            .count()
    };
    let (trajectory, closure) = (
        in_plot(&plan, super::draw::TRAJECTORY),
        in_plot(&plan, super::draw::LOOP),
    );
    println!("plan: {trajectory} trajectory pixels, {closure} loop-closure pixels");
    assert!(trajectory > 200 && closure > 100, "{trajectory}, {closure}");
    let no_loop = map_plan(
        &MapView {
            loop_closures: &[],
            ..view
        },
        "test room",
    );
    assert_eq!(in_plot(&no_loop, super::draw::LOOP), 0);
    let section = map_section(&view, &Section::through_trajectory(&view, 0.1), "test room");
    check_picture("section", &section, 10, (130, 100, 600, 400));
    let xz = map_section(&view, &Section::xz_through_start(&view, 0.05), "x-z");
    check_picture("section_xz", &xz, 10, (130, 100, 600, 400));
}

#[test]
fn map_pictures_survive_empty_input() {
    let view = MapView {
        points_in_world: &[],
        world_from_node: &[],
        loop_closures: &[(0, 5)],
    };
    assert!(map_plan(&view, "empty").width() > 100);
    assert!(map_section(&view, &Section::through_trajectory(&view, 0.1), "empty").width() > 100);
    assert!(viewer_html(&view, "empty").contains("<canvas"));
}

#[test]
fn cost_slice_has_its_minimum_at_the_truth() {
    let reference = room_sdem(&Vec3::new(0.0, 0.0, 1.0));
    let truth = Vec3::new(0.3, -0.2, 0.0);
    let query = room_sdem(&(Vec3::new(0.0, 0.0, 1.0) + truth));
    let slice = sample_cost_slice(
        &reference,
        &query,
        &CostConfig::default(),
        &truth,
        0.0,
        0.3,
        0.02,
    )
    .unwrap();
    assert_eq!(slice.x_m.len(), 31);
    assert_eq!(slice.costs.len(), 31 * 31);
    let (_, at) = slice.minimum().unwrap();
    assert!(
        (at[0] - truth.x).abs() < 0.03 && (at[1] - truth.y).abs() < 0.03,
        "{at:?}"
    );
    let image = cost_surface(&slice, "test room");
    check_picture("cost", &image, 50, (140, 100, 800, 760));
    assert!(sample_cost_slice(
        &reference,
        &query,
        &CostConfig::default(),
        &truth,
        0.0,
        0.3,
        0.0
    )
    .is_err());
    assert!(sample_cost_slice(
        &reference,
        &query,
        &CostConfig::default(),
        &truth,
        0.0,
        10.0,
        0.001
    )
    .is_err());
}

#[test]
fn viewer_page_is_offline_and_embeds_the_points() {
    let points: Vec<Vec3> = (0..1000)
        .map(|i| Vec3::new(i as f64 * 0.01, 0.0, 0.5))
        .collect();
    let poses = vec![Pose::identity(), Pose::translation(1.0, 0.0, 0.0)];
    let view = MapView {
        points_in_world: &points,
        world_from_node: &poses,
        loop_closures: &[(0, 1)],
    };
    let page = viewer_html(&view, "a <line> & more");
    assert!(page.starts_with("<!DOCTYPE html>"));
    for fetch in [
        "http://",
        "https://",
        "src=",
        "import ",
        "fetch(",
        "XMLHttpRequest",
        "<link",
    ] {
        assert!(!page.contains(fetch), "the page holds {fetch:?}");
    }
    assert!(page.contains("a &lt;line&gt; &amp; more"));
    assert!(page.contains("\"shownCount\":1000"));
    // The points are there: 1000 × 3 × 4 bytes of base64.
    let longest = page.split('"').map(str::len).max().unwrap();
    assert!(longest >= 1000 * 12 * 4 / 3, "{longest}");
    // Thinned to at most VIEWER_MAX_POINTS.
    let many: Vec<Vec3> = (0..VIEWER_MAX_POINTS + 10)
        .map(|i| Vec3::new(i as f64, 0.0, 0.0))
        .collect();
    let big = viewer_html(
        &MapView {
            points_in_world: &many,
            world_from_node: &[],
            loop_closures: &[],
        },
        "many",
    );
    assert!(big.contains(&format!(
        "\"shownCount\":{}",
        (VIEWER_MAX_POINTS + 10).div_ceil(2)
    )));
}

#[test]
fn base64_matches_the_rfc_vectors() {
    use super::html::base64;
    for (input, output) in [
        ("", ""),
        ("f", "Zg=="),
        ("fo", "Zm8="),
        ("foo", "Zm9v"),
        ("foob", "Zm9vYg=="),
        ("fooba", "Zm9vYmE="),
        ("foobar", "Zm9vYmFy"),
    ] {
        assert_eq!(base64(input.as_bytes()), output);
    }
}
