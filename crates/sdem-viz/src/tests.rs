//! Pictures are well formed and not blank; the page is offline and holds the points.

use super::draw::{UNKNOWN, WHITE};
use super::*;
use sdem::cost::CostConfig;
use sdem::geometry::{Attitude, Pose, Vec3};
use sdem::sdem::{Sdem, SdemConfig};
use std::collections::HashSet;

/// A 6 × 4 × 2.5 m room (floor at z = 0) seen from `origin`: the nearest wall in every direction
/// on a 1° lattice between −60° and 60° of elevation, and a window (no return) at azimuth
/// 40…60°, elevation above 10°. Points relative to `origin`.
fn room_scan(origin: &Vec3) -> Vec<Vec3> {
    let (lo, hi) = (Vec3::new(-3.0, -2.0, 0.0), Vec3::new(3.0, 2.0, 2.5));
    let mut points = Vec::new();
    for el in -60..60 {
        for az in -180..180 {
            let (a, e) = (
                (az as f64 + 0.3).to_radians(),
                (el as f64 + 0.4).to_radians(),
            );
            if (40..60).contains(&az) && el > 10 {
                continue;
            }
            let d = Vec3::new(e.cos() * a.cos(), e.cos() * a.sin(), e.sin());
            let mut t = f64::INFINITY;
            for k in 0..3 {
                if d[k].abs() > 1e-9 {
                    let bound = if d[k] > 0.0 { hi[k] } else { lo[k] };
                    t = t.min((bound - origin[k]) / d[k]);
                }
            }
            points.push(d * t);
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

#[test]
fn polar_slice_fills_free_space() {
    let sdem = room_sdem(&Vec3::new(0.5, 0.3, 1.0));
    for elevation in [-30.0, 20.0, 85.0] {
        let image = sdem_polar_slice(&sdem, elevation, "a test room");
        check_picture(
            &format!("slice{elevation}"),
            &image,
            20,
            (120, 90, 880, 850),
        );
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
