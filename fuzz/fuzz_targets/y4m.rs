//! YUV4MPEG2 streams: any bytes give frames, a clean end or an error, never a panic; frame
//! sizes from the header are bounded so a hostile header cannot exhaust memory.
#![no_main]

use std::io::Cursor;

libfuzzer_sys::fuzz_target!(|bytes: &[u8]| {
    let r = Box::new(Cursor::new(bytes.to_vec()));
    let Ok(mut y) = actrack::frames::Y4mReader::new(r, "fuzz.y4m".as_ref()) else {
        return;
    };
    for _ in 0..4 {
        match y.read_frame() {
            Ok(Some(_)) => {}
            Ok(None) | Err(_) => break,
        }
    }
});
