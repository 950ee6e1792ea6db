//! Probe: a saved map (MAP dir) and a scan (SCAN); node NODE's merged reference against the scan
//! levelled by the node's own attitude, window ±W around the node, heading ±H.
use sdem::localize::{localize, LocalizeOptions, SearchWindow};
use sdem::sdem::Sdem;
use sdem::search::HeadingWindow;

fn env<T: std::str::FromStr>(k: &str, d: T) -> T {
    std::env::var(k)
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(d)
}

fn main() {
    let map_dir = std::env::var("MAP").unwrap();
    let scan = std::env::var("SCAN").unwrap();
    let node: usize = env("NODE", 3);
    let w: f64 = env("W", 0.5);
    let h: f64 = env("H", 3.0);
    let saved = sdem_io::load_map(std::path::Path::new(&map_dir)).unwrap();
    let points = sdem_io::read_points(std::path::Path::new(&scan)).unwrap();
    let config = &saved.config;
    let n = &saved.map.nodes[node];
    let origin = n.position();
    let att = sdem::geometry::attitude_of(&n.world_from_sensor);
    println!(
        "node {node} at {:?} attitude {:?}, {} points in scan",
        origin,
        att,
        points.len()
    );
    let reference = saved
        .map
        .merged_reference(&[node], &origin, &config.sdem)
        .unwrap();
    {
        use nalgebra::Point3;
        let pts: Vec<Point3<f64>> = n
            .points_in_world()
            .into_iter()
            .map(|p| Point3::from(p - origin))
            .collect();
        let level = sdem::geometry::Attitude::default().with_sigma_deg(0.05, 0.05);
        let r = sdem::scan::Scan::with_grid(
            &pts,
            if env("NOLEV", 0) == 1 {
                None
            } else {
                Some(level)
            },
            &config.sdem,
        )
        .unwrap();
        let qp: Vec<Point3<f64>> = points.iter().map(|p| Point3::from(*p)).collect();
        let q = sdem::scan::Scan::with_grid(&qp, None, &config.sdem).unwrap();
        let mut o = LocalizeOptions {
            window: SearchWindow::around(&sdem::geometry::Vec3::zeros(), [w, w, 0.15]),
            refine: env("REF", 0) == 1,
            runner_up: true,
            ..config.localize.clone()
        };
        o.step_m = o.step_m.max(env("STEP", 0.1));
        o.cost.min_inlier_fraction = env("MINF", 0.2);
        o.cost.truncation_m = o.cost.truncation_m.max(env("TR", 0.1));
        match sdem::scan::localize(&r, &q, &o) {
            Ok(l) => println!("no attitude (scan::localize): rfq {} cost {:.3e} overlap {} inl {:.1}% doubts {:?}",
                l.reference_from_query, l.cost, l.overlap, l.diagnostics.inlier_fraction * 100.0,
                l.doubts.iter().map(|d| d.kind()).collect::<Vec<_>>()),
            Err(e) => println!("no attitude: {e}"),
        }
    }
    for (label, a) in [
        ("node attitude", att),
        (
            "level",
            sdem::geometry::Attitude::from_degrees(0.0, 0.0, att.yaw.to_degrees()),
        ),
    ] {
        let query = Sdem::from_usable_points(&points, &a, &config.sdem).unwrap();
        let o = LocalizeOptions {
            window: SearchWindow::around(&sdem::geometry::Vec3::zeros(), [w, w, 0.15]),
            heading: HeadingWindow {
                half_range_deg: h,
                step_deg: None,
            },
            ..config.localize.clone()
        };
        match localize(&reference, &query, &o) {
            Ok(l) => println!(
                "{label}: offset {:?} cost {:.3e} overlap {} inl {:.1}% doubts {:?}",
                l.offset,
                l.cost,
                l.overlap,
                l.diagnostics.inlier_fraction * 100.0,
                l.doubts.iter().map(|d| d.kind()).collect::<Vec<_>>()
            ),
            Err(e) => println!("{label}: {e}"),
        }
    }
}

#[allow(dead_code)]
fn unused() {}
