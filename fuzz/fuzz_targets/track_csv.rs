//! Trajectory CSVs (tracker output and ground truth): any text is parsed or refused, never a
//! panic.
#![no_main]

libfuzzer_sys::fuzz_target!(|text: &str| {
    let _ = actrack::track_csv::Trajectory::parse(text, "fuzz.csv".as_ref());
});
