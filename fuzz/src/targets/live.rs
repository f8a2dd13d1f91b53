//! The live-recording records (formation-record's `live`): what `formation record --connect`
//! receives from a world over the network.
//!
//! Case: one message's bytes, decoded with [`formation_record::live::decode`]. Decoded means it
//! was accepted. The seeds are a run's messages made by the world's encoder
//! ([`formation_record::live::encode`]): its setup, ticks, and both kinds of end.

use std::path::Path;

use formation_record::FinalSample;
use formation_record::live::{LiveMessage, LiveSetup, decode, encode};

use super::{Refusal, Scratch, Seed, Target, sample, seed_error};
use crate::FuzzError;
use crate::mutate::Shape;

/// The target.
pub const TARGET: Target = Target {
    name: "live",
    about: "the live-recording messages a remote recorder receives: live::decode",
    run,
    seeds,
    tokens: &[b"FMLV", &[1, 0], &[0xff, 0xff, 0xff, 0xff], &[0, 0, 0, 0]],
    shape: Shape::Bytes,
};

fn run(_: &Scratch, case: &[u8]) -> Result<(), Refusal> {
    decode(case).map(|_| ()).map_err(Refusal::of)
}

fn seeds() -> Result<Vec<Seed>, FuzzError> {
    let setup = sample::setup("live", Vec::new())?;
    let live =
        LiveSetup::for_run(&setup, 0, 2, Path::new("run.mcap")).map_err(seed_error("live"))?;
    let run_index = live.run_index;
    let last = sample::tick(6);
    let mut seeds = vec![("setup.bin".to_owned(), encode(&LiveMessage::Setup(live)))];
    for k in [0, 3] {
        seeds.push((
            format!("tick-{k}.bin"),
            encode(&LiveMessage::Tick {
                run_index,
                tick: sample::tick(k),
            }),
        ));
    }
    seeds.push((
        "end.bin".into(),
        encode(&LiveMessage::End {
            run_index,
            last: Some(FinalSample {
                tick: last.tick,
                time: last.time,
                poses: last.poses,
            }),
        }),
    ));
    seeds.push((
        "end-stopped.bin".into(),
        encode(&LiveMessage::End {
            run_index,
            last: None,
        }),
    ));
    Ok(seeds)
}
