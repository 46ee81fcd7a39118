//! Speed of the correlation scene's stored form: encodes and decodes a
//! streaming session's window (2 nodes × 200 tracks × 60 instants, state
//! dimension 4, a gain factor on every other track) and prints MB/s.
//!
//! `cargo run -p formats --release --example state_codec_speed`

use std::time::Instant;

use algo::correlation::scene::Scene;
use formats::state::scene::{SCENE_FORMAT, decode_scene, encode_scene};
use wire_formats::wire::{Reader, Writer};

fn main() {
    let (dim, tracks, instants) = (4, 200, 60);
    let mut s = Scene::new(dim, vec![0, 2], vec![]).unwrap();
    for k in 0..instants {
        s.push_instant(k as f64).unwrap();
    }
    for _ in 0..2 {
        let node = s.push_node();
        for i in 0..tracks {
            let t = s.push_track(node);
            for k in 0..instants {
                if (k + i) % 5 == 0 {
                    continue;
                }
                let v = (i * 1000 + k) as f64;
                let x = [v, 1.0, -v, 2.0];
                let mut p = [0.0; 16];
                for a in 0..dim {
                    p[a * dim + a] = 10.0 + a as f64;
                }
                p[1] = 0.5;
                p[4] = 0.5;
                s.track_mut(node, t).set(k, &x, &p);
                if i % 2 == 0 {
                    s.track_mut(node, t).set_gain_factor(k, &p);
                }
            }
        }
    }
    let reps = 200;
    let start = Instant::now();
    let mut bytes = 0;
    for _ in 0..reps {
        let mut w = Writer::default();
        encode_scene(&s, &mut w);
        bytes = std::hint::black_box(w.buf).len();
    }
    let enc = start.elapsed().as_secs_f64();
    let mut w = Writer::default();
    encode_scene(&s, &mut w);
    let start = Instant::now();
    for _ in 0..reps {
        let back = decode_scene(&mut Reader::new(&w.buf), SCENE_FORMAT).unwrap();
        std::hint::black_box(back);
    }
    let dec = start.elapsed().as_secs_f64();
    let mb = (bytes * reps) as f64 / 1e6;
    println!(
        "scene of {bytes} bytes: encode {:.0} MB/s, decode {:.0} MB/s",
        mb / enc,
        mb / dec
    );
}
