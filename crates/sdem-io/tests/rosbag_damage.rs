//! Damaged bags never make the bag reader panic or invent messages: an MCAP file that sdem
//! wrote, cut or with bytes changed at random, and the bytes of random messages given to the
//! import, end in messages that were in the file, then damage or an error.

use proptest::prelude::*;
use sdem::geometry::{Pose, Vec3};
use sdem_io::rosbag::{Bag, BagMessage, CdrReader};
use sdem_io::{write_map_mcap, MapScene};
use std::collections::HashSet;

/// An MCAP file of a small mapped run, and its messages' bytes.
fn sample() -> (Vec<u8>, HashSet<Vec<u8>>) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("run.mcap");
    let poses: Vec<Pose> = (0..6)
        .map(|i| Pose::translation(0.3 * i as f64, 0.0, 0.0))
        .collect();
    let scans: Vec<Vec<Vec3>> = (0..6)
        .map(|i| {
            (0..200)
                .map(|k| Vec3::new(k as f64 * 0.01, i as f64, 1.0))
                .collect()
        })
        .collect();
    let map: Vec<Vec3> = scans.iter().flatten().copied().collect();
    let scene = MapScene {
        world_from_sensor: &poses,
        scans_in_world: &scans,
        map_cloud: &map,
        loop_closures: &[(0, 5)],
    };
    write_map_mcap(&path, &scene).unwrap();
    let bytes = std::fs::read(&path).unwrap();
    let messages = read(&path).0.into_iter().collect();
    (bytes, messages)
}

/// Every message read from `path`, and whether the reader reported damage or an error.
fn read(path: &std::path::Path) -> (Vec<Vec<u8>>, bool) {
    let mut seen = Vec::new();
    let outcome = Bag::open(path).and_then(|bag| {
        bag.read(
            &mut |m: &BagMessage| {
                seen.push(m.data.to_vec());
                Ok(())
            },
            &mut |_| {},
        )
    });
    let troubled = !matches!(outcome, Ok(None));
    (seen, troubled)
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

    #[test]
    fn a_cut_or_changed_mcap_file_gives_only_its_own_messages(
        cut in 0.0f64..1.0,
        flips in proptest::collection::vec((0.0f64..1.0, any::<u8>()), 0..4),
    ) {
        let (mut bytes, original) = sample();
        for (at, value) in flips {
            let i = ((bytes.len() - 1) as f64 * at) as usize;
            bytes[i] ^= value | 1;
        }
        let keep = 8 + ((bytes.len() - 8) as f64 * cut) as usize;
        bytes.truncate(keep);
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("damaged.mcap");
        std::fs::write(&path, &bytes).unwrap();
        let (seen, troubled) = read(&path);
        prop_assert!(troubled, "a cut file must report damage");
        for data in &seen {
            prop_assert!(original.contains(data), "a message that was not written");
        }
    }

    #[test]
    fn random_bytes_never_make_a_message_decoder_panic(bytes in proptest::collection::vec(any::<u8>(), 0..400)) {
        let mut with_header = vec![0, 1, 0, 0];
        with_header.extend_from_slice(&bytes);
        let mut r = CdrReader::new(&with_header).unwrap();
        let _ = r.string("s");
        let _ = r.bytes("b");
        let _ = r.f64_sequence("f");
    }
}

#[test]
fn garbage_named_db3_is_damage_not_a_panic() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bag.db3");
    std::fs::write(&path, b"SQLite format 3\0 but not really a database at all").unwrap();
    let (seen, troubled) = read(&path);
    assert!(seen.is_empty() && troubled);
}

/// A bag is known by its first bytes as well as its name: an MCAP file renamed in capitals or
/// without an extension, and a folder of bag files whose `metadata.yaml` was lost, are bags; a
/// text file named `.mcap` is said to be no MCAP file (it was called damaged, with advice to
/// salvage it), and a file that cannot be opened says why.
#[test]
fn a_bag_is_known_by_its_bytes_and_a_file_of_another_kind_is_named_so() {
    use sdem_io::rosbag::is_rosbag;
    let (bytes, messages) = sample();
    let dir = tempfile::tempdir().unwrap();
    for name in ["RUN.MCAP", "run-without-extension"] {
        let path = dir.path().join(name);
        std::fs::write(&path, &bytes).unwrap();
        assert!(is_rosbag(&path), "{name}");
        let (seen, troubled) = read(&path);
        assert!(!troubled && seen.len() == messages.len(), "{name}");
    }
    let folder = dir.path().join("killed-recording");
    std::fs::create_dir(&folder).unwrap();
    std::fs::write(folder.join("killed-recording_0.mcap"), &bytes).unwrap();
    assert!(is_rosbag(&folder));
    assert_eq!(read(&folder).0.len(), messages.len());

    let text = dir.path().join("notes.mcap");
    std::fs::write(&text, "these are notes, not a recording\n").unwrap();
    let e = Bag::open(&text).unwrap_err().to_string();
    assert!(e.contains("is not an MCAP file"), "{e}");
    std::fs::write(&text, "notes\n").unwrap(); // shorter than a header
    let e = Bag::open(&text).unwrap_err().to_string();
    assert!(e.contains("is not an MCAP file"), "{e}");
    let named_db3 = dir.path().join("run.db3");
    std::fs::write(&named_db3, &bytes).unwrap();
    assert_eq!(
        read(&named_db3).0.len(),
        messages.len(),
        "read by its bytes"
    );
    assert!(!is_rosbag(&dir.path().join("missing.mcap")));
}
