//! The model contract's parsing of ONNX metadata (formation-onnx's `contract`): the
//! `formation.*` strings of a model someone hands an agent (ONNX Runtime reads the file; the
//! strings are ours to parse).
//!
//! Case: text, one `key=value` entry a line (split at the first `=`; bytes that are not UTF-8
//! are replaced, as every ONNX string reaches us as UTF-8), parsed with
//! [`contract::parse_metadata`]; then its envelope is read and its sensor contract is checked
//! against the paper's LIDAR, as a loading agent does. Decoded means the metadata was accepted.
//! The seeds are the `metadata_props` of the shipped models, as their exporter wrote them.

use std::collections::BTreeMap;
use std::path::Path;

use formation_onnx::SensorContract;
use formation_onnx::contract::{self, check_sensor};
use formation_proto::LidarSpec;

use super::{Refusal, Scratch, Seed, Target, seed_error};
use crate::FuzzError;
use crate::mutate::Shape;

/// The target.
pub const TARGET: Target = Target {
    name: "model-metadata",
    about: "a model's formation.* metadata: contract::parse_metadata, its envelope and sensor check",
    run,
    seeds,
    tokens: &[
        b"\nformation.format=formation-policy/1",
        b"\nformation.occupancy.size_px=",
        b"\nformation.occupancy.d_star_ref_m=",
        b"\nformation.envelope.d_star_min=",
        b"\nformation.envelope.d_star_max=",
        b"\nformation.envelope.team_sizes=",
        b"\nformation.lidar.noise_std=",
        b"\nformation.input=",
        b",",
        b"=",
        b"\n",
        b" ",
    ],
    shape: Shape::Text,
};

/// The metadata entries of a case.
pub fn entries(case: &[u8]) -> BTreeMap<String, String> {
    String::from_utf8_lossy(case)
        .lines()
        .filter_map(|line| line.split_once('='))
        .map(|(k, v)| (k.to_owned(), v.to_owned()))
        .collect()
}

fn run(_: &Scratch, case: &[u8]) -> Result<(), Refusal> {
    let meta = contract::parse_metadata(&entries(case)).map_err(Refusal::of)?;
    let envelope = meta.envelope();
    let _ = envelope.admits_d_star(1.5);
    let lidar = LidarSpec {
        beams: 900,
        max_range: 10.0,
    };
    let _ = check_sensor(&SensorContract::from(&meta), &lidar);
    let _ = check_sensor(
        &SensorContract {
            beams: None,
            max_range: None,
            occupancy: meta.occupancy,
        },
        &lidar,
    );
    Ok(())
}

/// Reads a protobuf varint at `*at`.
fn varint(bytes: &[u8], at: &mut usize) -> Option<u64> {
    let mut value = 0u64;
    for shift in (0..64).step_by(7) {
        let b = *bytes.get(*at)?;
        *at += 1;
        value |= u64::from(b & 0x7f) << shift;
        if b & 0x80 == 0 {
            return Some(value);
        }
    }
    None
}

/// The top-level fields of a protobuf message: `(field number, wire type, bytes)`, where the
/// bytes are those of a length-delimited field (empty for the other wire types).
fn fields(bytes: &[u8]) -> Option<Vec<(u64, u64, &[u8])>> {
    let mut out = Vec::new();
    let mut at = 0;
    while at < bytes.len() {
        let key = varint(bytes, &mut at)?;
        let (field, wire) = (key >> 3, key & 7);
        match wire {
            0 => {
                varint(bytes, &mut at)?;
                out.push((field, wire, &[][..]));
            }
            1 => at += 8,
            5 => at += 4,
            2 => {
                let len = usize::try_from(varint(bytes, &mut at)?).ok()?;
                let end = at.checked_add(len).filter(|&e| e <= bytes.len())?;
                out.push((field, wire, &bytes[at..end]));
                at = end;
            }
            _ => return None,
        }
    }
    Some(out)
}

/// The `metadata_props` of an ONNX model (`ModelProto` field 14, `StringStringEntryProto` key 1
/// and value 2), as `key=value` lines in file order.
pub fn metadata_lines(model: &[u8]) -> Option<String> {
    let mut text = String::new();
    for (field, wire, entry) in fields(model)? {
        if field != 14 || wire != 2 {
            continue;
        }
        let (mut key, mut value) = (String::new(), String::new());
        for (f, _, bytes) in fields(entry)? {
            let s = String::from_utf8_lossy(bytes).into_owned();
            match f {
                1 => key = s,
                2 => value = s,
                _ => {}
            }
        }
        text.push_str(&format!("{key}={value}\n"));
    }
    Some(text)
}

fn seeds() -> Result<Vec<Seed>, FuzzError> {
    let models = Path::new(env!("CARGO_MANIFEST_DIR")).join("../onnx/models");
    let mut seeds = Vec::new();
    for (name, path) in [
        ("policy.txt", models.join("policy.onnx")),
        ("paper-policy.txt", models.join("paper/policy.onnx")),
    ] {
        let bytes = std::fs::read(&path).map_err(seed_error("model-metadata"))?;
        let text = metadata_lines(&bytes).ok_or_else(|| FuzzError::Seed {
            target: "model-metadata",
            source: format!("{} is not an ONNX model", path.display()).into(),
        })?;
        seeds.push((name.to_owned(), text.into_bytes()));
    }
    Ok(seeds)
}
