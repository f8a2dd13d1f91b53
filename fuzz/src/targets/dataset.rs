//! The dataset reader (formation-trainer-bridge's `dataset`): a dataset folder someone hands
//! `formation train` or DAgger.
//!
//! Case: a flags byte, the manifest's length (`u32`, little-endian), `manifest.json`, then the
//! bytes of `shard-000000.safetensors`. Both are written to the scratch folder and read with
//! [`DatasetReader::open`] and [`DatasetReader::load_all`]; decoded means every sample was read.
//! With flag bit 0 set (as in the seeds), the manifest's entry for the shard is stamped with the
//! shard's true size and FNV-1a checksum before it is written, when the manifest is JSON with
//! such an entry, so that mutations of the shard reach the safetensors and column checks instead
//! of stopping at the checksum; with it clear, the checksum is checked as it is.
//!
//! Seeds: a dataset without ranges (format version 1), one whose samples carry their scan's
//! ranges (version 2: `"ranges"` in the manifest, a `ranges` tensor in the shard), and one whose
//! samples carry both the ranges and the neighbours detected in the scan (version 3:
//! `"neighbours"` too, a `neighbours` tensor `[N, K, 4]`).

use formation_proto::{
    BeyondWindow, LidarNoise, LidarSpec, NeighbourInput, OccupancySpec, RangeInput, SimulatedLidar,
};
use formation_trainer_bridge::dataset::{
    DatasetHeader, DatasetReader, DatasetWriter, MANIFEST_FILE, Sample,
};

use super::{Refusal, Scratch, Seed, Target, seed_error};
use crate::FuzzError;
use crate::mutate::Shape;

/// The target.
pub const TARGET: Target = Target {
    name: "dataset",
    about: "a dataset folder (manifest.json and a safetensors shard): DatasetReader::open + load_all",
    run,
    seeds,
    tokens: &[
        b"\"samples\": ",
        b"\"shards\": [",
        b"\"size_px\": ",
        b"\"shape\":[",
        b"\"dtype\":\"U8\"",
        b"\"data_offsets\":[",
        b"\"F32\"",
        b"null",
        b"[]",
        b"{}",
        b"\"__metadata__\"",
        b"shard-999999.safetensors",
        b"\"ranges\": ",
        b"sectors=12,clip=3",
        b"\"neighbours\": ",
        b"slots=3,threshold=1.3,nearest=2",
    ],
    shape: Shape::Bytes,
};

/// The shard's file name in every case.
pub const SHARD_FILE: &str = "shard-000000.safetensors";

/// FNV-1a 64 of `bytes`, 16 hex digits (the manifest's shard checksum).
pub fn fnv1a64_hex(bytes: &[u8]) -> String {
    let mut hash: u64 = 0xcbf2_9ce4_8422_2325;
    for &b in bytes {
        hash ^= u64::from(b);
        hash = hash.wrapping_mul(0x0000_0100_0000_01b3);
    }
    format!("{hash:016x}")
}

/// A case's parts: flags, manifest, shard.
pub fn split(case: &[u8]) -> (u8, &[u8], &[u8]) {
    let Some((&flags, rest)) = case.split_first() else {
        return (0, &[], &[]);
    };
    let Some((len, rest)) = rest.split_first_chunk::<4>() else {
        return (flags, rest, &[]);
    };
    let len = (u32::from_le_bytes(*len) as usize).min(rest.len());
    let (manifest, shard) = rest.split_at(len);
    (flags, manifest, shard)
}

/// The case of these parts.
pub fn join(flags: u8, manifest: &[u8], shard: &[u8]) -> Vec<u8> {
    let mut out = vec![flags];
    out.extend_from_slice(&(manifest.len() as u32).to_le_bytes());
    out.extend_from_slice(manifest);
    out.extend_from_slice(shard);
    out
}

/// The manifest with its first shard entry stamped with `shard`'s size and checksum, when it is
/// JSON with such an entry.
fn stamped(manifest: &[u8], shard: &[u8]) -> Option<Vec<u8>> {
    let mut value: serde_json::Value = serde_json::from_slice(manifest).ok()?;
    let entry = value.get_mut("shards")?.get_mut(0)?.as_object_mut()?;
    entry.insert("bytes".into(), serde_json::Value::from(shard.len() as u64));
    entry.insert(
        "fnv1a64".into(),
        serde_json::Value::from(fnv1a64_hex(shard)),
    );
    serde_json::to_vec(&value).ok()
}

fn run(scratch: &Scratch, case: &[u8]) -> Result<(), Refusal> {
    let (flags, manifest, shard) = split(case);
    let stamped = if flags & 1 == 1 {
        stamped(manifest, shard)
    } else {
        None
    };
    scratch.write(MANIFEST_FILE, stamped.as_deref().unwrap_or(manifest))?;
    scratch.write(SHARD_FILE, shard)?;
    let reader = DatasetReader::open(scratch.dir()).map_err(Refusal::of)?;
    reader.load_all().map_err(Refusal::of)?;
    Ok(())
}

/// The header of the seeds' datasets: 8x8 images.
pub fn header() -> DatasetHeader {
    DatasetHeader::new(
        OccupancySpec {
            size_px: 8,
            resolution_m: 0.1,
            beyond: BeyondWindow::Border,
            d_star_ref_m: Some(1.5),
        },
        SimulatedLidar {
            spec: LidarSpec {
                beams: 36,
                max_range: 4.0,
            },
            noise: LidarNoise { noise_std: 0.01 },
        },
        0.3,
        5,
        "fuzz-seed",
    )
}

/// Sample `i` of run `run` of DAgger iteration `iteration`, 8x8.
pub fn sample(i: usize, iteration: u32, run: u32) -> Sample {
    Sample {
        occupancy: (0..64)
            .map(|c| u8::from((c + i).is_multiple_of(7)))
            .collect(),
        delta_phi: 0.1 * i as f32,
        d_star: 1.5,
        wheels: [0.3, 0.28 + 0.01 * i as f32],
        ranges: Vec::new(),
        neighbours: Vec::new(),
        iteration,
        run,
        robot: (i % 3) as u8,
    }
}

/// The range input of the seed with ranges: 12 sectors of the 36 beams, clip 3.
pub fn ranges() -> RangeInput {
    RangeInput {
        sectors: 12,
        clip: 3.0,
    }
}

/// [`sample`] with the 12 range values of [`ranges`].
pub fn sample_with_ranges(i: usize, iteration: u32, run: u32) -> Sample {
    Sample {
        ranges: (0..12).map(|s| 0.2 * s as f32 + 0.01 * i as f32).collect(),
        ..sample(i, iteration, run)
    }
}

/// The neighbour input of the seed with neighbours: 3 slots, the scenarios' default rule.
pub fn neighbours() -> NeighbourInput {
    NeighbourInput {
        slots: 3,
        threshold: 1.3,
        nearest: 2,
        hidden: false,
    }
}

/// [`sample_with_ranges`] with the 3 slots of [`neighbours`]: two detections and an empty slot.
pub fn sample_with_neighbours(i: usize, iteration: u32, run: u32) -> Sample {
    let x = 0.05 * i as f32;
    Sample {
        neighbours: vec![
            0.9 + x,
            0.2,
            1.0,
            1.0, //
            -0.4,
            -1.1 - x,
            0.0,
            1.0, //
            0.0,
            0.0,
            0.0,
            0.0,
        ],
        ..sample_with_ranges(i, iteration, run)
    }
}

/// The case of a dataset of `header` holding `samples`.
fn seed_case(header: DatasetHeader, samples: Vec<Sample>) -> Result<Vec<u8>, FuzzError> {
    let dir = tempfile::tempdir().map_err(seed_error(TARGET.name))?;
    let mut writer = DatasetWriter::create(dir.path(), header).map_err(seed_error(TARGET.name))?;
    for sample in samples {
        writer.push(sample).map_err(seed_error(TARGET.name))?;
    }
    writer.finish().map_err(seed_error(TARGET.name))?;
    let manifest =
        std::fs::read(dir.path().join(MANIFEST_FILE)).map_err(seed_error(TARGET.name))?;
    let shard = std::fs::read(dir.path().join(SHARD_FILE)).map_err(seed_error(TARGET.name))?;
    Ok(join(1, &manifest, &shard))
}

fn seeds() -> Result<Vec<Seed>, FuzzError> {
    let plain = seed_case(header(), (0..3).map(|i| sample(i, 0, i as u32)).collect())?;
    let ranged = seed_case(
        header().with_ranges(Some(ranges())),
        (0..3).map(|i| sample_with_ranges(i, 0, i as u32)).collect(),
    )?;
    let with_neighbours = seed_case(
        header()
            .with_ranges(Some(ranges()))
            .with_neighbours(Some(neighbours())),
        (0..3)
            .map(|i| sample_with_neighbours(i, 0, i as u32))
            .collect(),
    )?;
    Ok(vec![
        ("dataset.bin".into(), plain),
        ("dataset-ranges.bin".into(), ranged),
        ("dataset-neighbours.bin".into(), with_neighbours),
    ])
}
