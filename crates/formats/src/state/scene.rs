//! Binary encoding of a correlation [`Scene`] (the window of aligned local
//! tracks a streaming correlation session holds), with [`wire_formats::wire`].

use algo::correlation::scene::Scene;

use wire_formats::wire::{FormatError, Reader, Writer, corrupt, invalid};

/// The scene's encoding written by [`encode_scene`].
pub const SCENE_FORMAT: u8 = 2;
/// Instant tag bits of scene format 2.
const TAG_PRESENT: u8 = 1;
const TAG_SYMMETRIC: u8 = 2;
const TAG_GAIN: u8 = 4;

/// Appends `scene` to `w` (the current format, [`SCENE_FORMAT`]).
/// Each held instant of a track takes one tag byte: 0 when absent, else
/// [`TAG_PRESENT`], plus [`TAG_SYMMETRIC`] when the covariance is
/// bit-for-bit symmetric (then only its upper triangle, row by row, is
/// written) and [`TAG_GAIN`] when a filter factor follows. Lossless:
/// decoding gives back the same bits.
pub fn encode_scene(scene: &Scene, w: &mut Writer) {
    let dim = scene.dim();
    w.usize(dim);
    w.usize(scene.position_indices().len());
    for &i in scene.position_indices() {
        w.usize(i);
    }
    w.usize(scene.first());
    w.f64s(scene.times());
    w.usize(scene.nodes().len());
    let held = scene.first()..scene.end();
    // One reservation for the whole scene instead of the buffer doubling
    // and copying itself as it grows: a tag per instant, and for each
    // present one at most the state, a full covariance and the gain.
    let bytes: usize = scene
        .nodes()
        .iter()
        .flatten()
        .map(|t| {
            let present = held.clone().filter(|&k| t.is_present(k)).count();
            let gain = held.clone().any(|k| t.gain_factor(k, dim).is_some());
            let per = dim + dim * dim + if gain { dim * dim } else { 0 };
            8 + held.len() + present * 8 * per
        })
        .sum();
    w.buf.reserve(bytes);
    for node in scene.nodes() {
        w.usize(node.len());
        for t in node {
            for k in held.clone() {
                if !t.is_present(k) {
                    w.u8(0);
                    continue;
                }
                let p = t.p(k, dim);
                let symmetric = (0..dim).all(|i| {
                    (i + 1..dim).all(|j| p[i * dim + j].to_bits() == p[j * dim + i].to_bits())
                });
                let g = t.gain_factor(k, dim);
                let mut tag = TAG_PRESENT;
                if symmetric {
                    tag |= TAG_SYMMETRIC;
                }
                if g.is_some() {
                    tag |= TAG_GAIN;
                }
                w.u8(tag);
                w.f64_run(t.x(k, dim));
                if symmetric {
                    for i in 0..dim {
                        w.f64_run(&p[i * dim + i..(i + 1) * dim]);
                    }
                } else {
                    w.f64_run(p);
                }
                if let Some(g) = g {
                    w.f64_run(g);
                }
            }
        }
    }
}

/// Reads a scene written by [`encode_scene`] in scene format `format`:
/// 1 (one presence byte, full covariances, an optional filter factor) or
/// 2 ([`SCENE_FORMAT`], tagged instants).
pub fn decode_scene(r: &mut Reader<'_>, format: u8) -> Result<Scene, FormatError> {
    if !(1..=SCENE_FORMAT).contains(&format) {
        return Err(corrupt(&format!("scene format {format} is unknown")));
    }
    let dim = r.usize()?;
    let npos = r.len(8)?;
    let pos = (0..npos)
        .map(|_| r.usize())
        .collect::<Result<Vec<_>, _>>()?;
    let first = r.usize()?;
    let times = r.f64s()?;
    let mut scene = Scene::held_from(dim, pos, first, times).map_err(invalid)?;
    let floats = |r: &mut Reader<'_>, n: usize| -> Result<Vec<f64>, FormatError> {
        (0..n).map(|_| r.f64()).collect()
    };
    let n_nodes = r.len(8)?;
    let mut p = vec![0.0; dim * dim];
    for _ in 0..n_nodes {
        let node = scene.push_node();
        let n_tracks = r.len(scene.times().len())?;
        for _ in 0..n_tracks {
            let ti = scene.push_track(node);
            for k in first..scene.end() {
                let tag = if format == 1 {
                    u8::from(r.bool()?)
                } else {
                    r.u8()?
                };
                if tag == 0 {
                    continue;
                }
                if tag & !(TAG_PRESENT | TAG_SYMMETRIC | TAG_GAIN) != 0 || tag & TAG_PRESENT == 0 {
                    return Err(corrupt(&format!("unknown instant tag {tag:#04x}")));
                }
                let x = floats(r, dim)?;
                if tag & TAG_SYMMETRIC != 0 {
                    for i in 0..dim {
                        for j in i..dim {
                            let v = r.f64()?;
                            p[i * dim + j] = v;
                            p[j * dim + i] = v;
                        }
                    }
                } else {
                    p = floats(r, dim * dim)?;
                }
                let g = if format == 1 {
                    r.opt(|r| floats(r, dim * dim))?
                } else if tag & TAG_GAIN != 0 {
                    Some(floats(r, dim * dim)?)
                } else {
                    None
                };
                let track = scene.track_mut(node, ti);
                track.set(k, &x, &p);
                if let Some(g) = g {
                    track.set_gain_factor(k, &g);
                }
            }
        }
    }
    Ok(scene)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every held value of two scenes, as bits (so that -0.0 ≠ 0.0).
    fn bits(s: &Scene) -> Vec<u64> {
        let dim = s.dim();
        let mut out: Vec<u64> = s.times().iter().map(|t| t.to_bits()).collect();
        for node in s.nodes() {
            for t in node {
                for k in s.first()..s.end() {
                    out.push(u64::from(t.is_present(k)));
                    if t.is_present(k) {
                        out.extend(t.x(k, dim).iter().map(|v| v.to_bits()));
                        out.extend(t.p(k, dim).iter().map(|v| v.to_bits()));
                        out.extend(
                            t.gain_factor(k, dim)
                                .into_iter()
                                .flatten()
                                .map(|v| v.to_bits()),
                        );
                    }
                }
            }
        }
        out
    }

    #[test]
    fn the_encoding_is_lossless_and_stores_symmetric_covariances_as_triangles() {
        let mut s = Scene::new(2, vec![0], vec![]).unwrap();
        for t in [0.0, 1.0, 2.0] {
            s.push_instant(t).unwrap();
        }
        let node = s.push_node();
        let (a, b) = (s.push_track(node), s.push_track(node));
        // Symmetric, with a -0.0 off the diagonal mirrored exactly.
        s.track_mut(node, a)
            .set(0, &[1.0, 2.0], &[4.0, -0.0, -0.0, 9.0]);
        // Asymmetric in the last bit, and 0.0 against -0.0: kept whole.
        let off = 0.1_f64;
        let off2 = f64::from_bits(off.to_bits() + 1);
        s.track_mut(node, a)
            .set(2, &[3.0, 4.0], &[4.0, off, off2, 9.0]);
        s.track_mut(node, b)
            .set(1, &[5.0, 6.0], &[1.0, 0.0, -0.0, 1.0]);
        s.track_mut(node, b)
            .set_gain_factor(1, &[0.5, 0.25, 0.125, 0.75]);
        let mut w = Writer::default();
        encode_scene(&s, &mut w);
        let back = decode_scene(&mut Reader::new(&w.buf), SCENE_FORMAT).unwrap();
        assert_eq!(bits(&back), bits(&s));
        // Re-encoding gives the same bytes.
        let mut w2 = Writer::default();
        encode_scene(&back, &mut w2);
        assert_eq!(w2.buf, w.buf);
        // Size: the header is 7 counts and indices (dim, position count, the
        // position, first, time count, node count, track count) and 3 times:
        // (7 + 3) × 8 bytes; then 6 tag bytes, and 3 states of 2 values, the
        // symmetric covariance's 3 values, the two others' 4 each and the
        // gain factor's 4: (6 + 3 + 8 + 4) × 8 bytes.
        assert_eq!(w.buf.len(), (7 + 3) * 8 + 6 + (6 + 3 + 8 + 4) * 8);
        // A bad tag, and an unknown format, are errors.
        let mut bad = w.buf.clone();
        bad[(7 + 3) * 8] = 0x80;
        assert!(decode_scene(&mut Reader::new(&bad), SCENE_FORMAT).is_err());
        assert!(decode_scene(&mut Reader::new(&w.buf), SCENE_FORMAT + 1).is_err());
    }
}
