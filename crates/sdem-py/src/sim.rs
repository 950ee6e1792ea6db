//! `sdem.sim`: seeded scans with their truth from sdem-sim, to try sdem and to test it without
//! data files: the benchmark's scan pairs, and stop-and-go runs with odometry.

use crate::arrays::{matrices4, matrix4, points_array};
use crate::errors::sdem_error;
use numpy::ndarray::Array2;
use numpy::IntoPyArray;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use sdem::{Attitude, Pose, SensorConfig};
use sdem_sim::benchmark::{bench_pairs, localize_config, BenchPair, PairConfig};
use sdem_sim::odometry::{simulate_odometry, OdometryNoise};
use sdem_sim::sim;

/// Seeded scan pairs in the simulated collapsed building, with the truth: what ``sdem bench``
/// measures (``sdem_sim::benchmark::bench_pairs``). Each pair: a reference stop drawn on the
/// building's route, and a query sensor pose around it (anywhere within
/// ``displacement_half_m``, turned by up to ``yaw_spread_deg``, tilted by up to
/// ``tilt_max_deg``), both scanned by the tilting laser range finder (5 mm range noise); the
/// query's compass reading is off by up to ``compass_error_max_deg``. A seed gives the same
/// pairs on every machine.
///
/// Args:
///     seed: seeds the building, its route and every pair.
///     count: the number of pairs.
///
/// Returns:
///     list[dict]: per pair, ``reference_points`` and ``query_points`` (``(N, 3)`` float64,
///     each in its sensor frame, metres), ``reference_attitude_deg`` and
///     ``query_attitude_deg`` (the gyro/compass readings, ``(roll, pitch, yaw)`` degrees),
///     ``reference_from_query`` (the truth, ``(4, 4)``), ``window`` (the search window that
///     holds every query of these pairs, for ``sdem.localize(..., window=...)``), and, in the
///     frame of ``sim.run(seed, ...)`` (whose route the reference stands on, at stop
///     ``reference_stop``), the true ``world_from_reference`` and ``world_from_query``.
///
/// Raises:
///     sdem.InvalidError: a negative or non-finite spread.
#[pyfunction]
#[pyo3(
    signature = (seed, count, *, displacement_half_m=(0.5, 0.5, 0.1), yaw_spread_deg=15.0, tilt_max_deg=3.0, compass_error_max_deg=10.0),
    text_signature = "(seed, count, *, displacement_half_m=(0.5, 0.5, 0.1), yaw_spread_deg=15.0, tilt_max_deg=3.0, compass_error_max_deg=10.0)"
)]
fn pairs<'py>(
    py: Python<'py>,
    seed: i64,
    count: i64,
    displacement_half_m: (f64, f64, f64),
    yaw_spread_deg: f64,
    tilt_max_deg: f64,
    compass_error_max_deg: f64,
) -> PyResult<Bound<'py, PyList>> {
    let seed = crate::arrays::non_negative(seed, "seed")?;
    let count = crate::arrays::non_negative(count, "count")? as usize;
    let (x, y, z) = displacement_half_m;
    let config = PairConfig {
        displacement_half_m: [x, y, z],
        yaw_spread_deg,
        tilt_max_deg,
        compass_error_max_deg,
        ..PairConfig::default()
    };
    let made = py
        .detach(|| bench_pairs(seed, count, &config))
        .map_err(sdem_error)?;
    let window = localize_config(&config).window;
    let list = PyList::empty(py);
    for pair in &made {
        let dict = pair_dict(py, pair)?;
        dict.set_item("window", crate::options::to_python(py, &window)?)?;
        list.append(dict)?;
    }
    Ok(list)
}

/// One pair as a dict.
fn pair_dict<'py>(py: Python<'py>, pair: &BenchPair) -> PyResult<Bound<'py, PyDict>> {
    let dict = PyDict::new(py);
    let xyz = |p: &sdem::geometry::Vec3| [p.x, p.y, p.z];
    dict.set_item(
        "reference_points",
        points_array(py, &pair.reference_points, xyz),
    )?;
    dict.set_item("reference_attitude_deg", degrees(&pair.reference_attitude))?;
    dict.set_item("query_points", points_array(py, &pair.query_points, xyz))?;
    dict.set_item("query_attitude_deg", degrees(&pair.query_attitude))?;
    dict.set_item("reference_from_query", matrix4(py, &pair.truth))?;
    dict.set_item("reference_stop", pair.reference_stop)?;
    dict.set_item(
        "world_from_reference",
        matrix4(py, &pair.world_from_reference),
    )?;
    dict.set_item("world_from_query", matrix4(py, &pair.world_from_query))?;
    Ok(dict)
}

/// An attitude reading as a `(roll, pitch, yaw)` tuple in degrees.
fn degrees(attitude: &Attitude) -> (f64, f64, f64) {
    let [r, p, y] = attitude.to_degrees();
    (r, p, y)
}

/// A seeded stop-and-go run through the simulated collapsed building, with the truth and
/// simulated odometry: what ``sdem simulate`` writes as a dataset folder.
///
/// Args:
///     seed: seeds the building, the route, the sweeps and the odometry.
///     stops: the number of stops (1 to 40), about 35 cm apart along the route.
///
/// Returns:
///     dict: ``points`` (a list of ``(N, 3)`` float64 arrays, each in its sensor frame,
///     metres), ``attitude_deg`` (``(n, 3)``: each stop's gyro/compass reading, degrees),
///     ``world_from_sensor`` (``(n, 4, 4)``: the truth), and ``odom_from_sensor`` (``(n, 4,
///     4)``: dead reckoning, 5 % of each step and 0.5° of heading a step off, for
///     ``Slam.add(..., odometry=...)``).
///
/// Raises:
///     sdem.InvalidError: a number of stops the route cannot hold.
#[pyfunction]
fn run<'py>(py: Python<'py>, seed: i64, stops: i64) -> PyResult<Bound<'py, PyDict>> {
    let seed = crate::arrays::non_negative(seed, "seed")?;
    let stops = crate::arrays::non_negative(stops, "stops")? as usize;
    let sensor = SensorConfig::default();
    let simulated = py
        .detach(|| -> sdem::Result<_> {
            let scene = sim::collapsed_building(seed);
            let route = sim::collapsed_building_stops(&scene, seed, stops, &sensor.lift)?;
            let run = sim::simulate_run(&scene, &route, &sensor, seed)?;
            let truth: Vec<Pose> = run.iter().map(|s| s.world_from_sensor).collect();
            let odometry = simulate_odometry(&truth, &OdometryNoise::default(), seed)?;
            let scans: Vec<_> = run.iter().map(|s| s.sweep.points_in_sensor()).collect();
            let readings: Vec<Attitude> = run.iter().map(|s| s.sweep.mean_attitude()).collect();
            Ok((scans, readings, truth, odometry))
        })
        .map_err(sdem_error)?;
    let (scans, readings, truth, odometry) = simulated;
    let dict = PyDict::new(py);
    let points = PyList::empty(py);
    for scan in &scans {
        points.append(points_array(py, scan, |p| [p.x, p.y, p.z]))?;
    }
    dict.set_item("points", points)?;
    let attitude = Array2::from_shape_fn((readings.len(), 3), |(k, i)| readings[k].to_degrees()[i]);
    dict.set_item("attitude_deg", attitude.into_pyarray(py))?;
    dict.set_item("world_from_sensor", matrices4(py, &truth))?;
    dict.set_item("odom_from_sensor", matrices4(py, &odometry))?;
    Ok(dict)
}

/// The `sim` submodule.
pub fn module<'py>(py: Python<'py>) -> PyResult<Bound<'py, PyModule>> {
    let module = PyModule::new(py, "sim")?;
    module.add(
        "__doc__",
        "Seeded scans with their truth from sdem's simulator: the benchmark's scan pairs \
         (pairs) and stop-and-go runs with odometry (run).",
    )?;
    module.add_function(wrap_pyfunction!(pairs, &module)?)?;
    module.add_function(wrap_pyfunction!(run, &module)?)?;
    Ok(module)
}
