//! C3D motion-capture files: any bytes are parsed or refused with an error, never a panic.
#![no_main]

libfuzzer_sys::fuzz_target!(|bytes: &[u8]| {
    let _ = actrack::mocap::c3d::parse_c3d("fuzz.c3d".as_ref(), bytes, None);
});
