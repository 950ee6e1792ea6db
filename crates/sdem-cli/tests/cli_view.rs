//! `sdem view` pictures and the 3D viewer page, from a real `sdem slam` run on a small
//! simulated dataset; the page is rendered in headless Chromium (installed by `scripts/test`).

mod common;

use common::{fails, run_ok, usage_error};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

/// A folder with `data/` (3 simulated stops) and `out/` (`sdem slam` over them), made once for
/// all tests of this file.
fn fixture() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("cli_view");
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        run_ok(&dir, &["simulate", "--out", "data", "--stops", "3"]);
        run_ok(&dir, &["slam", "data", "--out", "out", "--max-scans", "3"]);
        dir
    })
}

/// Decodes a PNG and checks it is a picture, not a blank: many colours, a good share of
/// non-white pixels. Returns its size.
fn check_png(path: &Path, min_colors: usize) -> (u32, u32) {
    let image = image::open(path)
        .unwrap_or_else(|e| panic!("{}: not a PNG: {e}", path.display()))
        .to_rgb8();
    let colors: std::collections::HashSet<[u8; 3]> = image.pixels().map(|p| p.0).collect();
    assert!(
        colors.len() >= min_colors,
        "{}: only {} colours",
        path.display(),
        colors.len()
    );
    let non_white = image.pixels().filter(|p| p.0 != [255, 255, 255]).count();
    let share = non_white as f64 / (image.width() * image.height()) as f64;
    assert!(
        share > 0.02,
        "{}: {:.1} % non-white",
        path.display(),
        share * 100.0
    );
    (image.width(), image.height())
}

#[test]
fn view_map_writes_every_picture_and_the_page() {
    let dir = fixture();
    let stdout = run_ok(
        dir,
        &["view", "map", "out", "--out-dir", "pictures", "--json"],
    );
    let report: serde_json::Value = serde_json::from_str(&stdout).expect("one JSON object");
    let written: Vec<&str> = report["written"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_str().unwrap())
        .collect();
    assert_eq!(written.len(), 6, "{written:?}");
    for name in ["plan", "section", "panorama", "slice", "cost"] {
        let path = dir.join("pictures").join(format!("{name}.png"));
        let (w, h) = check_png(&path, 12);
        assert!(w >= 800 && h >= 500, "{name}: {w}×{h}");
    }
    let page = std::fs::read_to_string(dir.join("pictures/viewer.html")).unwrap();
    assert!(!page.contains("http://") && !page.contains("https://"));
    assert!(page.contains("\"shownCount\":") && page.contains("<canvas"));
    // Pictures already in another folder are the user's: written over only with --force.
    let plan = dir.join("pictures/plan.png");
    std::fs::write(&plan, "mine").unwrap();
    let why = fails(dir, &["view", "map", "out", "--out-dir", "pictures"]);
    assert!(why.contains("plan.png") && why.contains("--force"), "{why}");
    assert_eq!(std::fs::read(&plan).unwrap(), b"mine");
    run_ok(
        dir,
        &["view", "map", "out", "--out-dir", "pictures", "--force"],
    );
    check_png(&plan, 12);
}

#[test]
fn view_panorama_and_slice_of_a_scan() {
    let dir = fixture();
    run_ok(
        dir,
        &[
            "view",
            "panorama",
            "data",
            "--index",
            "1",
            "--out",
            "p/pano.png",
        ],
    );
    check_png(&dir.join("p/pano.png"), 30);
    run_ok(
        dir,
        &[
            "view",
            "slice",
            "data",
            "--index",
            "2",
            "--elevation",
            "-10",
            "--out",
            "p/slice.png",
        ],
    );
    check_png(&dir.join("p/slice.png"), 12);
    // One point-cloud file, taken as level.
    let scan = std::fs::read_dir(dir.join("data/scans"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .min()
        .unwrap();
    let scan = scan.to_str().unwrap();
    run_ok(dir, &["view", "panorama", scan, "--out", "p/file.png"]);
    check_png(&dir.join("p/file.png"), 30);
}

#[test]
fn view_cost_of_one_localization() {
    let dir = fixture();
    run_ok(
        dir,
        &[
            "view",
            "cost",
            "data",
            "--reference",
            "0",
            "--query",
            "1",
            "--window",
            "0.1:0.6,-0.2:0.2,-0.1:0.1",
            "--out",
            "c/cost.png",
        ],
    );
    check_png(&dir.join("c/cost.png"), 30);
}

#[test]
fn view_names_what_is_wrong() {
    let dir = fixture();
    let e = fails(dir, &["view", "panorama", "nowhere", "--out", "x.png"]);
    assert!(e.contains("nowhere"), "{e}");
    let e = fails(
        dir,
        &["view", "panorama", "data", "--index", "7", "--out", "x.png"],
    );
    assert!(e.contains("--index 7") && e.contains("data"), "{e}");
    let e = fails(dir, &["view", "map", "data"]);
    assert!(
        e.contains("data") && e.contains("manifest") || e.contains("not a `sdem slam`"),
        "{e}"
    );
    usage_error(
        dir,
        &[
            "view",
            "slice",
            "data",
            "--elevation",
            "100",
            "--out",
            "x.png",
        ],
        &["'100' for '--elevation", "[-90, 90]"],
    );
    let e = fails(
        dir,
        &[
            "view",
            "cost",
            "data",
            "--reference",
            "9",
            "--query",
            "1",
            "--out",
            "x.png",
        ],
    );
    assert!(e.contains("--reference 9"), "{e}");
    assert!(!dir.join("x.png").exists());
}

/// Where Chromium is: `SDEM_CHROMIUM`, else `/usr/bin/chromium`, else `chromium` on the PATH.
fn chromium() -> PathBuf {
    if let Some(path) = std::env::var_os("SDEM_CHROMIUM") {
        return PathBuf::from(path);
    }
    let usual = PathBuf::from("/usr/bin/chromium");
    if usual.exists() {
        return usual;
    }
    let on_path = std::env::var_os("PATH")
        .map(|paths| {
            std::env::split_paths(&paths)
                .map(|p| p.join("chromium"))
                .find(|p| p.exists())
        })
        .unwrap_or_default();
    on_path.unwrap_or_else(|| {
        panic!(
            "Chromium is missing (looked at $SDEM_CHROMIUM, /usr/bin/chromium and chromium on the \
             PATH), and the viewer page's test renders the page in it. Install it with \
             `sudo apt-get install -y chromium` (scripts/test does this when it can), or set \
             SDEM_CHROMIUM to a Chromium binary"
        )
    })
}

/// A headless-Chromium screenshot (800 × 600) of `page`, with the given extra flags.
fn screenshot(page: &Path, png: &Path, extra: &[&str]) {
    let profile = tempfile::TempDir::new().unwrap();
    let url = format!("file://{}", page.canonicalize().unwrap().display());
    let mut command = Command::new(chromium());
    command
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-quic",
            "--no-first-run",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--hide-scrollbars",
            "--window-size=800,600",
            "--virtual-time-budget=5000",
        ])
        .arg(format!("--user-data-dir={}", profile.path().display()))
        .arg(format!("--screenshot={}", png.display()))
        .args(extra)
        .arg(&url);
    let out = command.output().expect("cannot run chromium");
    assert!(
        out.status.success() && png.exists(),
        "chromium failed on {url}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn viewer_page_renders_the_map_in_headless_chromium() {
    let dir = fixture();
    run_ok(dir, &["view", "map", "out", "--out-dir", "page"]);
    let page = dir.join("page/viewer.html");
    // WebGL on the software rasterizer, and the 2D canvas fallback without WebGL.
    for (name, extra) in [
        ("webgl", &["--enable-unsafe-swiftshader"][..]),
        ("canvas2d", &["--disable-webgl"][..]),
    ] {
        let png = dir.join(format!("page/screenshot-{name}.png"));
        let _ = std::fs::remove_file(&png);
        screenshot(&page, &png, extra);
        let image = image::open(&png).unwrap().to_rgb8();
        assert_eq!((image.width(), image.height()), (800, 600));
        // The map's points: many coloured pixels (not white, not grey text), in several colours,
        // below the title lines.
        let colored: Vec<[u8; 3]> = image
            .enumerate_pixels()
            .filter(|(_, y, _)| *y > 70)
            .map(|(_, _, p)| p.0)
            .filter(|c| {
                let (max, min) = (*c.iter().max().unwrap(), *c.iter().min().unwrap());
                max - min > 40
            })
            .collect();
        let distinct: std::collections::HashSet<[u8; 3]> = colored.iter().copied().collect();
        assert!(
            colored.len() > 3000 && distinct.len() > 20,
            "{name}: the screenshot {} shows {} coloured pixels in {} colours",
            png.display(),
            colored.len(),
            distinct.len()
        );
    }
}
