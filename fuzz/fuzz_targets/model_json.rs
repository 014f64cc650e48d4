//! Model files (`*.actrack.json`): any text is loaded or refused, never a panic.
#![no_main]

libfuzzer_sys::fuzz_target!(|text: &str| {
    let _ = actrack::ActionModel::from_json("fuzz.actrack.json".as_ref(), text);
});
