//! Training manifests (TOML): any text is parsed or refused, never a panic.
#![no_main]

libfuzzer_sys::fuzz_target!(|text: &str| {
    let _ = actrack::manifest::Manifest::parse("fuzz.toml".as_ref(), text);
});
