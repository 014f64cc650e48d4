//! Scene files (TOML): any text is validated or refused, never a panic.
#![no_main]

libfuzzer_sys::fuzz_target!(|text: &str| {
    let _ = actrack::Scene::parse(text, "fuzz.toml".as_ref());
});
