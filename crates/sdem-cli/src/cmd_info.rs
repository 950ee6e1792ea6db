//! `sdem info BAG`: what a ROS 2 bag holds, like `ros2 bag info`: files, storage, size, time
//! span, and each topic's type, count and rate, with what `sdem import` takes from it.

use crate::output::print_json;
use anyhow::{bail, Result};
use sdem_io::rosbag::{bag_info, Bag, BagInfo};
use std::path::PathBuf;

/// Arguments of `sdem info`.
#[derive(clap::Args)]
pub struct Args {
    /// The bag: a rosbag2 folder (metadata.yaml with .mcap or .db3 files) or one .mcap or .db3
    /// file.
    bag: PathBuf,
    /// Print one JSON object instead of text.
    #[arg(long)]
    json: bool,
}

/// Runs `sdem info`: the whole bag is read (no message decoded); a damaged bag is described up
/// to the damage, which is then reported as the error (exit status 1).
pub fn run(args: Args) -> Result<()> {
    let size = Bag::open(&args.bag).map_or(1, |b| b.size_bytes());
    let bar = crate::progress::bar(size.max(1), args.json, "reading");
    let info = bag_info(&args.bag, &mut |done| bar.set_position(done))?;
    bar.finish_and_clear();
    if args.json {
        print_json(&info)?;
    } else {
        print_text(&info);
    }
    if let Some(damage) = &info.damage {
        bail!(
            "{}; `sdem import --salvage` imports what comes before the damage",
            damage.describe()
        );
    }
    Ok(())
}

/// `2023-11-14 22:13:20.000 UTC` for seconds since the epoch.
fn utc(seconds: f64) -> String {
    let whole = seconds.floor() as i64;
    let millis = ((seconds - whole as f64) * 1000.0).round().min(999.0) as i64;
    let (days, rest) = (whole.div_euclid(86_400), whole.rem_euclid(86_400));
    // Howard Hinnant's days-from-civil, inverted.
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + i64::from(month <= 2);
    format!(
        "{year:04}-{month:02}-{day:02} {:02}:{:02}:{:02}.{millis:03} UTC",
        rest / 3600,
        rest % 3600 / 60,
        rest % 60
    )
}

fn size_text(bytes: u64) -> String {
    let b = bytes as f64;
    if b >= 1024.0 * 1024.0 * 1024.0 {
        format!("{:.2} GiB", b / (1024.0 * 1024.0 * 1024.0))
    } else if b >= 1024.0 * 1024.0 {
        format!("{:.1} MiB", b / (1024.0 * 1024.0))
    } else if b >= 1024.0 {
        format!("{:.1} KiB", b / 1024.0)
    } else {
        format!("{bytes} B")
    }
}

fn print_text(info: &BagInfo) {
    let files: Vec<String> = info.files.iter().map(|f| f.display().to_string()).collect();
    println!("Files:             {}", files.join("\n                   "));
    println!("Bag size:          {}", size_text(info.size_bytes));
    println!("Storage id:        {}", info.storage.name());
    if let Some(compression) = &info.compression {
        println!("Compression:       {compression}");
    }
    println!("Duration:          {:.3} s", info.duration_s);
    println!(
        "Start:             {} ({:.3})",
        utc(info.start_s),
        info.start_s
    );
    println!("End:               {} ({:.3})", utc(info.end_s), info.end_s);
    match info.metadata_messages {
        Some(listed) if listed != info.messages => println!(
            "Messages:          {} (metadata.yaml lists {listed})",
            info.messages
        ),
        _ => println!("Messages:          {}", info.messages),
    }
    println!("Topic information:");
    let width = info
        .topics
        .iter()
        .map(|t| t.stats.name.len())
        .max()
        .unwrap_or(0);
    for topic in &info.topics {
        let type_name = if topic.stats.type_name.is_empty() {
            "(no type)"
        } else {
            &topic.stats.type_name
        };
        println!(
            "  Topic: {:width$} | Type: {type_name} | Count: {} | Rate: {:.2} Hz | Serialization Format: {} | sdem: {}",
            topic.stats.name,
            topic.stats.count,
            topic.rate_hz,
            topic.stats.serialization_format,
            topic.sdem_use.unwrap_or("-"),
        );
    }
    if let Some(damage) = &info.damage {
        println!("DAMAGED:           {}", damage.describe());
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn utc_dates_are_the_calendar_ones() {
        assert_eq!(super::utc(0.0), "1970-01-01 00:00:00.000 UTC");
        assert_eq!(super::utc(1_700_000_000.25), "2023-11-14 22:13:20.250 UTC");
        assert_eq!(super::utc(951_825_600.0), "2000-02-29 12:00:00.000 UTC");
    }
}
