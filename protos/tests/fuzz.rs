//! Decoding must never panic, whatever the bytes: actors, learner and label server all read
//! messages off the network. Inputs are random byte strings, random but well-formed field
//! sequences (alone and appended to a valid message), every truncation of a valid encoding and
//! random bit flips of one.

mod common;

use std::{fmt::Debug, panic};

use common::*;
use lhm_protos::WireMessage;

const RANDOM_INPUTS: usize = 5_000;
const FIELD_SEQUENCES: usize = 2_000;
const BIT_FLIP_INPUTS: usize = 1_000;

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// Decodes `bytes`, turning a panic into a test failure that shows the input. Returns whether
/// the input was accepted.
fn decode_ok<M: WireMessage + Debug>(bytes: &[u8]) -> bool {
    match panic::catch_unwind(|| M::decode_checked(bytes)) {
        Ok(Ok(message)) => {
            // Whatever is accepted must also pass the sender-side check and survive a re-encode
            // (compared as bytes: Metrics may hold NaN, which is never == itself).
            let again = message
                .encode_checked()
                .expect("accepted message re-encodes");
            assert_eq!(M::decode_checked(&again).unwrap().encode_to_vec(), again);
            true
        }
        Ok(Err(_)) => false,
        Err(_) => panic!(
            "{}::decode_checked panicked on {}",
            M::FULL_NAME,
            hex(bytes)
        ),
    }
}

fn push_varint(buf: &mut Vec<u8>, mut value: u64) {
    while value >= 0x80 {
        buf.push(value as u8 | 0x80);
        value >>= 7;
    }
    buf.push(value as u8);
}

/// `schema_version = 1` followed by random fields with valid wire types, so that inputs get past
/// the version check and exercise validation with absurd dimensions, enums and array lengths.
fn random_fields(rng: &mut Rng) -> Vec<u8> {
    let mut buf = vec![0x08, 0x01];
    for _ in 0..rng.below(16) {
        let field = 1 + rng.below(24) as u64;
        let wire_type = [0, 1, 2, 5][rng.below(4)];
        push_varint(&mut buf, field << 3 | wire_type);
        match wire_type {
            0 => {
                let value = match rng.below(4) {
                    0 => rng.below(4) as u64,
                    1 => u64::from(u32::MAX),
                    2 => u64::MAX,
                    _ => rng.next_u64() >> rng.below(64),
                };
                push_varint(&mut buf, value);
            }
            1 => buf.extend(rng.bytes(8)),
            5 => {
                let nan_or_random = if rng.below(4) == 0 {
                    f32::NAN.to_le_bytes().to_vec()
                } else {
                    rng.bytes(4)
                };
                buf.extend(nan_or_random);
            }
            _ => {
                let len = rng.below(48);
                push_varint(&mut buf, len as u64);
                buf.extend(rng.bytes(len));
            }
        }
    }
    buf
}

/// Fuzzes `M` around the valid `sample`.
fn fuzz<M: WireMessage + Debug>(sample: &M, seed: u64) {
    let mut rng = Rng::new(seed);

    let mut accepted = 0;
    for _ in 0..RANDOM_INPUTS {
        let len = if rng.below(2) == 0 {
            rng.below(16)
        } else {
            rng.below(512)
        };
        accepted += usize::from(decode_ok::<M>(&rng.bytes(len)));
    }
    // An unversioned random string passing every check would mean the checks are toothless.
    assert!(
        accepted <= RANDOM_INPUTS / 100,
        "{}: {accepted} random inputs accepted",
        M::FULL_NAME
    );

    for _ in 0..FIELD_SEQUENCES {
        decode_ok::<M>(&random_fields(&mut rng));
    }

    let valid = sample.encode_to_vec();
    assert!(decode_ok::<M>(&valid));

    // Protobuf merges concatenated messages (later scalars win, repeated fields append), so
    // random fields after a valid message reach the deep checks with odd dimensions and lengths.
    for _ in 0..FIELD_SEQUENCES {
        let mut bytes = valid.clone();
        bytes.extend(random_fields(&mut rng));
        decode_ok::<M>(&bytes);
    }
    let truncations_rejected = (0..valid.len())
        .filter(|&len| !decode_ok::<M>(&valid[..len]))
        .count();

    let mut flips_rejected = 0;
    for _ in 0..BIT_FLIP_INPUTS {
        let mut bytes = valid.clone();
        for _ in 0..1 + rng.below(3) {
            let bit = rng.below(bytes.len() * 8);
            bytes[bit / 8] ^= 1 << (bit % 8);
        }
        flips_rejected += usize::from(!decode_ok::<M>(&bytes));
    }

    let truncated = truncations_rejected as f64 / valid.len() as f64;
    let flipped = flips_rejected as f64 / BIT_FLIP_INPUTS as f64;
    let name = M::FULL_NAME;
    eprintln!(
        "{name}: {} bytes, rejected {truncated:.3} of truncations, {flipped:.3} of bit flips",
        valid.len()
    );
    // Cutting a message short almost always leaves a length field or an array inconsistent.
    // Bit flips mostly land in float payloads and legitimately give other finite floats, but
    // those in tags, lengths, dimensions, enums and UTF-8 must be caught. (Measured: >= 0.90 and
    // >= 0.11 with these seeds.)
    assert!(
        truncated >= 0.8,
        "{name}: only {truncated:.3} of truncations rejected"
    );
    assert!(
        flipped >= 0.1,
        "{name}: only {flipped:.3} of bit flips rejected"
    );
}

#[test]
fn trajectory_chunk_decoding_never_panics() {
    fuzz(&sample_chunk(), 10);
}

#[test]
fn policy_weights_decoding_never_panics() {
    fuzz(&sample_weights(), 11);
}

#[test]
fn label_request_decoding_never_panics() {
    fuzz(&sample_label_request(), 12);
}

#[test]
fn label_reply_decoding_never_panics() {
    fuzz(&sample_label_reply(), 13);
}

#[test]
fn actor_status_decoding_never_panics() {
    fuzz(&sample_actor_status(), 14);
}

#[test]
fn metrics_decoding_never_panics() {
    fuzz(&sample_metrics(), 15);
}

#[test]
fn episode_frames_decoding_never_panics() {
    fuzz(&sample_episode_frames(), 16);
}
