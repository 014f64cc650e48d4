//! The joint-trajectory CSV of DESIGN.md: any text is parsed or refused, never a panic.
#![no_main]

libfuzzer_sys::fuzz_target!(|text: &str| {
    let _ = actrack::mocap::joints_csv::parse_joints_csv("fuzz.csv".as_ref(), text);
});
