//! Property tests: random and mutated bytes fed to every parser (motion capture, manifests,
//! model files) never panic, only error.

use std::fmt::Write as _;
use std::path::Path;

use proptest::prelude::*;

use crate::manifest::Manifest;
use crate::mocap::{c3d, decompress, joints_csv, vicon};
use crate::model::ActionModel;

fn vicon_sample() -> String {
    let mut s = String::from(
        "\u{feff}Trajectories\n100\n,,S:A,,,S:B,,\nFrame,Sub Frame,X,Y,Z,X,Y,Z\n,,mm,mm,mm,mm,mm,mm\n",
    );
    for f in 1..=6 {
        let _ = writeln!(s, "{f},0,{f}.5,2,3,,,");
    }
    s
}

fn joints_sample() -> String {
    let mut s = String::from(joints_csv::HEADER);
    s.push('\n');
    for t in 0..5 {
        let _ = writeln!(
            s,
            "{t},{},reach,0.1,0.5,0,0,0,0.1,0.2,-0.2,0.1,0.4,-0.3",
            f64::from(t) / 30.0
        );
    }
    s
}

const MANIFEST: &str = "root = \".\"\n[options]\nstates = 5\n[preprocessing]\ntrim = false\n[[trials]]\nfiles = \"*.csv\"\naction = \"reach\"\narm = \"R\"\n";

const MODEL: &str = "{\"format\":\"actrack-model\",\"version\":1,\"actions\":[],\"arm_lengths\":{\"upper_arm\":0.3,\"forearm_hand\":0.4}}";

/// A minimal C3D: header block, one parameter block, no frames (enough to reach c3dio).
fn c3d_sample() -> Vec<u8> {
    let mut b = vec![0u8; 1024];
    b[0] = 2;
    b[1] = 0x50;
    b[512 + 2] = 1;
    b[512 + 3] = 0x54;
    b
}

fn mutate(mut base: Vec<u8>, edits: &[(usize, u8, u8)]) -> Vec<u8> {
    for &(pos, op, val) in edits {
        if base.is_empty() {
            base.push(val);
            continue;
        }
        let p = pos % base.len();
        match op % 4 {
            0 => base[p] = val,
            1 => base.insert(p, val),
            2 => {
                base.remove(p);
            }
            _ => base.truncate(p),
        }
    }
    base
}

fn all_parsers(bytes: &[u8]) {
    let p = Path::new("fuzz.csv");
    let text = String::from_utf8_lossy(bytes);
    let _ = vicon::parse_vicon_csv(p, &text, None);
    let _ = vicon::parse_vicon_csv(p, &text, Some(&["A".to_string()]));
    let _ = joints_csv::parse_joints_csv(p, &text);
    let _ = Manifest::parse(Path::new("/nonexistent/fuzz.toml"), &text);
    let _ = ActionModel::from_json(p, &text);
    let _ = c3d::parse_c3d(p, bytes, None);
    let _ = decompress(p, bytes.to_vec());
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 256, ..ProptestConfig::default() })]

    #[test]
    fn random_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..2048)) {
        all_parsers(&bytes);
    }

    #[test]
    fn mutated_files_never_panic(
        which in 0usize..5,
        edits in proptest::collection::vec((any::<usize>(), any::<u8>(), any::<u8>()), 1..8),
    ) {
        let base = match which {
            0 => vicon_sample().into_bytes(),
            1 => joints_sample().into_bytes(),
            2 => MANIFEST.as_bytes().to_vec(),
            3 => MODEL.as_bytes().to_vec(),
            _ => c3d_sample(),
        };
        all_parsers(&mutate(base, &edits));
    }

    #[test]
    fn mutated_xz_and_gzip_never_panic(
        edits in proptest::collection::vec((any::<usize>(), any::<u8>(), any::<u8>()), 1..4),
        gz in any::<bool>(),
    ) {
        use std::io::Write;
        let text = vicon_sample();
        let packed = if gz {
            let mut e = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
            e.write_all(text.as_bytes()).unwrap();
            e.finish().unwrap()
        } else {
            let mut out = Vec::new();
            lzma_rs::xz_compress(&mut std::io::Cursor::new(text.as_bytes()), &mut out).unwrap();
            out
        };
        let p = Path::new("fuzz.csv.xz");
        if let Ok(bytes) = decompress(p, mutate(packed, &edits)) {
            all_parsers(&bytes);
        }
    }
}

#[test]
fn samples_parse() {
    let p = Path::new("s");
    assert!(vicon::parse_vicon_csv(p, &vicon_sample(), None).is_ok());
    assert!(joints_csv::parse_joints_csv(p, &joints_sample()).is_ok());
    assert!(c3d::parse_c3d(p, &[0u8; 10], None).is_err());
}
