//! C3D motion-capture files: any bytes are parsed or refused with an error, never a panic.
//!
//! `parse_c3d` runs the C3D parser (`c3dio`) inside `catch_unwind` and turns its panics into
//! errors naming the file. libFuzzer's panic hook aborts on every panic, even a caught one, so
//! this target lets panics raised inside `c3dio` unwind to that `catch_unwind`, as they do in the
//! library, and still aborts on any other panic.
#![no_main]

use std::sync::Once;

static HOOK: Once = Once::new();

libfuzzer_sys::fuzz_target!(|bytes: &[u8]| {
    HOOK.call_once(|| {
        let abort = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            // Raised in c3dio itself or in the standard library on its behalf (an overflow in
            // an iterator's `product`): c3dio is on the stack.
            let inside = info.location().is_some_and(|l| l.file().contains("/c3dio-"))
                || std::backtrace::Backtrace::force_capture()
                    .to_string()
                    .contains("c3dio::");
            if inside {
                return;
            }
            abort(info);
        }));
    });
    let _ = actrack::mocap::c3d::parse_c3d("fuzz.c3d".as_ref(), bytes, None);
});
