//! `sdem bench --suite`'s flags: which suite, the flags each takes, and their checks, all made
//! before anything is read or run (a flag a suite does not take is a usage error).

use super::routes;
use anyhow::Result;
use std::path::PathBuf;

/// The suites.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Suite {
    /// Simulated pairs, no attitude: roll/pitch up to ±30°, any heading, steps up to 1 m.
    Unlevelled,
    /// The same pairs with attitude readings off by σ 2° roll/pitch and σ 20° heading.
    CompassNoise,
    /// KITTI frames and simulated spinning-LiDAR scans, no guess.
    Lidar,
    /// The stop-and-go loop on simulated routes robots really drive (long steps, a turn-around,
    /// a kidnapped robot, a half-blocked scanner, revisits the other way, a second run),
    /// relocalization in a saved map, and the KITTI frames beside KISS-ICP.
    Routes,
    /// Real scans seen again from known poses, beside GICP from identity.
    RealGeometry,
    /// The stop-and-go loop on long routes as the map grows: time per stop, memory, ATE by size.
    Scale,
}

impl Suite {
    pub(super) fn name(self) -> &'static str {
        match self {
            Suite::Unlevelled => "unlevelled",
            Suite::CompassNoise => "compass-noise",
            Suite::Lidar => "lidar",
            Suite::Routes => "routes",
            Suite::RealGeometry => "real-geometry",
            Suite::Scale => "scale",
        }
    }
}

/// The flags of `sdem bench --suite`.
#[derive(clap::Args, Debug)]
pub struct SuiteArgs {
    /// Run a suite instead: unlevelled (200 simulated pairs without attitude: roll/pitch up
    /// to ±30°, any heading, steps up to 1 m; 8 with --quick), compass-noise (the same pairs
    /// with readings off by σ 2° roll/pitch and σ 20° heading), lidar (KITTI frames, 20
    /// simulated spinning-LiDAR and 20 solid-state (70° field of view) pairs, no guess; on the
    /// grid and scale derived from each scan), real-geometry (real scans seen again from 50
    /// known poses each, 3 with --quick: the 3DTK scans and KITTI frames, or --scan; beside
    /// GICP), routes (the stop-and-go loop on six seeded routes without and with odometry,
    /// relocalization at every stop of a saved map, and the KITTI frames beside KISS-ICP;
    /// --quick: without odometry only, 8 relocalizations), scale (the loop on long routes as
    /// the map grows: --sizes, --route). The peers run beside it when found.
    #[arg(long, value_enum, conflicts_with = "faults")]
    pub suite: Option<Suite>,
    /// With --suite real-geometry: a real scan to re-view (any point file sdem reads, in its
    /// sensor's frame; repeat the flag) [default: the 3DTK scans and KITTI frames 0, 7 and 15
    /// in ../shared/data beside the repository].
    #[arg(long = "scan", value_name = "FILE", requires = "suite")]
    pub scans: Vec<PathBuf>,
    /// With --suite lidar or routes (not with --route, which leaves the KITTI part out): the
    /// KITTI folder (velodyne/, poses.txt, calib.txt) [default: ../shared/data/kitti-00-first16
    /// beside the repository, skipped, saying so, when absent].
    #[arg(long, value_name = "DIR", requires = "suite")]
    pub kitti: Option<PathBuf>,
    /// With --suite: the peers' folder, holding register_pair.py [default: ../shared/peers
    /// beside the repository]; their Python is $SDEM_PEERS_PYTHON, else
    /// /tmp/peers-venv/bin/python. Without either the suite runs without the peers, saying so.
    /// Not with --suite routes --route (the peers there run on the KITTI part only).
    #[arg(long, value_name = "DIR", requires = "suite")]
    pub peers: Option<PathBuf>,
    /// With --suite: give the peers the first N pairs of each part, 0 for none [default: 20
    /// of the simulated pairs, 4 with --quick; every KITTI pair].
    #[arg(long, value_name = "N", requires = "suite")]
    pub peer_pairs: Option<usize>,
    /// With --suite scale: the map sizes measured, nodes, increasing; each route runs up to
    /// the largest [default: 100,300,1000; 100 with --quick; the full set is 100,300,1000,3000].
    #[arg(
        long,
        value_name = "N,N,...",
        value_delimiter = ',',
        requires = "suite",
        allow_hyphen_values = true,
        value_parser = parse_size
    )]
    pub sizes: Vec<usize>,
    /// With --suite scale or routes: the routes (repeat or separate by commas) [scale's
    /// default: room-laps, floor, wings; room-laps with --quick. routes' default: all six
    /// (long-steps, turn-around, kidnapped, half-blocked, revisit, second-run) and the KITTI
    /// frames; naming routes leaves the KITTI frames out, so --kitti and --peers are refused
    /// with it].
    #[arg(
        long = "route",
        value_name = "ROUTE",
        value_delimiter = ',',
        requires = "suite"
    )]
    pub routes: Vec<String>,
    /// With --suite scale: where the plot of time per stop against stop number goes [default:
    /// scale.png].
    #[arg(long, value_name = "FILE.png", requires = "suite")]
    pub plot: Option<PathBuf>,
    /// With --suite scale: write the plot over an existing --plot file (refused without it).
    #[arg(long, requires = "suite")]
    pub force: bool,
}

impl SuiteArgs {
    /// `--plot`, or its default ([`crate::cmd_bench_scale::DEFAULT_PLOT`]).
    pub fn plot(&self) -> PathBuf {
        (self.plot.clone()).unwrap_or_else(|| crate::cmd_bench_scale::DEFAULT_PLOT.into())
    }
}

/// Parses one of `--sizes N,N,...`: a map size of at least 1 node.
fn parse_size(text: &str) -> std::result::Result<usize, String> {
    crate::parse::count_in(
        text,
        1..=usize::MAX,
        "a map size in nodes (e.g. 100,300,1000)",
    )
}

/// The flags `sdem bench` shares with its suites.
pub struct Common {
    /// A short run.
    pub quick: bool,
    /// `--pairs`: the pairs of each part.
    pub pairs: Option<usize>,
    /// The seed of the simulated pairs.
    pub seed: u64,
    /// The simulated tilting-scanner pairs' search grid, metres.
    pub step: f64,
    /// One JSON object instead of text.
    pub json: bool,
}

/// The scale suite's arguments from the flags, with its defaults.
pub(super) fn scale_args(
    args: &SuiteArgs,
    common: &Common,
) -> Result<crate::cmd_bench_scale::ScaleArgs> {
    let (full, quick) = crate::cmd_bench_scale::DEFAULT_SIZES;
    let sizes = if args.sizes.is_empty() {
        (if common.quick { quick } else { full }).to_vec()
    } else {
        args.sizes.clone()
    };
    let routes = if args.routes.is_empty() {
        if common.quick {
            vec![sdem_sim::sim::LongRoute::RoomLaps]
        } else {
            sdem_sim::sim::LongRoute::ALL.to_vec()
        }
    } else {
        long_routes(&args.routes)?
    };
    Ok(crate::cmd_bench_scale::ScaleArgs {
        sizes,
        routes,
        plot: args.plot(),
        seed: common.seed,
        json: common.json,
    })
}

/// Refuses (a usage error, before anything is read or run) a flag the suite does not take,
/// naming the suites that take it, and a `--route` the suite does not have. `pairs` and
/// `step`: whether `--pairs` and `--step` were given.
pub fn check_flags(args: &SuiteArgs, suite: Suite, pairs: bool, step: bool) -> Result<()> {
    let takes_routes = matches!(suite, Suite::Scale | Suite::Routes);
    // Named routes leave out the routes suite's KITTI part, the only use there of --kitti and
    // of the peers (KISS-ICP on the KITTI frames).
    let only_routes = suite == Suite::Routes && !args.routes.is_empty();
    let refused = [
        (
            !args.sizes.is_empty() && suite != Suite::Scale,
            "--sizes applies to --suite scale only",
        ),
        (
            !args.routes.is_empty() && !takes_routes,
            "--route applies to --suite scale and --suite routes only",
        ),
        (
            args.kitti.is_some() && !matches!(suite, Suite::Lidar | Suite::Routes),
            "--kitti applies to --suite lidar and --suite routes only",
        ),
        (
            !args.scans.is_empty() && suite != Suite::RealGeometry,
            "--scan applies to --suite real-geometry only",
        ),
        (
            pairs && takes_routes,
            "--pairs applies to --suite unlevelled, compass-noise, lidar and real-geometry only \
             (scale and routes run whole routes: --sizes and --route choose them)",
        ),
        (
            step && (takes_routes || suite == Suite::Lidar),
            "--step applies to --suite unlevelled, compass-noise and real-geometry only (lidar \
             searches each scan's grid at 5 cm, scale and routes with the loop's own step)",
        ),
        (
            args.plot.is_some() && suite != Suite::Scale,
            "--plot applies to --suite scale only (its plot of time per stop); the other suites \
             write no file",
        ),
        (
            args.force && suite != Suite::Scale,
            "--force applies to --suite scale only (it writes the plot over an existing --plot \
             file); the other suites write no file",
        ),
        (
            args.peers.is_some() && suite == Suite::Scale,
            "--peers applies to --suite unlevelled, compass-noise, lidar, routes and \
             real-geometry only (scale runs no peer)",
        ),
        (
            args.kitti.is_some() && only_routes,
            "--kitti cannot be given with --route: --route runs only the named routes, without \
             the KITTI part; drop --route to run every route and the KITTI frames, or drop \
             --kitti",
        ),
        (
            args.peers.is_some() && only_routes,
            "--peers cannot be given with --route: --route runs only the named routes, without \
             the KITTI part, the only one --suite routes gives the peers (KISS-ICP on the KITTI \
             frames); drop --route to run every route and the KITTI frames, or drop --peers",
        ),
        (
            args.peer_pairs.is_some() && takes_routes,
            "--peer-pairs applies to --suite unlevelled, compass-noise, lidar and real-geometry \
             only (routes gives KISS-ICP every KITTI frame; scale runs no peer)",
        ),
    ];
    if let Some((_, message)) = refused.iter().find(|(given, _)| *given) {
        return Err(crate::parse::usage_error("bench", message));
    }
    match suite {
        Suite::Routes => routes::parse_routes(&args.routes).map(|_| ()),
        Suite::Scale => long_routes(&args.routes).map(|_| ()),
        _ => Ok(()),
    }
}

/// The long routes of `--suite scale` named by `--route`.
///
/// # Errors
/// A usage error for a name that is not a long route's, with the names there are.
fn long_routes(names: &[String]) -> Result<Vec<sdem_sim::sim::LongRoute>> {
    (names.iter())
        .map(|r| {
            (r.trim().parse())
                .map_err(|e| crate::parse::usage_error("bench", format!("--route {r}: {e}")))
        })
        .collect()
}
