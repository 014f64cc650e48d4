//! Vicon Nexus CSV export: any text is parsed or refused with an error, never a panic.
#![no_main]

libfuzzer_sys::fuzz_target!(|text: &str| {
    let _ = actrack::mocap::vicon::parse_vicon_csv("fuzz.csv".as_ref(), text, None);
});
