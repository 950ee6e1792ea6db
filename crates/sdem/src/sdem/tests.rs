//! Tests of the S-DEM: cell indexing and binning, the nearest return, levelling, pairs built together,
//! virtual S-DEMs and their occlusion, partial extents and bad configurations.

#[test]
fn wrap_column_is_rem_euclid() {
    for n in [1, 2, 7, 180, 360] {
        for a in -3 * n - 2..3 * n + 2 {
            assert_eq!(super::wrap_column(a, n), a.rem_euclid(n), "{a} mod {n}");
        }
    }
}

/// The clamped conversion agrees with the cell binning's floor wherever a cone's cells can
/// lie, and sends what cannot be a cell (NaN, ±∞, beyond ±10⁸) outside every grid.
#[test]
fn floor_clamped_is_the_binnings_floor_within_its_range() {
    use super::floor_i32;
    let mut values = vec![
        0.0f32,
        -0.0,
        0.5,
        -0.5,
        1.0,
        -1.0,
        359.999,
        -1e-7,
        1e-7,
        99_999_999.0,
    ];
    values.extend((-20_000..20_000).map(|i| i as f32 * 0.137));
    values.extend((-200..200).map(|i| i as f32));
    for x in values {
        assert_eq!(super::floor_clamped(x), floor_i32(x), "{x}");
    }
    for x in [f32::NAN, f32::NEG_INFINITY, -1e12] {
        assert_eq!(super::floor_clamped(x), -100_000_000, "{x}");
    }
    for x in [f32::INFINITY, 1e12] {
        assert_eq!(super::floor_clamped(x), 100_000_000, "{x}");
    }
}

#[test]
fn batch_binning_equals_cell_of() {
    use rand::{Rng, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
    for config in [
        super::SdemConfig::default(),
        // A full circle whose last column is narrower than the others.
        super::SdemConfig {
            resolution_deg: 0.7,
            ..Default::default()
        },
        super::SdemConfig {
            resolution_deg: 0.7,
            azimuth_min_deg: -90.0,
            azimuth_max_deg: 90.0,
            elevation_min_deg: -45.0,
            elevation_max_deg: 40.0,
            ..Default::default()
        },
    ] {
        let spec = super::GridSpec::new(&config).unwrap();
        let n = 10_000;
        let mut pts: Vec<[f32; 3]> = (0..n)
            .map(|_| {
                [
                    rng.random_range(-8.0f32..8.0),
                    rng.random_range(-8.0f32..8.0),
                    rng.random_range(-8.0f32..8.0),
                ]
            })
            .collect();
        // Poles, axes, the origin and non-finite values.
        pts.extend([
            [0.0, 0.0, 1.0],
            [0.0, 0.0, -1.0],
            [0.0, 0.0, 0.0],
            [-1.0, 0.0, 0.0],
            [-1.0, -0.0, 0.0],
            [f32::NAN, 1.0, 1.0],
            [f32::INFINITY, 0.0, 0.0],
        ]);
        let xs: Vec<f32> = pts.iter().map(|p| p[0]).collect();
        let ys: Vec<f32> = pts.iter().map(|p| p[1]).collect();
        let zs: Vec<f32> = pts.iter().map(|p| p[2]).collect();
        // The build chosen at run time (AVX2 where the processor has it) and the baseline one.
        for baseline in [false, true] {
            let mut cells = vec![0; pts.len()];
            let mut ranges = vec![0.0; pts.len()];
            if baseline {
                spec.cells_of_any(&xs, &ys, &zs, &mut cells, &mut ranges);
            } else {
                spec.cells_of(&xs, &ys, &zs, &mut cells, &mut ranges);
            }
            for (i, p) in pts.iter().enumerate() {
                match spec.cell_of(*p) {
                    Some((c, r)) => assert_eq!(
                        (cells[i], ranges[i].to_bits()),
                        (c, r.to_bits()),
                        "{p:?}, baseline build {baseline}"
                    ),
                    None => assert_eq!(cells[i], u32::MAX, "{p:?}, baseline build {baseline}"),
                }
            }
        }
    }
}

use super::*;
use crate::geometry::{direction, Attitude};

fn sphere_points(radius: f64, step_deg: f64) -> Vec<Vec3> {
    let mut pts = Vec::new();
    let mut el = -89.5;
    while el < 90.0 {
        let mut az = -179.5;
        while az < 180.0 {
            pts.push(direction(f64::to_radians(az), f64::to_radians(el)) * radius);
            az += step_deg;
        }
        el += step_deg;
    }
    pts
}

#[test]
fn nearest_return_wins_and_unknown_is_nan() {
    let pts = vec![Vec3::new(3.0, 0.01, 0.01), Vec3::new(1.5, 0.005, 0.005)];
    let s = Sdem::from_points(&pts, &Attitude::default(), &SdemConfig::default()).unwrap();
    assert_eq!(s.known_cells(), 1);
    let c = s.cells()[0] as usize;
    assert!((s.range(c).unwrap() as f64 - pts[1].norm()).abs() < 1e-6);
    let unknown = s.ranges().iter().filter(|r| r.is_nan()).count();
    assert_eq!(unknown, s.grid().len() - 1);
    assert!(s.ranges().iter().all(|r| r.is_nan() || *r > 0.0));
}

#[test]
fn grid_covers_the_whole_sphere() {
    let s = Sdem::from_points(
        &sphere_points(2.0, 1.0),
        &Attitude::default(),
        &SdemConfig::default(),
    )
    .unwrap();
    assert_eq!(s.grid().len(), 360 * 180);
    assert_eq!(s.known_cells(), 360 * 180);
}

#[test]
fn levelling_uses_the_attitude() {
    // A point straight ahead of a sensor pitched 10° nose-down lies 10° below the horizon.
    let pts = vec![Vec3::new(2.0, 0.0, 0.0)];
    let pitch_down = Attitude::from_degrees(0.0, 10.0, 0.0);
    let s = Sdem::from_points(&pts, &pitch_down, &SdemConfig::default()).unwrap();
    let (_, el) = s.grid().cell_center(s.cells()[0] as usize);
    assert!(
        (el.to_degrees() + 9.5).abs() < 1e-4,
        "elevation {}",
        el.to_degrees()
    );
}

#[test]
fn a_pair_is_built_as_each_alone() {
    let a = sphere_points(2.0, 1.0);
    let b: Vec<Vec3> = sphere_points(3.0, 0.9)
        .into_iter()
        .map(|p| p * 0.5)
        .collect();
    let (ra, rb) = (
        Attitude::from_degrees(2.0, -4.0, 30.0),
        Attitude::from_degrees(-1.0, 3.0, -75.0),
    );
    let config = SdemConfig::default();
    let (sa, sb) = Sdem::pair_from_points((&a, &ra), (&b, &rb), &config).unwrap();
    assert_eq!(sa, Sdem::from_points(&a, &ra, &config).unwrap());
    assert_eq!(sb, Sdem::from_points(&b, &rb, &config).unwrap());
    assert_ne!(sa, sb);
    let bad = SdemConfig {
        resolution_deg: -1.0,
        ..config
    };
    assert!(Sdem::pair_from_points((&a, &ra), (&b, &rb), &bad).is_err());
}

#[test]
fn virtual_sdem_at_own_origin_is_identical() {
    let pts: Vec<Vec3> = sphere_points(2.0, 0.7)
        .into_iter()
        .enumerate()
        .map(|(i, p)| p * (1.0 + 0.3 * ((i as f64) * 0.37).sin()))
        .collect();
    let s = Sdem::from_points(
        &pts,
        &Attitude::from_degrees(3.0, -2.0, 40.0),
        &SdemConfig::default(),
    )
    .unwrap();
    let v = s.virtual_at(&Vec3::zeros());
    assert_eq!(v.cells(), s.cells());
    assert_eq!(v.points(), s.points());
    let same = s
        .ranges()
        .iter()
        .zip(v.ranges())
        .all(|(a, b)| a.to_bits() == b.to_bits());
    assert!(same);
}

#[test]
fn virtual_sdem_occludes() {
    // A near point and a far point along the same ray from the new origin: the near one wins.
    let pts = vec![Vec3::new(1.0, 1.0, 0.0), Vec3::new(1.0, 2.0, 0.0)];
    let s = Sdem::from_points(&pts, &Attitude::default(), &SdemConfig::default()).unwrap();
    let v = s.virtual_at(&Vec3::new(1.0, 0.0, 0.0));
    assert_eq!(v.known_cells(), 1);
    assert!((v.range(v.cells()[0] as usize).unwrap() - 1.0).abs() < 1e-6);
}

#[test]
fn partial_extent_and_bad_configs() {
    let cfg = SdemConfig {
        azimuth_min_deg: -90.0,
        azimuth_max_deg: 90.0,
        elevation_min_deg: -45.0,
        elevation_max_deg: 45.0,
        resolution_deg: 2.0,
        ..Default::default()
    };
    let s = Sdem::from_points(&sphere_points(1.0, 1.0), &Attitude::default(), &cfg).unwrap();
    assert_eq!(s.grid().len(), 90 * 45);
    assert_eq!(s.known_cells(), 90 * 45);
    for bad in [
        SdemConfig {
            resolution_deg: 0.0,
            ..Default::default()
        },
        SdemConfig {
            azimuth_min_deg: 10.0,
            azimuth_max_deg: -10.0,
            ..Default::default()
        },
        SdemConfig {
            elevation_max_deg: f64::NAN,
            ..Default::default()
        },
    ] {
        assert!(GridSpec::new(&bad).is_err());
    }
}

/// A grid too fine to hold (a resolution of a thousandth of a degree asked for 65 billion cells
/// and aborted the process) is refused by name, with the finest resolution that fits; the
/// finest grid a scan's own step gives (a full sphere at 0.1°) and a band at 0.05° pass.
#[test]
fn grids_beyond_the_cell_limit_are_refused_with_the_finest_that_fits() {
    for resolution_deg in [0.001, 0.05] {
        let full = SdemConfig {
            resolution_deg,
            ..Default::default()
        };
        let e = full.validate().unwrap_err().to_string();
        assert!(
            e.contains(&format!("resolution {resolution_deg}°")) && e.contains("at least 0.1°"),
            "{e}"
        );
    }
    let finest_derived = SdemConfig {
        resolution_deg: 0.1,
        ..Default::default()
    };
    assert!(finest_derived.validate().is_ok());
    let band = SdemConfig {
        resolution_deg: 0.05,
        elevation_min_deg: -25.0,
        elevation_max_deg: 15.0,
        ..Default::default()
    };
    assert!(band.validate().is_ok());
    assert_eq!(
        (360.0 / 0.1 * 180.0 / 0.1f64).round() as usize,
        super::MAX_CELLS
    );
}

#[test]
fn the_cells_around_a_cell_wrap_on_a_full_circle_and_stop_at_a_partial_grids_edges() {
    use super::{GridSpec, SdemConfig};
    let full = GridSpec::new(&SdemConfig::default()).unwrap();
    let n = full.azimuth_cells();
    // Row 1, column 0: the column before is the last one; rows 0–2 all there.
    let around = full.cells_around(n);
    assert_eq!(
        around,
        [
            Some(n - 1),
            Some(0),
            Some(1),
            Some(2 * n - 1),
            Some(n),
            Some(n + 1),
            Some(3 * n - 1),
            Some(2 * n),
            Some(2 * n + 1),
        ]
    );
    // The first row has none below it.
    assert!(full.cells_around(5)[..3].iter().all(Option::is_none));
    let half = GridSpec::new(&SdemConfig {
        azimuth_min_deg: -90.0,
        azimuth_max_deg: 90.0,
        ..SdemConfig::default()
    })
    .unwrap();
    let m = half.azimuth_cells();
    let last_row_last_column = half.len() - 1;
    let around = half.cells_around(last_row_last_column);
    assert_eq!(
        around,
        [
            Some(last_row_last_column - m - 1),
            Some(last_row_last_column - m),
            None,
            Some(last_row_last_column - 1),
            Some(last_row_last_column),
            None,
            None,
            None,
            None,
        ]
    );
}
