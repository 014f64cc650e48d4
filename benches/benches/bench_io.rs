//! Input benches: decoding YUV4MPEG2 frames to RGB (`actrack::frames::Y4mReader`) at 640×480,
//! limited-range 4:2:0 (what ffmpeg pipes and most y4m files hold) and full-range 4:4:4 (what
//! `actrack-cli synth --y4m` writes), on one core, from memory.

use std::hint::black_box;
use std::path::Path;

use actrack::frames::Y4mReader;
use criterion::{Criterion, Throughput, criterion_group, criterion_main};

const W: usize = 640;
const H: usize = 480;
const FRAMES: usize = 8;

/// A y4m stream of `FRAMES` frames with varied bytes in every plane.
fn stream(tag: &str, chroma_bytes: usize) -> Vec<u8> {
    let mut data = format!("YUV4MPEG2 W{W} H{H} F30:1 {tag}\n").into_bytes();
    let mut x = 0x2545_f491_u32;
    for _ in 0..FRAMES {
        data.extend_from_slice(b"FRAME\n");
        data.extend((0..W * H + chroma_bytes).map(|_| {
            // xorshift32: every byte value, no pattern the conversion could exploit.
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            x.to_le_bytes()[0]
        }));
    }
    data
}

fn bench_y4m(c: &mut Criterion) {
    let mut group = c.benchmark_group("y4m_frame_640x480");
    group.throughput(Throughput::Elements(FRAMES as u64));
    for (name, tag, chroma_bytes) in [
        ("420_limited", "C420jpeg", 2 * (W / 2) * (H / 2)),
        ("444_full", "C444 XCOLORRANGE=FULL", 2 * W * H),
    ] {
        // The reader takes a `'static` source; the bench keeps the stream for its lifetime.
        let data: &'static [u8] = Box::leak(stream(tag, chroma_bytes).into_boxed_slice());
        group.bench_function(name, |b| {
            b.iter(|| {
                let cursor = std::io::Cursor::new(data);
                let mut r = Y4mReader::new(Box::new(cursor), Path::new("bench")).expect("header");
                while let Some(img) = r.read_frame().expect("frame") {
                    black_box(img.as_raw()[0]);
                }
            });
        });
    }
    group.finish();
}

criterion_group!(benches, bench_y4m);
criterion_main!(benches);
