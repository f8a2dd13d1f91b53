//! The DAgger part reader (formation-trainer-bridge's `dagger_part`): a share of an iteration's
//! labelled samples, as a worker of a sweep hands it back.
//!
//! Case: the part file's bytes, written to the scratch folder and read with [`read_part`];
//! decoded means the part was accepted. The seed is written by [`write_part`].

use formation_trainer_bridge::dagger_part::{PartHeader, RolloutSettings, read_part, write_part};

use super::dataset::{header, sample};
use super::{Refusal, Scratch, Seed, Target, seed_error};
use crate::FuzzError;
use crate::mutate::Shape;

/// The target.
pub const TARGET: Target = Target {
    name: "dagger",
    about: "a DAgger part (safetensors with a JSON header in its metadata): read_part",
    run,
    seeds,
    tokens: &[
        b"\"__metadata__\"",
        b"\"shape\":[",
        b"\"data_offsets\":[",
        b"\\\"size_px\\\":",
        b"\\\"runs\\\":",
        b"\\\"first_run\\\":",
        b"\"samples\":\"",
        b"\"U32\"",
        b"null",
        b"[]",
    ],
    shape: Shape::FixedLength,
};

fn run(scratch: &Scratch, case: &[u8]) -> Result<(), Refusal> {
    let path = scratch.write("part.safetensors", case)?;
    read_part(&path).map(|_| ()).map_err(Refusal::of)
}

fn seeds() -> Result<Vec<Seed>, FuzzError> {
    let dir = tempfile::tempdir().map_err(seed_error(TARGET.name))?;
    let part = PartHeader {
        dataset: header(),
        iteration: 2,
        rollouts: RolloutSettings {
            scenario: "fuzz-seed".into(),
            team_sizes: vec![3, 5],
            durations_s: Vec::new(),
            seed: 11,
            expert_share: 0.25,
            model_fnv1a64: "0123456789abcdef".into(),
        },
        first_run: 4,
        runs: 2,
    };
    let samples: Vec<_> = (0..4).map(|i| sample(i, 2, 4 + (i / 2) as u32)).collect();
    let path = dir.path().join("part-0.safetensors");
    write_part(&path, &part, &samples).map_err(seed_error(TARGET.name))?;
    let empty = dir.path().join("part-empty.safetensors");
    write_part(
        &empty,
        &PartHeader {
            first_run: 6,
            runs: 0,
            ..part
        },
        &[],
    )
    .map_err(seed_error(TARGET.name))?;
    Ok(vec![
        (
            "part.safetensors".into(),
            std::fs::read(&path).map_err(seed_error(TARGET.name))?,
        ),
        (
            "part-empty.safetensors".into(),
            std::fs::read(&empty).map_err(seed_error(TARGET.name))?,
        ),
    ])
}
